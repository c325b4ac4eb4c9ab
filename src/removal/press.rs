//! The force the ball really presses with at each contact (issues 28/29). The arm commands
//! the ball centre the preload below the *nominal* surface; where the part stands `d` above it
//! (its measured deviation) the ball is pressed `preload + d` deep, and the penetration falls
//! as the pass removes material. Every contact carries that force as a share of the preload's
//! (`Contact::force_ratio`), and the influence scales its patch and pressure by it; the Monte
//! Carlo's position error changes the same penetration through [`ToolModel::force_ratio`].
//! Method: docs/ALGORITHMS.md, "Removal planning".
use nalgebra::{Matrix3, Point3, Vector3};

use super::influence::{Contact, Influence};
use super::tool::{ComplianceDirection, ToolModel};
use super::{known, target};
use crate::repair::SurfacePoint;
use crate::spatial::Neighbours;

/// Share of a contact's target removal taken as already gone when its force is evaluated
/// (0.5, mid-pass): the removal there grows from 0 to the target over the grind and Preston's
/// removal is linear in the force (`k F v` summed over the patch), so to first order the mean
/// force over the pass is the force at half the removal.
pub const MID_PASS_SHARE: f64 = 0.5;

/// Smallest determinant of the plane fit's normal matrix per point cubed (1e-4, coordinates
/// in patch radii): about a tenth of a radius of spread in both directions; below it the
/// slope is not determined and the mean deviation stands.
const MIN_SPREAD: f64 = 1e-4;

/// The part as measured around a contact: its deviation there and the deviation's slope.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactDeviation {
    /// Deviation at the contact point, mm (+ = excess).
    pub deviation: f64,
    /// Gradient of the deviation along the surface, mm/mm (tangent to the nominal normal).
    pub slope: Vector3<f64>,
}

impl ContactDeviation {
    /// Outward unit normal of the measured surface at a point whose nominal normal is `n`:
    /// the surface moved out by `d` along `n` has tangents `t + (grad d . t) n`.
    pub fn normal(&self, n: &Vector3<f64>) -> Vector3<f64> {
        (n - self.slope).normalize()
    }
}

/// The part around the contact at `point` (nominal normal `normal`) from the known deviations
/// of the core points `cores` (indexed by `index`) within `radius` mm: the plane `d0 + g . x`
/// fitted by least squares in the tangent plane; fewer than three points or a degenerate
/// spread: their mean with no slope; none: the nearest core point's deviation (0 where
/// unknown).
pub fn measured_at(
    cores: &[SurfacePoint],
    index: &Neighbours,
    (point, normal): (&Point3<f64>, &Vector3<f64>),
    radius: f64,
) -> ContactDeviation {
    let near: Vec<(Vector3<f64>, f64)> = index
        .within_unsorted(point, radius)
        .iter()
        .map(|nb| &cores[nb.index])
        .filter(|c| c.distance.is_finite())
        .map(|c| (c.position - point, c.distance))
        .collect();
    let flat = |deviation| ContactDeviation {
        deviation,
        slope: Vector3::zeros(),
    };
    if near.is_empty() {
        let nearest = index.nearest(point).map(|nb| cores[nb.index].distance);
        return flat(known(nearest.unwrap_or(0.0)));
    }
    let mean = near.iter().map(|n| n.1).sum::<f64>() / near.len() as f64;
    // the fit's deviation and slope do not depend on which tangents span the plane
    let (tx, ty) = crate::spatial::tangent_basis(normal);
    let (mut m, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
    for (x, d) in &near {
        let row = Vector3::new(1.0, x.dot(&tx) / radius, x.dot(&ty) / radius);
        m += row * row.transpose();
        rhs += row * *d;
    }
    // the coordinates in patch radii: a spread of a tenth of it in each direction at least
    match (near.len() >= 3 && m.determinant() > MIN_SPREAD * near.len().pow(3) as f64)
        .then(|| m.try_inverse())
        .flatten()
    {
        Some(inv) => {
            let f = inv * rhs;
            ContactDeviation {
                deviation: f[0],
                slope: (tx * f[1] + ty * f[2]) / radius,
            }
        }
        None => flat(mean),
    }
}

/// The force ratio at a contact where the part stands `deviation` mm above nominal and the
/// plan removes down to `allowance` mm: the penetration `preload + deviation - share x target`
/// ([`MID_PASS_SHARE`]) over the preload.
pub fn force_ratio(tool: &ToolModel, deviation: f64, allowance: f64) -> f64 {
    force_ratio_at(tool, tool.preload_mm, deviation, allowance)
}

/// [`force_ratio`] of a contact commanded `depth` mm below touching the nominal surface
/// (`Contact::depth_mm`) instead of the preload: its penetration over the preload.
fn force_ratio_at(tool: &ToolModel, depth: f64, deviation: f64, allowance: f64) -> f64 {
    let removed = MID_PASS_SHARE * target(deviation, allowance);
    tool.force_ratio(depth + deviation - removed)
}

/// Smallest cosine of the spindle's tilt from the measured normal at which a spindle-axis
/// mount is modelled (0.17, cos 80 degrees: tool.toml's largest `tilt_deg`): the spring's
/// compression grows as depth / cos and the slide as tan, both without bound as the axis lies
/// down on the surface; a contact tilted further counts as tilted 80 degrees.
pub const MIN_AXIS_COS: f64 = 0.17;

/// Sets every contact's `force_ratio`, `normal` and `offset` from the part measured at the
/// core points `cores` (indexed by `index`) under the patch of the preload's force
/// (`influence`), the plan removing down to `allowance` mm: the ball presses the measured
/// surface, at its deviation and along its normal, and gives along the tool's
/// `compliance_direction` ([`along_axis`] for a spring-loaded spindle).
pub fn press(
    contacts: &mut [Contact],
    tool: &ToolModel,
    influence: &Influence,
    (cores, index): (&[SurfacePoint], &Neighbours),
    allowance: f64,
) {
    let patch = influence.patch_radius();
    for c in contacts {
        let part = measured_at(cores, index, (&c.point, &c.normal), patch);
        if tool.compliance_direction == ComplianceDirection::SpindleAxis {
            along_axis(c, tool, influence.ball_mm(), &part, allowance);
            continue;
        }
        c.force_ratio = force_ratio_at(tool, c.depth_mm, part.deviation, allowance);
        let nominal = c.normal;
        c.normal = part.normal(&nominal);
        // the ball centre is this far from the measured surface (its radius less the
        // penetration); its foot there is up-slope of the nominal contact by that times the
        // part of the nominal normal across the measured one
        let height = (influence.ball_mm() - c.force_ratio * tool.preload_mm).max(0.0);
        let across = nominal - c.normal * nominal.dot(&c.normal);
        let slide = across * height;
        c.offset = slide - nominal * nominal.dot(&slide);
    }
}

/// Contact `c` pressed by a spring-loaded spindle (docs/ALGORITHMS.md, "The mount's
/// direction"): the arm commands the ball centre `depth` (`c.depth_mm`: the preload, or less
/// where a servo could not hold its force) below the nominal surface along the nominal normal
/// n, the point `(ball - depth) n` from `c.point`; the measured surface
/// is the plane through `c.point + h n` (h the deviation less the mid-pass removal) with
/// normal m. The rigid ball retreats along the spindle axis a by the compression s that
/// leaves it touching: `s = (ball - m . (free - h n)) / cos`, `cos = -m . a`; the contact force
/// is normal (friction at the patch runs across the lean plane, square to a), and its axial
/// part balances the spring: `F = rate x s / cos`. The patch centre is the ball centre's foot
/// on the plane, `free - s a - ball m`; its part along the surface is the offset.
pub fn along_axis(
    c: &mut Contact,
    tool: &ToolModel,
    ball_mm: f64,
    part: &ContactDeviation,
    allowance: f64,
) {
    let nominal = c.normal;
    let m = part.normal(&nominal);
    let a = c.spin.normalize();
    let cos = (-m.dot(&a)).max(MIN_AXIS_COS);
    let h = part.deviation - MID_PASS_SHARE * target(part.deviation, allowance);
    let free = nominal * (ball_mm - c.depth_mm);
    let s = ((ball_mm - m.dot(&(free - nominal * h))) / cos).max(0.0);
    c.force_ratio = tool.force_ratio(s / cos);
    c.normal = m;
    let touch = free - a * s - m * ball_mm;
    c.offset = touch - nominal * nominal.dot(&touch);
}

/// How a spring-loaded spindle at the pressed contact `c` answers its commanded centre moved
/// 1 mm outward along the normal (the Monte Carlo's position error): the force ratio falls by
/// `1 / (preload cos^2)` and the patch slides `tan` along the lean (the tangent toward which
/// the tip leans), the first-order change of [`along_axis`] on a flat surface.
pub fn axial_give(tool: &ToolModel, c: &Contact) -> (f64, Vector3<f64>) {
    let (tilt, lean) = c.tilt();
    let cos = tilt.cos.max(MIN_AXIS_COS);
    (1.0 / (tool.preload_mm * cos * cos), lean * (tilt.sin / cos))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn core(x: f64, distance: f64) -> SurfacePoint {
        SurfacePoint {
            position: Point3::new(x, 0.0, 0.0),
            normal: Vector3::z(),
            distance,
            uncertainty: 0.0,
            region: -1,
        }
    }

    /// By hand: 0.4 mm of excess, allowance 0.1: target 0.3, penetration 2 + 0.4 - 0.15.
    #[test]
    fn the_ratio_is_the_mid_pass_penetration_over_the_preload() {
        let tool = ToolModel::default();
        assert!((force_ratio(&tool, 0.4, 0.1) - 2.25 / 2.0).abs() < 1e-12);
        assert!((force_ratio(&tool, 0.0, 0.0) - 1.0).abs() < 1e-12);
        // a pit: the ball presses less, nothing is removed there
        assert!((force_ratio(&tool, -0.5, 0.0) - 0.75).abs() < 1e-12);
        assert_eq!(force_ratio(&tool, -3.0, 0.0), 0.0);
    }

    #[test]
    fn without_a_spread_the_deviation_is_the_mean_under_the_patch_or_the_nearest() {
        let cores = [
            core(0.0, 0.2),
            core(0.3, 0.4),
            core(0.5, f64::NAN),
            core(2.0, 1.0),
            core(5.0, f64::NAN),
        ];
        let positions: Vec<_> = cores.iter().map(|c| c.position).collect();
        let index = Neighbours::new(&positions);
        let z = Vector3::z();
        let at = |x: f64| {
            let m = measured_at(&cores, &index, (&Point3::new(x, 0.0, 0.0), &z), 0.6);
            assert_eq!(m.slope, Vector3::zeros(), "points on a line give no slope");
            m.deviation
        };
        // the unknown point under the patch is skipped
        assert!((at(0.1) - 0.3).abs() < 1e-12);
        assert!((at(0.5) - 0.3).abs() < 1e-12);
        // none under the patch: the nearest; unknown there: 0
        assert!((at(3.0) - 1.0).abs() < 1e-12);
        assert_eq!(at(5.1), 0.0);
    }

    /// An n x n grid of core points `pitch` mm apart centred on the origin of the plane z = 0,
    /// with deviation `d(x, y)`, and its index.
    fn plane(n: usize, pitch: f64, d: impl Fn(f64, f64) -> f64) -> (Vec<SurfacePoint>, Neighbours) {
        let half = 0.5 * (n - 1) as f64 * pitch;
        let cores: Vec<SurfacePoint> = (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f64 * pitch - half, (i / n) as f64 * pitch - half);
                SurfacePoint {
                    position: Point3::new(x, y, 0.0),
                    distance: d(x, y),
                    ..core(0.0, 0.0)
                }
            })
            .collect();
        let positions: Vec<_> = cores.iter().map(|c| c.position).collect();
        let index = Neighbours::new(&positions);
        (cores, index)
    }

    /// A tilted plane of deviations d = 0.1 + 0.2 x - 0.1 y: found exactly, and the normal of
    /// the measured surface is (-0.2, 0.1, 1) normalised.
    #[test]
    fn a_sloped_part_gives_its_deviation_and_normal() {
        let (cores, index) = plane(10, 0.2, |x, y| 0.1 + 0.2 * x - 0.1 * y);
        let p = Point3::new(0.1, 0.05, 0.0);
        let m = measured_at(&cores, &index, (&p, &Vector3::z()), 0.6);
        assert!((m.deviation - (0.1 + 0.02 - 0.005)).abs() < 1e-12, "{m:?}");
        let want = Vector3::new(-0.2, 0.1, 1.0).normalize();
        assert!((m.normal(&Vector3::z()) - want).norm() < 1e-12, "{m:?}");
    }

    /// On a part sloped 0.2 mm/mm along x at 0.1 mm above nominal, the ball (radius 3 mm,
    /// preload 2 mm: its centre 3 - 2.1 = 0.9 mm from the measured surface, no allowance
    /// removed at mid-pass with allowance above the deviation) touches up-slope at the foot of
    /// its centre on the measured plane, 0.9 x sin(atan 0.2) away along it: on the nominal
    /// surface, 0.9 x sin x cos of the slope's angle along +x.
    #[test]
    fn on_a_slope_the_patch_moves_up_slope_by_the_centre_height() {
        let (cores, index) = plane(20, 0.1, |x, _| 0.1 + 0.2 * x);
        let tool = ToolModel::default();
        let influence = Influence::new(&tool, 3.0);
        let mut contacts = [Contact {
            point: Point3::origin(),
            normal: Vector3::z(),
            along: Vector3::y(),
            spin: -Vector3::z(),
            length: 0.0,
            force_ratio: 1.0,
            offset: Vector3::zeros(),
            depth_mm: tool.preload_mm,
        }];
        press(&mut contacts, &tool, &influence, (&cores, &index), 1.0);
        let c = &contacts[0];
        assert!(
            (c.force_ratio - 2.1 / 2.0).abs() < 1e-9,
            "{}",
            c.force_ratio
        );
        let angle = 0.2f64.atan();
        let want = 0.9 * angle.sin() * angle.cos();
        assert!(
            (c.offset - Vector3::x() * want).norm() < 1e-9,
            "{:?} vs {want}",
            c.offset
        );
    }
}

//! The force the ball really presses with at each contact (issues 28/29). The arm commands
//! the ball centre the preload below the *nominal* surface; where the part stands `d` above it
//! (its measured deviation) the ball is pressed `preload + d` deep, and the penetration falls
//! as the pass removes material. Every contact carries that force as a share of the preload's
//! (`Contact::force_ratio`), and the influence scales its patch and pressure by it; the Monte
//! Carlo's position error changes the same penetration through [`ToolModel::force_ratio`].
//! Method: docs/ALGORITHMS.md, "Removal planning".
use nalgebra::Point3;

use super::influence::{Contact, Influence};
use super::tool::ToolModel;
use super::{known, target};
use crate::plan::inspection::SurfacePoint;
use crate::spatial::Neighbours;

/// Share of a contact's target removal taken as already gone when its force is evaluated
/// (0.5, mid-pass): the removal there grows from 0 to the target over the grind and Preston's
/// removal is linear in the force (`k F v` summed over the patch), so to first order the mean
/// force over the pass is the force at half the removal.
pub const MID_PASS_SHARE: f64 = 0.5;

/// The part's measured deviation at `point`, mm: the mean of the known deviations of the core
/// points `cores` (indexed by `index`) within `radius` mm (the contact patch: the area the ball
/// rests on), or the nearest core point's when none is that close (0 where unknown).
pub fn deviation_at(
    cores: &[SurfacePoint],
    index: &Neighbours,
    point: &Point3<f64>,
    radius: f64,
) -> f64 {
    let near: Vec<f64> = index
        .within_unsorted(point, radius)
        .iter()
        .map(|nb| cores[nb.index].distance)
        .filter(|d| d.is_finite())
        .collect();
    if near.is_empty() {
        return index
            .nearest(point)
            .map_or(0.0, |nb| known(cores[nb.index].distance));
    }
    near.iter().sum::<f64>() / near.len() as f64
}

/// The force ratio at a contact where the part stands `deviation` mm above nominal and the
/// plan removes down to `allowance` mm: the penetration `preload + deviation - share x target`
/// ([`MID_PASS_SHARE`]) over the preload.
pub fn force_ratio(tool: &ToolModel, deviation: f64, allowance: f64) -> f64 {
    let removed = MID_PASS_SHARE * target(deviation, allowance);
    tool.force_ratio(tool.preload_mm + deviation - removed)
}

/// Sets every contact's `force_ratio` from the part measured at the core points `cores`
/// (indexed by `index`) under the patch of the preload's force (`influence`), the plan
/// removing down to `allowance` mm.
pub fn press(
    contacts: &mut [Contact],
    tool: &ToolModel,
    influence: &Influence,
    (cores, index): (&[SurfacePoint], &Neighbours),
    allowance: f64,
) {
    let patch = influence.patch_radius();
    for c in contacts {
        let deviation = deviation_at(cores, index, &c.point, patch);
        c.force_ratio = force_ratio(tool, deviation, allowance);
    }
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
    fn the_deviation_is_the_mean_under_the_patch_or_the_nearest() {
        let cores = [
            core(0.0, 0.2),
            core(0.3, 0.4),
            core(0.5, f64::NAN),
            core(2.0, 1.0),
            core(5.0, f64::NAN),
        ];
        let positions: Vec<_> = cores.iter().map(|c| c.position).collect();
        let index = Neighbours::new(&positions);
        let at = |x: f64| deviation_at(&cores, &index, &Point3::new(x, 0.0, 0.0), 0.6);
        // the unknown point under the patch is skipped
        assert!((at(0.1) - 0.3).abs() < 1e-12);
        assert!((at(0.5) - 0.3).abs() < 1e-12);
        // none under the patch: the nearest; unknown there: 0
        assert!((at(3.0) - 1.0).abs() < 1e-12);
        assert_eq!(at(5.1), 0.0);
    }
}

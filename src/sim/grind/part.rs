//! The virtual part: surface points with outward normals that move inward as the true law
//! removes material under the simulated tool.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::law::{preston_rate, HertzContact, KField};
use super::{GrindConfig, MountGive};
use crate::preprocess::pca_normal;
use crate::spatial::Neighbours;

/// Extra distance beyond the ball radius at which the nearest surface point is still looked
/// at, mm: the ball is out of contact farther than that, and the query stays cheap.
const CONTACT_SEARCH_MARGIN_MM: f64 = 0.5;

/// Margin by which a ball's lower bound on its distance to the part must exceed the contact
/// reach for a step to skip the nearest-point query, mm (1e-6: the distances are sums of
/// squares of coordinates around 100 mm, rounded at 1e-14 mm; the margin keeps the skipped
/// steps exactly those the query would have found out of reach).
const CLEARANCE_ROUNDING_MM: f64 = 1e-6;

/// Surface points whose heights under the ball give the penetration (their median): one
/// stray point (an outlier that lies near the surface, a normal across an edge) among them
/// cannot press the ball; 9 is a 3 x 3 patch of scan points, 0.15 mm across at synth's
/// density, far under the smallest contact patch.
pub const PENETRATION_NEIGHBOURS: usize = 9;

/// Removal at a point since its normal was last estimated past which the normal is estimated
/// again from the surface as it is, mm (0.005): the contact's relative speed follows the angle
/// between the spindle and the normal by cot(tilt), 2.7 at the default 20 degrees, and a flank
/// 1 mm from a bump's top taken down 0.005 mm more turns by 0.3 degrees, 1.4 % of the speed,
/// under the +-10 % of the true k's field. A grind flattens a bump's flanks by 9-14 degrees,
/// which with the normals it started from changed the removal at the top by 2x.
const NORMAL_REFRESH_MM: f64 = 0.005;

/// Smallest cosine of the spindle's tilt from the surface normal at which the simulated
/// axial mount is followed (0.1, 84 degrees): the slide grows as 1 / cos; a tool laid that
/// flat on the part counts as tilted 84 degrees.
const MIN_AXIAL_COS: f64 = 0.1;

/// Surface points whose current positions give a refreshed normal (PCA), as `prepare`'s
/// initial estimate (`NormalConfig`'s k, 20).
const NORMAL_NEIGHBOURS: usize = 20;

/// A part being ground, reference frame, mm.
pub struct VirtualPart {
    /// Where each point was when its normal was last estimated (`index` holds the first
    /// positions: a point moves by a fraction of a millimetre, its neighbours stay).
    points: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    removal: Vec<f64>,
    /// Removal at each point when its normal was last estimated.
    fresh: Vec<f64>,
    /// Points whose removal may have outgrown their normal (indices, possibly repeated).
    stale: Vec<usize>,
    k: Vec<f64>,
    index: Neighbours,
    /// The points near the ball centre of the last step (`index` never moves, so they are
    /// the same whenever the same centre is asked again; their heights are not kept).
    last_near: Option<LastNear>,
    /// The last ball centre whose nearest point was looked up, and that point's distance,
    /// mm: the nearest distance changes by at most what the centre moved, so a ball that was
    /// far from the part and moved little is still out of reach without a query.
    clearance: Option<(Point3<f64>, f64)>,
}

/// [`VirtualPart::penetration`]'s neighbours of one ball centre.
struct LastNear {
    centre: Point3<f64>,
    ball_mm: f64,
    near: Option<Vec<usize>>,
}

/// The state of the tool at one step, reference frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolState {
    /// Ball centre where the arm holds it (the mount unloaded), mm: a spindle-axis mount lets
    /// the ball slide back from it ([`VirtualPart::seat`]).
    pub centre: Point3<f64>,
    /// Spindle axis, unit (shank to tip).
    pub axis: Vector3<f64>,
    /// Velocity of the ball centre, mm/s.
    pub velocity: Vector3<f64>,
}

impl VirtualPart {
    /// A part of `points` with outward unit `normals` (same length), true k from `cfg`.
    pub fn new(points: Vec<Point3<f64>>, normals: Vec<Vector3<f64>>, cfg: &GrindConfig) -> Self {
        assert_eq!(points.len(), normals.len(), "one normal per point");
        let field = KField::new(cfg);
        let k = points.par_iter().map(|p| field.at(p)).collect();
        let index = Neighbours::new(&points);
        VirtualPart {
            removal: vec![0.0; points.len()],
            fresh: vec![0.0; points.len()],
            stale: Vec::new(),
            points,
            normals,
            k,
            index,
            last_near: None,
            clearance: None,
        }
    }

    /// Removal so far per point, mm (along the inward normal).
    pub fn removal(&self) -> &[f64] {
        &self.removal
    }

    /// The true k per point, mm^2/N.
    pub fn true_k(&self) -> &[f64] {
        &self.k
    }

    /// The outward normals.
    pub fn normals(&self) -> &[Vector3<f64>] {
        &self.normals
    }

    /// Surface point `i` now (moved inward along its normal by the removal since its normal
    /// was last estimated, from where it was then), mm.
    pub fn current(&self, i: usize) -> Point3<f64> {
        self.points[i] - self.normals[i] * (self.removal[i] - self.fresh[i])
    }

    /// The surface now, every point.
    pub fn current_points(&self) -> Vec<Point3<f64>> {
        (0..self.points.len()).map(|i| self.current(i)).collect()
    }

    /// Penetration of the ball into the surface now, mm: the ball radius minus the centre's
    /// height above the surface, the median over the nearest [`PENETRATION_NEIGHBOURS`]
    /// points of the height above each one's tangent plane (negative: no contact); None when
    /// no point is near. Returns the index of the median point too (its normal is the
    /// contact's).
    pub fn penetration(&self, centre: &Point3<f64>, ball_mm: f64) -> Option<(usize, f64)> {
        let near = match &self.last_near {
            Some(last) if last.centre == *centre && last.ball_mm == ball_mm => last.near.clone(),
            _ => self.near(centre, ball_mm),
        }?;
        let mut heights: Vec<(f64, usize)> = near
            .into_iter()
            .map(|i| (self.normals[i].dot(&(centre - self.current(i))), i))
            .collect();
        heights.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (height, i) = heights[heights.len() / 2];
        Some((i, ball_mm - height))
    }

    /// [`VirtualPart::near`] of the ball centre where the arm holds it at this step: None
    /// without a query while the last nearest distance, less what the centre moved since,
    /// stays beyond the reach (by [`CLEARANCE_ROUNDING_MM`]); the nearest point first while
    /// the ball was out of contact (one cheap query answers most steps), the neighbours at
    /// once while it was in contact (one query instead of two). The same answer each way.
    fn near_tool(&mut self, centre: &Point3<f64>, ball_mm: f64) -> Option<Vec<usize>> {
        let reach = ball_mm + CONTACT_SEARCH_MARGIN_MM;
        if let Some((at, distance)) = self.clearance {
            if distance - (centre - at).norm() > reach + CLEARANCE_ROUNDING_MM {
                return None;
            }
        }
        let in_contact = (self.last_near.as_ref()).is_some_and(|last| last.near.is_some());
        if in_contact {
            self.clearance = None;
            return self.near(centre, ball_mm);
        }
        let nearest = self.index.nearest(centre)?;
        self.clearance = Some((*centre, nearest.dist2.sqrt()));
        if nearest.dist2 > reach * reach {
            return None;
        }
        Some(
            (self.index.knn(centre, PENETRATION_NEIGHBOURS).into_iter())
                .map(|nb| nb.index)
                .collect(),
        )
    }

    /// The [`PENETRATION_NEIGHBOURS`] points nearest `centre` (nearest first, as
    /// `Neighbours::knn`), None when the nearest lies farther than the ball radius and
    /// [`CONTACT_SEARCH_MARGIN_MM`]. One query where all of them lie within that reach (a
    /// ball in contact): the k nearest within a radius are the k nearest when there are k.
    fn near(&self, centre: &Point3<f64>, ball_mm: f64) -> Option<Vec<usize>> {
        let reach = ball_mm + CONTACT_SEARCH_MARGIN_MM;
        let r2 = reach * reach;
        let want = PENETRATION_NEIGHBOURS.min(self.index.len()).max(1);
        let indices = |v: Vec<_>| v.into_iter().map(|nb: crate::spatial::Neighbour| nb.index);
        if r2.is_finite() {
            let within = self.index.knn_within(centre, PENETRATION_NEIGHBOURS, reach);
            if within.len() >= want {
                return Some(indices(within).collect());
            }
        }
        let nearest = self.index.nearest(centre)?;
        if nearest.dist2 > r2 {
            return None;
        }
        Some(indices(self.index.knn(centre, PENETRATION_NEIGHBOURS)).collect())
    }

    /// Where the ball sits with the arm holding its mount at `tool`, and how hard it presses:
    /// the surface point whose tangent plane it touches, the ball centre and the normal force
    /// over the spring rate (mm). [`MountGive::SurfaceNormal`]: the centre where the arm puts
    /// it and the penetration. [`MountGive::SpindleAxis`]: the rigid ball slides back along
    /// the axis a until it touches, by `s = penetration / cos` (cos = -n . a, the tilt from
    /// the inward normal), taken once more where it then sits (a curved part); the spring
    /// pushes `rate x s` along a, and the normal contact force whose axial part balances it is
    /// `rate x s / cos` (the friction at the patch runs across the plane of a and n).
    pub fn seat(&self, tool: &ToolState, cfg: &GrindConfig) -> Option<(usize, Point3<f64>, f64)> {
        let ball = cfg.ball_radius_mm;
        let (i, depth) = self.penetration(&tool.centre, ball)?;
        if cfg.compliance_direction == MountGive::SurfaceNormal || depth.is_nan() || depth <= 0.0 {
            return Some((i, tool.centre, depth));
        }
        let cos = |k: usize| (-self.normals[k].dot(&tool.axis)).max(MIN_AXIAL_COS);
        let first = depth / cos(i);
        let (j, left) = self
            .penetration(&(tool.centre - tool.axis * first), ball)
            .unwrap_or((i, 0.0));
        let s = (first + left / cos(j)).max(0.0);
        Some((j, tool.centre - tool.axis * s, s / cos(j)))
    }

    /// Grinds for `dt` seconds with the tool at `tool`: the spring force from the penetration,
    /// the Hertz patch centred under the ball, and at every point inside it the true Preston
    /// rate at its pressure and its speed relative to the turning ball. Returns the contact.
    pub fn grind_step(
        &mut self,
        tool: &ToolState,
        dt: f64,
        cfg: &GrindConfig,
    ) -> Option<HertzContact> {
        // the points under the ball where the arm holds it: asked once a step, by the seat
        // and by the caller's contact normal after the step (`penetration`)
        let near = self.near_tool(&tool.centre, cfg.ball_radius_mm);
        self.last_near = Some(LastNear {
            centre: tool.centre,
            ball_mm: cfg.ball_radius_mm,
            near,
        });
        let (i, ball, depth) = self.seat(tool, cfg)?;
        let contact = HertzContact::hertz(
            depth,
            cfg.spring_rate_n_mm,
            cfg.ball_radius_mm,
            cfg.modulus_mpa,
        )?;
        let n = self.normals[i];
        let below = self.current(i);
        // patch centre: the ball centre's foot on the tangent plane of the nearest point
        let centre = ball - n * n.dot(&(ball - below));
        let omega = tool.axis * cfg.spindle_rpm * std::f64::consts::TAU / 60.0;
        let reach = contact.radius_mm + CONTACT_SEARCH_MARGIN_MM;
        for nb in self.index.within_unsorted(&centre, reach) {
            let j = nb.index;
            let d = self.current(j) - centre;
            let r = (d - n * n.dot(&d)).norm();
            let p = contact.pressure(r);
            if p <= 0.0 {
                continue;
            }
            // surface speed of the ball where it touches point j, plus the feed: the spring
            // takes the penetration, so the ball keeps its radius (its pole is R below the
            // centre along the normal, the patch point offset across it)
            let across = d - n * n.dot(&d);
            let arm = across
                - n * (cfg.ball_radius_mm * cfg.ball_radius_mm - across.norm_squared())
                    .max(0.0)
                    .sqrt();
            let v = (omega.cross(&arm) + tool.velocity).norm();
            self.removal[j] += preston_rate(self.k[j], p, v, cfg) * dt;
            if self.removal[j] - self.fresh[j] > NORMAL_REFRESH_MM {
                self.stale.push(j);
            }
        }
        self.refresh_normals();
        Some(contact)
    }

    /// Estimates again the normal of every point ground [`NORMAL_REFRESH_MM`] or more since
    /// its last estimate from the current positions of its [`NORMAL_NEIGHBOURS`] nearest
    /// points (turned as the normal it replaces).
    fn refresh_normals(&mut self) {
        if self.stale.is_empty() {
            return;
        }
        let mut around = std::mem::take(&mut self.stale);
        around.sort_unstable();
        around.dedup();
        let renewed: Vec<(usize, Vector3<f64>)> = around
            .iter()
            .map(|&i| {
                let near: Vec<Point3<f64>> = self
                    .index
                    .knn(&self.points[i], NORMAL_NEIGHBOURS)
                    .iter()
                    .map(|nb| self.current(nb.index))
                    .collect();
                let (n, _) = pca_normal(&near, 0..near.len());
                (i, if n.dot(&self.normals[i]) < 0.0 { -n } else { n })
            })
            .collect();
        for (i, n) in renewed {
            self.points[i] = self.current(i);
            self.fresh[i] = self.removal[i];
            self.normals[i] = n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat grid on z = 0 whose normals lean 10 degrees (as a ground bump's flank keeps
    /// those it started with), every point ground 0.01 mm along them: the refresh turns the
    /// normals to the plane's (+z) and leaves every point where it was.
    #[test]
    fn a_refresh_turns_stale_normals_to_the_surface_and_moves_no_point() {
        let points: Vec<Point3<f64>> = (0..400)
            .map(|i| Point3::new(0.05 * (i % 20) as f64, 0.05 * (i / 20) as f64, 0.0))
            .collect();
        let lean = Vector3::new(10f64.to_radians().sin(), 0.0, 10f64.to_radians().cos());
        let mut part = VirtualPart::new(points, vec![lean; 400], &GrindConfig::default());
        part.removal = vec![0.01; 400];
        let before = part.current_points();
        part.stale = (0..400).collect();
        part.refresh_normals();
        for (i, p) in part.current_points().iter().enumerate() {
            assert!((p - before[i]).norm() < 1e-12, "point {i} moved");
            assert!(
                (part.normals[i] - Vector3::z()).norm() < 1e-9,
                "{i}: {}",
                part.normals[i]
            );
        }
        assert!(part.stale.is_empty() && part.fresh == part.removal);
    }
}

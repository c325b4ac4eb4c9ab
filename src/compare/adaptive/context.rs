//! The context every step of the adaptive variant reads: both clouds with their grids, the
//! per-point data [`super::prepare`] computes once (normals, RWME terms, δ, the point pairs),
//! the candidate radii, the core points and the thresholds from the tolerance; with the
//! queries the steps share (cylinders of reference points and of point pairs, summits).
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::point_pair::{Pairing, PAIR_CANDIDATES};
use crate::compare::clouds::Clouds;
use crate::spatial::Neighbours;

/// Per-cloud data shared by all core points (built by [`super::prepare::prepare`]).
pub(super) struct Context<'a> {
    pub(super) clouds: &'a Clouds<'a>,
    pub(super) ref_normals: &'a [Vector3<f64>],
    /// Per storage slot of the reference grid (its order keeps a cylinder's points close in
    /// memory): the point's normal and RWME terms.
    pub(super) ref_slots: Vec<RefSlot>,
    /// Per storage slot of the scan grid: the normal of the reference point the scan point
    /// is paired with ([`Pairing`]) and the point-pair distance from its tangent plane; None
    /// when no reference point is within the reach of a cylinder around a reference point
    /// (looked up when needed).
    pub(super) scan_slots: Vec<Option<(Vector3<f64>, f64)>>,
    pub(super) pairing: Pairing<'a>,
    pub(super) radii: Vec<f64>,
    /// Their squares.
    pub(super) radii2: Vec<f64>,
    /// Half-length of every cylinder: max(max_distance, smallest radius), py4dgeo's rule
    /// with the smallest candidate radius (not the largest: that reached outlier clusters
    /// beyond max_distance; docs/ACCURACY.md, step 1).
    pub(super) half_length: f64,
    /// The core points and their index: [`super::refine`] evaluates the reference points
    /// whose nearest core point is the one refined (its Voronoi cell on the reference).
    pub(super) core: &'a [Point3<f64>],
    pub(super) core_index: Neighbours,
    /// Radius around a core point that holds its cell: twice the core-point spacing.
    pub(super) refine_radius: f64,
    /// Scan noise (one standard deviation along the normal), mm.
    pub(super) noise: f64,
    /// The noise the peak models' guards and the model fill read, mm: `noise`, or the
    /// noise of δ's tail when δ is a mixture of noise levels (a merged scan:
    /// [`super::prepare`]).
    pub(super) model_noise: f64,
    /// Cosine of `max_normal_angle`.
    pub(super) cos_limit: f64,
    /// δ of every reference point ([`super::prepare`]).
    pub(super) delta: Vec<f64>,
    /// The thresholds from the tolerance ([`Thresholds`]).
    pub(super) limits: Thresholds,
    /// Smallest radius of a peak fit's window (`peak.min_window`), mm.
    pub(super) min_peak_window: f64,
    /// Scan points per reference point at the two clouds' median surface densities: how many
    /// scan points a disc's reference points predict (`cover.rs`).
    pub(super) scan_per_reference: f64,
}

/// The thresholds the steps after the cylinders work to, mm: the tolerance given to the
/// comparison and those derived from it (`refine_above`, `densify_above`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Thresholds {
    /// The tolerance on |distance|.
    pub(super) tolerance: f64,
    /// Significant core points beyond this get their peak refined ([`super::refine`]).
    pub(super) refine_above: f64,
    /// Summits beyond this are densified ([`super::densify`]; infinite: off).
    pub(super) densify_above: f64,
}

/// A reference point's data in grid storage order.
pub(super) struct RefSlot {
    pub(super) normal: Vector3<f64>,
    /// RWME terms: w = exp(-|δ|/h) and w·|δ| (NaN when δ is: unscanned surface).
    pub(super) terms: [f64; 2],
    /// A scan point lies within the cover radius of the point (`cover.rs`).
    pub(super) covered: bool,
}

impl Context<'_> {
    /// The core point nearest to `x` (None without core points).
    pub(super) fn nearest_core(&self, x: &Point3<f64>) -> Option<&Point3<f64>> {
        self.nearest_core_id(x).map(|i| &self.core[i])
    }

    /// Index of the core point nearest to `x` (None without core points).
    pub(super) fn nearest_core_id(&self, x: &Point3<f64>) -> Option<usize> {
        self.core_index.knn(x, 1).first().map(|c| c.index)
    }

    /// The smallest candidate radius.
    pub(super) fn smallest_radius(&self) -> f64 {
        self.radii[0]
    }

    /// The largest candidate radius.
    pub(super) fn largest_radius(&self) -> f64 {
        *self.radii.last().expect("radii")
    }

    /// Whether a result is one whose peak [`super::refine`] looks for: significant and
    /// beyond `refine_above`.
    pub(super) fn refined(&self, dev: &crate::compare::deviation::Deviation) -> bool {
        dev.significant && dev.distance.abs() > self.limits.refine_above
    }

    /// Indices of the reference points within `radius` of the axis through `p` along `n` and
    /// within max(`max_distance`, `radius`) of `p` along it, in storage order: a plain
    /// cylinder (py4dgeo's slabs, [`crate::spatial::Grid::cylinder`], leave out a
    /// plane through `p` when the cylinder has two: it lies on their common boundary).
    pub(super) fn reference_near(
        &self,
        p: &Point3<f64>,
        n: &Vector3<f64>,
        radius: f64,
        max_distance: f64,
        out: &mut Vec<usize>,
    ) {
        out.clear();
        self.clouds
            .ref_grid
            .near_axis(p, n, radius, max_distance.max(radius), |slot, _, _| {
                out.push(slot)
            });
    }

    /// Radius of a peak fit's window: the largest candidate radius plus the refine radius
    /// (the cell's reach plus the widest flank a quadric estimate sees), at least
    /// `peak.min_window`.
    pub(super) fn peak_window(&self) -> f64 {
        (self.largest_radius() + self.refine_radius).max(self.min_peak_window)
    }

    /// Calls `f(rho², y - p, pair distance)` for every scan point y within `radius` of the
    /// axis through `p` along `n` (half-length: the cylinders') whose nearest reference
    /// point's normal is within `max_normal_angle` of `n` (`knn`: scratch).
    pub(super) fn scan_pairs(
        &self,
        p: &Point3<f64>,
        n: &Vector3<f64>,
        radius: f64,
        knn: &mut Vec<(f64, u32)>,
        mut f: impl FnMut(f64, Vector3<f64>, f64),
    ) {
        let c = self.clouds;
        c.scan_grid
            .near_axis(p, n, radius, self.half_length, |slot, _, rho2| {
                let y = c.scan_grid.slot_point(slot);
                let y = Point3::new(y[0], y[1], y[2]);
                let (normal, pair) = match self.scan_slots[slot] {
                    Some(nearest) => nearest,
                    None => {
                        c.ref_grid.knn(&y, PAIR_CANDIDATES, f64::INFINITY, knn);
                        let Some(pair) = self.pairing.pair(&y, knn) else {
                            return;
                        };
                        pair
                    }
                };
                if normal.dot(n) >= self.cos_limit {
                    f(rho2, y - p, pair);
                }
            });
    }

    /// Those of the points `ids` (of `points`) whose |value| (`values` per point) is the
    /// largest among the points of `ids` of the same sign within the refine radius (ties: the
    /// lower index): one per bump, a few along a ridge.
    pub(super) fn summits(
        &self,
        points: &[Point3<f64>],
        ids: &[usize],
        values: &[f64],
    ) -> Vec<usize> {
        let pts: Vec<Point3<f64>> = ids.iter().map(|&i| points[i]).collect();
        let index = Neighbours::new(&pts);
        let magnitude = |k: usize| values[ids[k]].abs();
        let sign = |k: usize| values[ids[k]] > 0.0;
        (0..pts.len())
            .into_par_iter()
            .filter(|&k| {
                index
                    .within_unsorted(&pts[k], self.refine_radius)
                    .iter()
                    .filter(|nb| nb.index != k && sign(nb.index) == sign(k))
                    .all(|nb| (magnitude(k), nb.index) > (magnitude(nb.index), k))
            })
            .map(|k| ids[k])
            .collect()
    }
}

/// Two unit vectors completing `n` to a right-handed frame.
pub(super) fn tangent_frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    // The helper axis must be far from parallel to `n` (|n.x| < 0.9: at least 25° off x).
    let helper = if n.x.abs() < FRAME_HELPER_LIMIT {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    (e1, n.cross(&e1))
}

/// [`tangent_frame`] crosses `n` with x unless |n.x| reaches this (then y): the cross product
/// stays well conditioned.
const FRAME_HELPER_LIMIT: f64 = 0.9;

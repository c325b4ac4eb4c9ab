//! The point-pair distance: each scan point is paired with a reference point, and its
//! distance is its height above that point's tangent plane (along the reference normal). The
//! pair's normal also decides which cylinders take the scan point (the normal filter). At an
//! edge the nearest reference point is often the other face's: [`Pairing::pair`] has the
//! rules there.
use nalgebra::{Point3, Vector3};

use crate::compare::clouds::Clouds;
use crate::spatial::Grid;

/// Reference points a scan point's pairing looks among ([`Pairing::pair`]).
pub(super) const PAIR_CANDIDATES: usize = 4;

/// Candidates of a scan point's pairing whose normals differ by more than this (degrees) lie
/// on two faces of an edge ([`Pairing::pair`]). Facets of a smooth surface differ by a few
/// degrees over a reference spacing; 10, 15 and 20 gave the same accuracy-test numbers.
const EDGE_ANGLE: f64 = 15.0;

/// Which reference point a scan point is paired with: its point-pair distance is measured from
/// that point's tangent plane, and its normal decides which cylinders take the scan point.
pub(super) struct Pairing<'a> {
    clouds: &'a Clouds<'a>,
    ref_normals: &'a [Vector3<f64>],
    /// Cosine of the normal filter's angle (`max_normal_angle`).
    cos_limit: f64,
    /// Cosine of [`EDGE_ANGLE`].
    edge_cos: f64,
    /// Reach of a reference point's patch across its normal: the 90th percentile of the scan
    /// points' nearest-reference distance.
    over: f64,
}

impl Pairing<'_> {
    /// The normal and pair distance of scan point `y` given its nearest reference points
    /// `found` (squared distance, index; nearest first; None when empty): the nearest one's,
    /// unless a candidate's normal differs from it by more than [`EDGE_ANGLE`] (an edge within
    /// reach). At an edge a scan point of one face within a reference spacing of the edge is
    /// often nearer to a reference point of the other face, and lies off its tangent plane by
    /// up to the spacing times the sine of the edge's angle. Then:
    /// - beyond the normal filter's angle (a sharp edge, whose faces' points no cylinder
    ///   shares): the candidate whose patch is closest to `y`, a patch being the candidate's
    ///   tangent plane within `over` of it: distance² = t² + max(0, a − over)² for a height t
    ///   above the plane and an offset a across the normal (seed 24 at 300k: four of the nine
    ///   scan points of a narrow face were paired with the other face, 0.05-0.1 mm above its
    ///   plane, and three core points read 0.055 mm where the truth is 0);
    /// - a shallower edge: of the nearest candidate and the nearest one of the other face, the
    ///   upper plane at a convex edge and the lower one at a concave edge, as the surface of
    ///   a solid bounded by the two faces (seed 37 at 300k: a narrow face between faces 23-35°
    ///   off read +0.013 to +0.063 mm towards a corner, and 4 core points made a region where
    ///   the truth is 0). Not the closest patch there: a defect's height above one face is
    ///   smaller above the other's plane, and the closest patch reads it low (seed 15's
    ///   0.32 mm ridge across a 26° edge: RMS 0.0081 → 0.0287 mm).
    pub(super) fn pair(
        &self,
        y: &Point3<f64>,
        found: &[(f64, u32)],
    ) -> Option<(Vector3<f64>, f64)> {
        let (_, first) = *found.first()?;
        let normal = &self.ref_normals[first as usize];
        let at = |i: u32| {
            let n = self.ref_normals[i as usize];
            (n, n.dot(&(y - self.clouds.reference.points[i as usize])))
        };
        let cos_to_first = |i: u32| self.ref_normals[i as usize].dot(normal);
        let Some(other) = found
            .iter()
            .map(|&(_, i)| i)
            .find(|&i| cos_to_first(i) < self.edge_cos)
        else {
            return Some(at(first));
        };
        if found.iter().any(|&(_, i)| cos_to_first(i) < self.cos_limit) {
            let patch_distance2 = |d2: f64, t: f64| {
                let across = (d2 - t * t).max(0.0).sqrt();
                t * t + (across - self.over).max(0.0).powi(2)
            };
            return found
                .iter()
                .map(|&(d2, i)| {
                    let pair = at(i);
                    (patch_distance2(d2, pair.1), pair)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, pair)| pair);
        }
        // Convex when each point lies below the other's tangent plane.
        let points = &self.clouds.reference.points;
        let convex = (normal - self.ref_normals[other as usize])
            .dot(&(points[other as usize] - points[first as usize]))
            < 0.0;
        let (near, far) = (at(first), at(other));
        Some(match convex == (near.1 >= far.1) {
            true => near,
            false => far,
        })
    }
}

impl<'a> Pairing<'a> {
    /// The pairing over `clouds` with the reference normals `ref_normals` and the normal
    /// filter's cosine `cos_limit`.
    pub(super) fn new(
        clouds: &'a Clouds<'a>,
        ref_normals: &'a [Vector3<f64>],
        cos_limit: f64,
    ) -> Pairing<'a> {
        Pairing {
            clouds,
            ref_normals,
            cos_limit,
            edge_cos: EDGE_ANGLE.to_radians().cos(),
            over: clouds.ref_grid.typical_kth(&clouds.scan.points, 1),
        }
    }

    /// Per scan point (file order): the normal of its paired reference point and its
    /// point-pair distance, for the scan points with a reference point within `reach`
    /// (None for the others: looked up when a cylinder meets them).
    pub(super) fn pair_scan_points(&self, reach: f64) -> Vec<Option<(Vector3<f64>, f64)>> {
        let clouds = self.clouds;
        let (reference, scan) = (&clouds.ref_grid, &clouds.scan_grid);
        each_nearest(
            reference,
            scan,
            &clouds.scan.points,
            PAIR_CANDIDATES,
            reach,
            |j, found| self.pair(&clouds.scan.points[j], found),
        )
    }
}

/// `f(i, found)` for every point i of `queries` (its `points`, in file order): `found` its
/// `k` nearest points of `targets` within `reach` (squared distance, index; nearest first),
/// searched in one batch over both grids.
pub(super) fn each_nearest<R: Send>(
    targets: &Grid,
    queries: &Grid,
    points: &[Point3<f64>],
    k: usize,
    reach: f64,
    f: impl Fn(usize, &[(f64, u32)]) -> R + Sync,
) -> Vec<R> {
    let halo = targets.typical_kth(points, k);
    targets.knn_each(queries, k, reach, halo, f)
}

//! Points inside an M3C2 cylinder, with py4dgeo 1.2's semantics: the cylinder of radius r
//! around the axis through the core point along the normal extends L = max(max_distance, r)
//! both ways; it is cut into N = ceil(L / r) slabs (N = 1 when max_distance <= r), each
//! searched with a ball of radius sqrt(r² + (L/N)²) around its midpoint; a point belongs when
//! its squared distance to the axis is <= r² and its distance along the axis from the slab's
//! midpoint is < L/N.
use nalgebra::{Point3, Vector3};

use crate::cloud::Neighbours;

/// A point inside a cylinder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Member {
    /// Index into the searched cloud.
    pub index: usize,
    /// Signed offset along the axis from the core point, mm.
    pub t: f64,
    /// Squared distance from the axis, mm².
    pub rho2: f64,
}

/// The members of the cylinder (radius `radius`, half-length from `max_distance`) around the
/// axis through `core` along the unit vector `axis`, slab by slab.
pub fn members(
    index: &Neighbours,
    points: &[Point3<f64>],
    core: &Point3<f64>,
    axis: &Vector3<f64>,
    radius: f64,
    max_distance: f64,
) -> Vec<Member> {
    let (length, slabs) = if max_distance > radius {
        (max_distance, (max_distance / radius).ceil())
    } else {
        (radius, 1.0)
    };
    let half = length / slabs;
    let ball = (radius * radius + half * half).sqrt();
    let r2 = radius * radius;
    let mut out = Vec::new();
    for i in 0..slabs as usize {
        let offset = (2.0 * i as f64 + 1.0 - slabs) / slabs * length;
        let mid = core + axis * offset;
        for n in index.within_unsorted(&mid, ball) {
            let d = points[n.index] - mid;
            let along = d.dot(axis);
            let rho2 = (d - axis * along).norm_squared();
            if rho2 <= r2 && along.abs() < half {
                out.push(Member {
                    index: n.index,
                    t: along + offset,
                    rho2,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn members_match_a_brute_force_cylinder() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let points: Vec<Point3<f64>> = (0..5000)
            .map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()) * 4.0)
            .collect();
        let index = Neighbours::new(&points);
        let core = Point3::new(2.0, 2.0, 2.0);
        let axis = Vector3::new(1.0, 2.0, 2.0).normalize();
        for (r, l) in [(0.3, 1.0), (0.5, 0.2), (0.4, 1.9)] {
            let mut got: Vec<usize> = members(&index, &points, &core, &axis, r, l)
                .iter()
                .map(|m| m.index)
                .collect();
            got.sort();
            let len = if l > r { l } else { r };
            let want: Vec<usize> = (0..points.len())
                .filter(|&i| {
                    let d = points[i] - core;
                    let t = d.dot(&axis);
                    (d - axis * t).norm() <= r && t.abs() < len
                })
                .collect();
            assert_eq!(got, want, "r {r} l {l}");
        }
    }
}

//! Fast Point Feature Histograms (Rusu et al. 2009) exactly as Open3D computes them
//! (`compute_fpfh_feature`): 3 Darboux-frame quantities, 11 bins each, SPFH of the neighbours
//! weighted by inverse squared distance, then the point's own SPFH added.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::spatial::Grid;

/// Number of histogram bins of one feature.
pub const FPFH_BINS: usize = 33;

/// One FPFH descriptor.
pub type Fpfh = [f64; FPFH_BINS];

/// The pair feature (alpha-like angle `theta`, `phi`, `alpha`) of Open3D's
/// `ComputePairFeatures`, or None for coincident points or a degenerate frame.
fn pair_features(
    p1: &Point3<f64>,
    n1: &Vector3<f64>,
    p2: &Point3<f64>,
    n2: &Vector3<f64>,
) -> Option<[f64; 3]> {
    let mut dp = p2 - p1;
    let d = dp.norm();
    if d == 0.0 {
        return None;
    }
    let (mut a, mut b) = (n1, n2);
    let angle1 = n1.dot(&dp) / d;
    let angle2 = n2.dot(&dp) / d;
    // Open3D compares acos(|angle1|) > acos(|angle2|); acos decreases, so compare the
    // cosines (two acos calls fewer per pair).
    let f2 = if angle1.abs() < angle2.abs() {
        a = n2;
        b = n1;
        dp = -dp;
        -angle2
    } else {
        angle1
    };
    let v = dp.cross(a);
    let vn = v.norm();
    if vn == 0.0 {
        return None;
    }
    let v = v / vn;
    let w = a.cross(&v);
    let f1 = v.dot(b);
    let f0 = w.dot(b).atan2(a.dot(b));
    Some([f0, f1, f2])
}

/// Histogram bin (0..11) of a value in [lo, lo + span].
fn bin(value: f64, lo: f64, span: f64) -> usize {
    ((11.0 * (value - lo) / span).floor().max(0.0) as usize).min(10)
}

/// FPFH of every point. Neighbourhoods are Open3D's hybrid search: at most `max_nn` nearest
/// points within `radius` (the point itself included and skipped). A point without neighbours
/// gets an all-zero descriptor.
pub fn compute_fpfh(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    radius: f64,
    max_nn: usize,
) -> Vec<Fpfh> {
    let all: Vec<usize> = (0..points.len()).collect();
    compute_fpfh_at(points, normals, radius, max_nn, &all)
}

/// FPFH of the points at `at` (indices), computed over the whole cloud (the SPFH of every
/// point is needed by its neighbours).
pub fn compute_fpfh_at(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    radius: f64,
    max_nn: usize,
    at: &[usize],
) -> Vec<Fpfh> {
    // Open3D's hybrid search: the max_nn nearest within the radius, nearest first, ties to
    // the lowest index (the point itself comes first, at distance 0), batched on a grid.
    let neighbours: Vec<Vec<(usize, f64)>> = Grid::knn_among(points, max_nn, radius, |_, found| {
        found.iter().map(|&(d2, j)| (j as usize, d2)).collect()
    });
    let spfh: Vec<Fpfh> = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut h = [0.0; FPFH_BINS];
            let nb = &neighbours[i];
            if nb.len() > 1 {
                let incr = 100.0 / (nb.len() - 1) as f64;
                for &(j, _) in &nb[1..] {
                    let f = pair_features(&points[i], &normals[i], &points[j], &normals[j])
                        .unwrap_or([0.0; 3]);
                    h[bin(f[0], -std::f64::consts::PI, 2.0 * std::f64::consts::PI)] += incr;
                    h[11 + bin(f[1], -1.0, 2.0)] += incr;
                    h[22 + bin(f[2], -1.0, 2.0)] += incr;
                }
            }
            h
        })
        .collect();
    at.par_iter()
        .map(|&i| {
            let mut h = [0.0; FPFH_BINS];
            let nb = &neighbours[i];
            if nb.len() > 1 {
                for &(j, d2) in &nb[1..] {
                    if d2 == 0.0 {
                        continue;
                    }
                    let inv = 1.0 / d2;
                    for (hb, sb) in h.iter_mut().zip(&spfh[j]) {
                        *hb += sb * inv;
                    }
                }
                // Each 11-bin block's total (Open3D sums it along the way: the same terms).
                let sum: [f64; 3] = std::array::from_fn(|k| h[11 * k..11 * (k + 1)].iter().sum());
                let scale = sum.map(|s| if s != 0.0 { 100.0 / s } else { 0.0 });
                for (b, hb) in h.iter_mut().enumerate() {
                    *hb = *hb * scale[b / 11] + spfh[i][b];
                }
            }
            h
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Translation3};
    use rand::{Rng, SeedableRng};

    #[test]
    fn rotation_and_translation_leave_features_unchanged() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        // Points on a bumpy height field with analytic normals.
        let mut pts = Vec::new();
        let mut nrm = Vec::new();
        for _ in 0..800 {
            let (x, y): (f64, f64) = (rng.gen_range(-5.0..5.0), rng.gen_range(-5.0..5.0));
            let z = (x * 0.7).sin() + 0.5 * (y * 0.9).cos();
            pts.push(Point3::new(x, y, z));
            nrm.push(Vector3::new(-0.7 * (x * 0.7).cos(), 0.45 * (y * 0.9).sin(), 1.0).normalize());
        }
        let a = compute_fpfh(&pts, &nrm, 1.5, 100);
        let iso = nalgebra::Isometry3::from_parts(
            Translation3::new(3.0, -2.0, 7.0),
            Rotation3::from_euler_angles(0.3, -1.1, 2.0).into(),
        );
        let pts2: Vec<_> = pts.iter().map(|p| iso * p).collect();
        let nrm2: Vec<_> = nrm.iter().map(|n| iso.rotation * n).collect();
        let b = compute_fpfh(&pts2, &nrm2, 1.5, 100);
        for (fa, fb) in a.iter().zip(&b) {
            for k in 0..FPFH_BINS {
                assert!((fa[k] - fb[k]).abs() < 1e-6 * (1.0 + fa[k].abs()));
            }
            let total: f64 = fa.iter().sum();
            assert!(
                total == 0.0 || (total - 600.0).abs() < 1e-6,
                "three histograms of 200"
            );
        }
    }
}

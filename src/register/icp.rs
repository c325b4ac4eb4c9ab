//! Point-to-plane ICP with a robust (Geman–McClure) kernel: defects and outliers are
//! down-weighted instead of pulling the pose.
use nalgebra::{Isometry3, Matrix6, Point3, Vector3, Vector6};
use rayon::prelude::*;
use serde::Serialize;

use crate::spatial::Grid;

/// Settings of one ICP run (lengths in mm).
#[derive(Debug, Clone, Copy)]
pub struct IcpParams {
    /// Pairs farther apart than this are ignored (and count against fitness).
    pub max_distance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
    /// Converged when fitness and inlier RMSE both change by less than this, relatively.
    pub relative_tolerance: f64,
    /// Geman–McClure scale `k` (weight `(k² / (k² + r²))²`); None: `3 × 1.4826 × median |r|`
    /// each iteration (a robust noise estimate), never below `min_kernel_scale`.
    pub kernel_scale: Option<f64>,
    /// Floor of the adaptive kernel scale.
    pub min_kernel_scale: f64,
}

/// Result of an ICP run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct IcpResult {
    /// Final scan-to-reference pose.
    #[serde(skip)]
    pub pose: Isometry3<f64>,
    /// Iterations run.
    pub iterations: usize,
    /// True when the tolerance was met before the iteration cap.
    pub converged: bool,
    /// Fraction of source points with a target point within `max_distance` (final pose).
    pub fitness: f64,
    /// RMS point-to-point distance of those pairs (mm).
    pub inlier_rmse: f64,
    /// RMS point-to-plane residual of those pairs (mm).
    pub plane_rmse: f64,
    /// Kernel scale of the last iteration (mm).
    pub kernel_scale: f64,
    /// How far the pose's statistical uncertainty can move the surface: the largest 1-σ
    /// displacement along the target normal over the matched points (mm), from the
    /// cluster-robust covariance of the pose ([`pose_std`]). NaN when the pose is not
    /// determined (too few pairs or blocks).
    pub pose_std: f64,
}

/// Edge of the cubes that group the residuals of [`pose_std`] (mm): residuals within a cube
/// may be correlated (a defect, a scanner stripe), residuals of different cubes are taken as
/// independent. Larger than the widest defect the synthetic cases plant (3 mm).
pub const UNCERTAINTY_BLOCK: f64 = 15.0;

/// The pose's statistical uncertainty projected on the surface: the largest 1-σ displacement
/// along a target normal over `pairs` (moved point, target index, residual, ...) under the
/// pose covariance `H⁻¹ M H⁻¹`. `H = Σ w J Jᵀ` is the Gauss–Newton matrix of the robust
/// point-to-plane fit (`w` the Geman–McClure weight with scale `k`, `J = [q × n, n]`) and
/// `M = G/(G-1) Σ_b s_b s_bᵀ` sums the score `s_b = Σ_{i∈b} w_i r_i J_i` of each
/// [`UNCERTAINTY_BLOCK`] cube `b` (a cluster-robust sandwich: it holds when residuals are
/// correlated within a cube). NaN when fewer than 7 cubes hold pairs or `H` is singular.
pub fn pose_std(pairs: &[(Point3<f64>, usize, f64, f64)], normals: &[Vector3<f64>], k: f64) -> f64 {
    let k2 = k * k;
    let mut h = Matrix6::<f64>::zeros();
    // Ordered by key, so the sums below run in the same order on every run.
    let mut blocks: std::collections::BTreeMap<[i64; 3], Vector6<f64>> = Default::default();
    for &(q, j, r, _) in pairs {
        let jac = jacobian(&q, &normals[j]);
        let w = weight(r, k2);
        h += jac * jac.transpose() * w;
        let key = q.coords.map(|c| (c / UNCERTAINTY_BLOCK).floor() as i64);
        *blocks.entry([key.x, key.y, key.z]).or_default() += jac * (w * r);
    }
    let g = blocks.len() as f64;
    let Some(h_inv) = h.try_inverse().filter(|_| blocks.len() >= 7) else {
        return f64::NAN;
    };
    let meat = blocks
        .values()
        .fold(Matrix6::zeros(), |m, s| m + s * s.transpose())
        * (g / (g - 1.0));
    let cov = h_inv * meat * h_inv;
    pairs
        .iter()
        .map(|(q, j, _, _)| {
            let jac = jacobian(q, &normals[*j]);
            (jac.transpose() * cov * jac)[0].max(0.0).sqrt()
        })
        .fold(0.0, f64::max)
}

/// Geman–McClure weight `(k² / (k² + r²))²` of residual `r` (`k2` = k²).
fn weight(r: f64, k2: f64) -> f64 {
    (k2 / (k2 + r * r)).powi(2)
}

/// Derivative of the point-to-plane residual of `q` (target normal `n`) with respect to a
/// small move (rotation vector, translation) applied in the target frame: `[q × n, n]`.
fn jacobian(q: &Point3<f64>, n: &Vector3<f64>) -> Vector6<f64> {
    let c = q.coords.cross(n);
    Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z)
}

/// Pairs per partial sum of a linearisation ([`Step`]).
const SUM_CHUNK: usize = 4096;

/// One linearisation: normal equations plus the statistics at the current pose.
#[derive(Default)]
struct Step {
    a: Matrix6<f64>,
    b: Vector6<f64>,
    pairs: usize,
    sum_d2: f64,
    sum_r2: f64,
}

impl Step {
    fn add(mut self, o: Step) -> Step {
        self.a += o.a;
        self.b += o.b;
        self.pairs += o.pairs;
        self.sum_d2 += o.sum_d2;
        self.sum_r2 += o.sum_r2;
        self
    }
}

/// A moved source point's nearest target point (index, squared distance), if within reach.
type Nearest = Option<(usize, f64)>;

/// The nearest indexed point (index, squared distance) of each source point under `pose`,
/// when within `max_distance` (inclusive); ties to the lowest index. Also the moved points.
fn nearest_each(
    src: &[Point3<f64>],
    index: &Grid,
    pose: &Isometry3<f64>,
    max_distance: f64,
) -> (Vec<Point3<f64>>, Vec<Nearest>) {
    let moved: Vec<Point3<f64>> = src.par_iter().map(|s| pose * s).collect();
    let queries = Grid::new(&moved, index.cell());
    let found = index.knn_each(&queries, 1, max_distance, 0.5 * index.cell(), |_, nb| {
        nb.first().map(|&(d2, j)| (j as usize, d2))
    });
    (moved, found)
}

/// Matches every source point under `pose`: (point in target frame, target index) for pairs
/// within the distance, with the point-to-plane residual.
fn residuals(
    src: &[Point3<f64>],
    target: &[Point3<f64>],
    normals: &[Vector3<f64>],
    index: &Grid,
    pose: &Isometry3<f64>,
    max_distance: f64,
) -> Vec<(Point3<f64>, usize, f64, f64)> {
    let (moved, found) = nearest_each(src, index, pose, max_distance);
    moved
        .iter()
        .zip(found)
        .filter_map(|(q, nb)| {
            let (j, d2) = nb?;
            Some((*q, j, normals[j].dot(&(q - target[j])), d2))
        })
        .collect()
}

/// Share of `src` points (under `pose`) with a target point within `distance`, and the RMS
/// distance of those pairs.
pub fn fitness(
    src: &[Point3<f64>],
    index: &Grid,
    pose: &Isometry3<f64>,
    distance: f64,
) -> (f64, f64) {
    let (_, found) = nearest_each(src, index, pose, distance);
    let (n, sum) = found
        .iter()
        .flatten()
        .fold((0usize, 0.0), |(n, s), &(_, d2)| (n + 1, s + d2));
    (
        n as f64 / src.len().max(1) as f64,
        (sum / n.max(1) as f64).sqrt(),
    )
}

fn median_abs(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.map(f64::abs).collect();
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Aligns `src` to the target surface (points, unit normals, their row grid
/// [`Grid::for_points`]: the searches of all source points run as one batch) from `init`.
pub fn icp(
    src: &[Point3<f64>],
    target: &[Point3<f64>],
    normals: &[Vector3<f64>],
    index: &Grid,
    init: &Isometry3<f64>,
    p: &IcpParams,
) -> IcpResult {
    let n = src.len().max(1) as f64;
    let mut pose = *init;
    let mut last: Option<(f64, f64)> = None;
    let mut result = IcpResult {
        pose,
        iterations: 0,
        converged: false,
        fitness: 0.0,
        inlier_rmse: 0.0,
        plane_rmse: 0.0,
        kernel_scale: 0.0,
        pose_std: f64::NAN,
    };
    let mut final_pairs = Vec::new();
    for it in 0..=p.max_iterations {
        let pairs = residuals(src, target, normals, index, &pose, p.max_distance);
        let k = p.kernel_scale.unwrap_or_else(|| {
            (3.0 * 1.4826 * median_abs(pairs.iter().map(|e| e.2))).max(p.min_kernel_scale)
        });
        let k2 = k * k;
        // Fixed chunks summed in order: the same sums (and pose) on every run, whatever
        // thread took which chunk.
        let step = pairs
            .par_chunks(SUM_CHUNK)
            .map(|chunk| {
                chunk.iter().fold(Step::default(), |mut s, &(q, j, r, d2)| {
                    let jac = jacobian(&q, &normals[j]);
                    let w = weight(r, k2);
                    s.a += jac * jac.transpose() * w;
                    s.b += jac * (w * r);
                    s.pairs += 1;
                    s.sum_d2 += d2;
                    s.sum_r2 += r * r;
                    s
                })
            })
            .collect::<Vec<Step>>()
            .into_iter()
            .fold(Step::default(), Step::add);
        let fitness = step.pairs as f64 / n;
        let pairs_f = step.pairs.max(1) as f64;
        let rmse = (step.sum_d2 / pairs_f).sqrt();
        result = IcpResult {
            pose,
            iterations: it,
            converged: false,
            fitness,
            inlier_rmse: rmse,
            plane_rmse: (step.sum_r2 / pairs_f).sqrt(),
            kernel_scale: k,
            pose_std: f64::NAN,
        };
        final_pairs = pairs;
        if let Some((f0, r0)) = last {
            let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-300);
            if rel(fitness, f0) < p.relative_tolerance && rel(rmse, r0) < p.relative_tolerance {
                result.converged = true;
                break;
            }
        }
        if it == p.max_iterations || step.pairs < 6 {
            break;
        }
        last = Some((fitness, rmse));
        let Some(x) = step.a.cholesky().map(|c| c.solve(&(-step.b))) else {
            break;
        };
        let delta = Isometry3::new(
            Vector3::new(x[3], x[4], x[5]),
            Vector3::new(x[0], x[1], x[2]),
        );
        pose = delta * pose;
        if x.norm() < 1e-13 {
            result.pose = pose;
            result.converged = true;
            break;
        }
    }
    result.pose_std = pose_std(&final_pairs, normals, result.kernel_scale);
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn recovers_a_small_move_on_a_sphere_with_outliers() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let sphere = |rng: &mut rand_chacha::ChaCha8Rng| {
            let v = Vector3::new(
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0),
                rng.gen_range(-1.0..1.0f64),
            )
            .normalize();
            // An ellipsoid-ish bumpy surface so that no rotation is unconstrained.
            let r = 20.0 + 2.0 * (3.0 * v.x).sin() + 1.5 * (2.0 * v.y).cos();
            Point3::from(v * r)
        };
        let target: Vec<Point3<f64>> = (0..40_000).map(|_| sphere(&mut rng)).collect();
        let index = Grid::for_points(&target);
        let normals = crate::preprocess::estimate_normals(
            &crate::cloud::PointCloud::from_points(target.clone()),
            &crate::preprocess::NormalConfig::default(),
        )
        .unwrap()
        .normals;
        let truth = Isometry3::new(
            Vector3::new(0.3, -0.2, 0.25),
            Vector3::new(0.01, -0.02, 0.015),
        );
        let mut src: Vec<Point3<f64>> = (0..8_000)
            .map(|_| truth.inverse() * sphere(&mut rng))
            .collect();
        for p in src.iter_mut().take(400) {
            *p += Vector3::new(0.0, 0.0, 1.5); // a "defect" patch of outliers
        }
        let r = icp(
            &src,
            &target,
            &normals,
            &index,
            &Isometry3::identity(),
            &IcpParams {
                max_distance: 3.0,
                max_iterations: 60,
                relative_tolerance: 1e-9,
                kernel_scale: None,
                min_kernel_scale: 0.01,
            },
        );
        let err = r.pose.inverse() * truth;
        assert!(err.translation.vector.norm() < 0.01, "{:?}", err);
        assert!(err.rotation.angle().to_degrees() < 0.02);
        assert!(r.fitness > 0.9);
    }
}

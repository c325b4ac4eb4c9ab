//! Poses from correspondences: weighted SVD (Umeyama without scale), the MAE score over all
//! correspondences, and iterative re-weighted refinement.
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// The rigid transform `T` minimising `sum w_i |T s_i - t_i|²` (Umeyama 1991 with weighted
/// centroids, reflection corrected). None when fewer than 3 points carry weight or the points
/// are degenerate (collinear).
pub fn weighted_svd(
    src: &[Point3<f64>],
    dst: &[Point3<f64>],
    weights: &[f64],
) -> Option<Isometry3<f64>> {
    let wsum: f64 = weights.iter().sum();
    if weights.iter().filter(|&&w| w > 0.0).count() < 3 || wsum.is_nan() || wsum <= 0.0 {
        return None;
    }
    let mut cs = Vector3::zeros();
    let mut cd = Vector3::zeros();
    for ((s, d), &w) in src.iter().zip(dst).zip(weights) {
        cs += s.coords * w;
        cd += d.coords * w;
    }
    cs /= wsum;
    cd /= wsum;
    let mut h = Matrix3::zeros();
    for ((s, d), &w) in src.iter().zip(dst).zip(weights) {
        h += (s.coords - cs) * (d.coords - cd).transpose() * w;
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let sv = svd.singular_values;
    if sv[1] <= 1e-12 * sv[0].max(1e-300) {
        return None;
    }
    let v = v_t.transpose();
    let mut fix = Matrix3::identity();
    if (v * u.transpose()).determinant() < 0.0 {
        fix[(2, 2)] = -1.0;
    }
    let r = Rotation3::from_matrix_unchecked(v * fix * u.transpose());
    let t = cd - r * cs;
    Some(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_rotation_matrix(&r),
    ))
}

/// MAE score of a pose over all correspondences: `sum over |T s_i - t_i| < tau of
/// (tau - e_i) / tau`, and the number of inliers.
pub fn mae_score(
    pose: &Isometry3<f64>,
    src: &[Point3<f64>],
    dst: &[Point3<f64>],
    tau: f64,
) -> (f64, usize) {
    let mut score = 0.0;
    let mut inliers = 0;
    for (s, d) in src.iter().zip(dst) {
        let e = (pose * s - d).norm();
        if e < tau {
            score += (tau - e) / tau;
            inliers += 1;
        }
    }
    (score, inliers)
}

/// Iterative re-weighted SVD: re-solve with weights `(tau - e_i) / tau` of the current inliers
/// until the inlier set stops changing (at most `iterations` rounds). Keeps the best-scoring pose.
pub fn refine(
    pose: &Isometry3<f64>,
    src: &[Point3<f64>],
    dst: &[Point3<f64>],
    tau: f64,
    iterations: usize,
) -> Isometry3<f64> {
    let mut best = *pose;
    let mut best_score = mae_score(pose, src, dst, tau).0;
    let mut current = *pose;
    let mut last_inliers: Vec<bool> = Vec::new();
    for _ in 0..iterations {
        let errs: Vec<f64> = src
            .iter()
            .zip(dst)
            .map(|(s, d)| (current * s - d).norm())
            .collect();
        let inl: Vec<bool> = errs.iter().map(|&e| e < tau).collect();
        if inl == last_inliers {
            break;
        }
        let w: Vec<f64> = errs.iter().map(|&e| ((tau - e) / tau).max(0.0)).collect();
        let Some(next) = weighted_svd(src, dst, &w) else {
            break;
        };
        let score = mae_score(&next, src, dst, tau).0;
        if score > best_score {
            best_score = score;
            best = next;
        }
        current = next;
        last_inliers = inl;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn exact_correspondences_give_the_exact_pose() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for _ in 0..20 {
            let truth = Isometry3::new(
                Vector3::new(
                    rng.gen_range(-60.0..60.0),
                    rng.gen_range(-60.0..60.0),
                    rng.gen_range(-60.0..60.0),
                ),
                Vector3::new(
                    rng.gen_range(-3.0..3.0),
                    rng.gen_range(-3.0..3.0),
                    rng.gen_range(-3.0..3.0),
                ),
            );
            let src: Vec<Point3<f64>> = (0..10)
                .map(|_| {
                    Point3::new(
                        rng.gen_range(-30.0..30.0),
                        rng.gen_range(-30.0..30.0),
                        rng.gen_range(-30.0..30.0),
                    )
                })
                .collect();
            let dst: Vec<Point3<f64>> = src.iter().map(|p| truth * p).collect();
            let w: Vec<f64> = (0..10).map(|_| rng.gen_range(0.5..2.0)).collect();
            let got = weighted_svd(&src, &dst, &w).unwrap();
            let diff = got.inverse() * truth;
            assert!(diff.translation.vector.norm() < 1e-9);
            assert!(diff.rotation.angle() < 1e-9);
        }
    }

    #[test]
    fn zero_weights_ignore_outliers_and_collinear_points_are_refused() {
        let truth = Isometry3::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(0.1, 0.2, 0.3));
        let src = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(5.0, 5.0, 5.0),
        ];
        let mut dst: Vec<_> = src.iter().map(|p| truth * p).collect();
        dst[4] = Point3::new(-40.0, 7.0, 0.0);
        let got = weighted_svd(&src, &dst, &[1.0, 1.0, 1.0, 1.0, 0.0]).unwrap();
        assert!((got.inverse() * truth).translation.vector.norm() < 1e-12);
        let start = Isometry3::new(
            Vector3::new(0.1, -0.1, 0.05),
            Vector3::new(0.02, 0.0, -0.03),
        ) * truth;
        let refined = refine(&start, &src, &dst, 1.0, 10);
        let diff = refined.inverse() * truth;
        assert!(diff.translation.vector.norm() < 1e-9 && diff.rotation.angle() < 1e-9);
        assert_eq!(mae_score(&refined, &src, &dst, 1e-6).1, 4);
        let line = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
        ];
        assert!(weighted_svd(&line, &line, &[1.0; 3]).is_none());
    }
}

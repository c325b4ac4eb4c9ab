//! Curvature-aware down-sampling (the paper's section C): the mean angle between a point's
//! normal and its neighbours' normals splits the cloud into a feature region (above a
//! threshold angle) and a non-feature region; each is sampled uniformly, the feature region
//! giving N·(1-J) points and the non-feature region N·J (N target count, J uniform ratio).
use anyhow::{bail, Result};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::normals::{estimate_normals, NormalConfig, Orientation};
use crate::cloud::PointCloud;
use crate::spatial::Neighbours;

/// Settings of curvature-aware sampling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CurvatureSampleConfig {
    /// N: points to keep. Default 20,000.
    pub target: usize,
    /// J: share of N drawn uniformly from the non-feature (flat) region; the feature region
    /// gives N·(1-J). Default 0.5.
    pub uniform_ratio: f64,
    /// A point whose mean normal angle to its neighbours exceeds this is a feature point
    /// (degrees). Default 5.
    pub feature_angle_deg: f64,
    /// k: neighbours (other than the point) over which the angle is averaged. Default 10.
    pub k: usize,
    /// Optional search radius (mm) bounding those neighbours. Default none.
    pub radius: Option<f64>,
    /// PCA neighbourhood of the normals (their sign is not used: angles are between axes).
    /// Default 20 neighbours, no radius.
    pub normal_k: usize,
    /// Seed of the uniform draws. Default 0.
    pub seed: u64,
}

impl Default for CurvatureSampleConfig {
    fn default() -> Self {
        CurvatureSampleConfig {
            target: 20_000,
            uniform_ratio: 0.5,
            feature_angle_deg: 5.0,
            k: 10,
            radius: None,
            normal_k: 20,
            seed: 0,
        }
    }
}

/// The sample and how it was drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvatureSample {
    /// Indices of the kept points (into the sampled cloud), ascending.
    pub indices: Vec<usize>,
    /// Per input point: true in the feature region.
    pub feature: Vec<bool>,
    /// Per input point: mean angle between its normal axis and its neighbours' (degrees).
    pub mean_angle_deg: Vec<f64>,
    /// Points in the feature region.
    pub feature_points: usize,
    /// Kept points from the feature region.
    pub kept_feature: usize,
    /// Kept points from the non-feature region.
    pub kept_flat: usize,
}

fn check(cfg: &CurvatureSampleConfig, n: usize) -> Result<()> {
    if n == 0 {
        bail!("curvature sampling: the cloud is empty");
    }
    if cfg.target == 0 {
        bail!("curvature sampling: the target count must be at least 1");
    }
    if !(0.0..=1.0).contains(&cfg.uniform_ratio) {
        bail!(
            "curvature sampling: uniform ratio J must be in [0, 1] (got {:?})",
            cfg.uniform_ratio
        );
    }
    if !(cfg.feature_angle_deg >= 0.0 && cfg.feature_angle_deg <= 90.0) {
        bail!(
            "curvature sampling: feature angle must be in [0, 90] degrees (got {:?})",
            cfg.feature_angle_deg
        );
    }
    if cfg.k == 0 || cfg.k >= n {
        bail!(
            "curvature sampling: k = {} must be at least 1 and below the cloud's {n} points",
            cfg.k
        );
    }
    if let Some(r) = cfg.radius {
        if !(r > 0.0 && r.is_finite()) {
            bail!("curvature sampling: radius must be a positive number of mm (got {r:?})");
        }
    }
    Ok(())
}

/// `count` indices drawn uniformly without replacement from `pool`.
fn draw(pool: &[usize], count: usize, rng: &mut ChaCha8Rng) -> Vec<usize> {
    rand::seq::index::sample(rng, pool.len(), count.min(pool.len()))
        .into_iter()
        .map(|j| pool[j])
        .collect()
}

/// Curvature-aware down-sampling, front function. When a region has fewer points than its
/// quota, all of them are kept and the other region makes up the difference, so
/// min(N, points) are returned.
pub fn curvature_sample(
    cloud: &PointCloud,
    cfg: &CurvatureSampleConfig,
) -> Result<CurvatureSample> {
    check(cfg, cloud.len())?;
    let normals = estimate_normals(
        cloud,
        &NormalConfig {
            k: cfg.normal_k,
            orientation: Orientation::Unoriented,
            ..NormalConfig::default()
        },
    )?
    .normals;
    let index = Neighbours::new(&cloud.points);
    let radius = cfg.radius.unwrap_or(f64::INFINITY);
    let mean_angle_deg: Vec<f64> = index.par_map_points(
        || (),
        |_, i| {
            let nb = index.knn_within(&cloud.points[i], cfg.k + 1, radius);
            let angles: Vec<f64> = nb
                .iter()
                .filter(|n| n.index != i)
                .map(|n| normals[i].dot(&normals[n.index]).abs().min(1.0).acos())
                .collect();
            if angles.is_empty() {
                0.0
            } else {
                angles.iter().sum::<f64>().to_degrees() / angles.len() as f64
            }
        },
    );
    let feature: Vec<bool> = mean_angle_deg
        .iter()
        .map(|&a| a > cfg.feature_angle_deg)
        .collect();
    let (feature_pool, flat_pool): (Vec<usize>, Vec<usize>) =
        (0..cloud.len()).partition(|&i| feature[i]);
    let target = cfg.target.min(cloud.len());
    let want_feature = (target as f64 * (1.0 - cfg.uniform_ratio)).round() as usize;
    let take_feature = want_feature
        .min(feature_pool.len())
        .max(target.saturating_sub(flat_pool.len()));
    let take_flat = target - take_feature;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let mut indices = draw(&feature_pool, take_feature, &mut rng);
    indices.extend(draw(&flat_pool, take_flat, &mut rng));
    indices.sort_unstable();
    Ok(CurvatureSample {
        indices,
        feature_points: feature_pool.len(),
        kept_feature: take_feature,
        kept_flat: take_flat,
        feature,
        mean_angle_deg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    /// A 40 x 40 grid folded 90 degrees along x = 20 (0.5 mm spacing).
    fn folded() -> PointCloud {
        PointCloud::from_points(
            (0..3200)
                .map(|i| {
                    let (u, v) = ((i % 80) as f64 * 0.5, (i / 80) as f64 * 0.5);
                    if u <= 20.0 {
                        Point3::new(u, v, 0.0)
                    } else {
                        Point3::new(20.0, v, u - 20.0)
                    }
                })
                .collect(),
        )
    }

    #[test]
    fn the_fold_is_the_feature_region_and_gets_its_quota() {
        let cloud = folded();
        let cfg = CurvatureSampleConfig {
            target: 400,
            ..Default::default()
        };
        let s = curvature_sample(&cloud, &cfg).unwrap();
        // Feature points lie at the fold only.
        for (i, p) in cloud.points.iter().enumerate() {
            if s.feature[i] {
                assert!((p.x - 20.0).abs() < 2.5 && p.z < 2.5, "{p}");
            }
        }
        assert_eq!(s.indices.len(), 400);
        assert_eq!(s.kept_feature, 200.min(s.feature_points));
        assert_eq!(s.kept_feature + s.kept_flat, 400);
        let again = curvature_sample(&cloud, &cfg).unwrap();
        assert_eq!(again.indices, s.indices);
    }

    #[test]
    fn bad_settings_fail_in_one_line() {
        let cloud = folded();
        for cfg in [
            CurvatureSampleConfig {
                target: 0,
                ..Default::default()
            },
            CurvatureSampleConfig {
                uniform_ratio: 1.5,
                ..Default::default()
            },
            CurvatureSampleConfig {
                feature_angle_deg: -1.0,
                ..Default::default()
            },
            CurvatureSampleConfig {
                k: 0,
                ..Default::default()
            },
        ] {
            let e = curvature_sample(&cloud, &cfg).unwrap_err().to_string();
            assert!(
                e.starts_with("curvature sampling:") && !e.contains('\n'),
                "{e}"
            );
        }
    }
}

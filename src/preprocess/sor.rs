//! Statistical outlier removal (the paper's eqs. 1-4), in the paper's/PCL's convention or, on
//! request, exactly Open3D's `remove_statistical_outlier`.
use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::cloud::{PointCloud, MAX_COORD_MM};
use crate::spatial::Grid;

/// Settings of the statistical outlier filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SorConfig {
    /// k: neighbours whose mean distance is measured for each point. Default 20.
    pub k: usize,
    /// λ: a point is an outlier when its mean distance exceeds mean + λ·std. Default 2.0.
    pub std_ratio: f64,
    /// Open3D's convention: the point itself is the first of its k neighbours (distance 0),
    /// the standard deviation has Bessel's correction, points whose mean is 0 are dropped and
    /// survivors lie strictly below the threshold. Default false (the paper's and PCL's: k
    /// neighbours other than the point, population standard deviation, keep <= threshold).
    pub count_self: bool,
}

impl Default for SorConfig {
    fn default() -> Self {
        SorConfig {
            k: 20,
            std_ratio: 2.0,
            count_self: false,
        }
    }
}

/// What the filter found.
#[derive(Debug, Clone, PartialEq)]
pub struct SorResult {
    /// Indices of the points kept, ascending.
    pub kept: Vec<usize>,
    /// Number of points removed.
    pub removed: usize,
    /// Each point's mean distance to its k neighbours (mm), d̄ᵢ of eq. 1.
    pub mean_distances: Vec<f64>,
    /// μ: mean of the d̄ᵢ (eq. 2), mm.
    pub mean: f64,
    /// σ: their standard deviation (eq. 3), mm.
    pub std: f64,
    /// μ + λσ (eq. 4), mm.
    pub threshold: f64,
}

impl SorResult {
    /// The input cloud reduced to the kept points.
    pub fn apply(&self, cloud: &PointCloud) -> PointCloud {
        cloud.select(&self.kept)
    }
}

/// Most neighbours per point: the filter's work and memory grow as points × k, and Open3D's
/// examples use 20..50; a k of thousands on a million points would allocate gigabytes.
pub const MAX_K: usize = 500;

/// Checks the settings against a cloud of `n` points, with a one-line reason.
pub fn check(cfg: &SorConfig, n: usize) -> Result<()> {
    if n == 0 {
        bail!("outlier filter: the cloud is empty");
    }
    if cfg.k != 0 && cfg.k >= n {
        bail!(
            "outlier filter: k = {} needs more points than the cloud's {n}",
            cfg.k
        );
    }
    check_settings(cfg).map_err(|(_, why)| anyhow::anyhow!(why))
}

/// Checks the settings alone (no cloud): `k` within 1..=[`MAX_K`], `std_ratio` finite and
/// at least 0. A refusal names the setting's key (for a config file's line) and why.
pub fn check_settings(cfg: &SorConfig) -> Result<(), (&'static str, String)> {
    if cfg.k == 0 {
        return Err(("k", "outlier filter: k must be at least 1 (got 0)".into()));
    }
    if cfg.k > MAX_K {
        return Err((
            "k",
            format!(
                "outlier filter: k = {} is more than {MAX_K} neighbours (the work and memory grow as points × k)",
                cfg.k
            ),
        ));
    }
    if !cfg.std_ratio.is_finite() || cfg.std_ratio < 0.0 {
        return Err((
            "std_ratio",
            format!(
                "outlier filter: std ratio must be a finite number >= 0 (got {:?})",
                cfg.std_ratio
            ),
        ));
    }
    Ok(())
}

/// Refuses a cloud with a coordinate that is not finite or beyond ±[`MAX_COORD_MM`] (the
/// readers' bound; clouds made in code need not come through a reader), naming the point:
/// near 1e300 the neighbour grid's extent and the squared distances overflow.
pub fn check_coordinates(cloud: &PointCloud, stage: &str) -> Result<()> {
    let beyond = |p: &nalgebra::Point3<f64>| !p.coords.iter().all(|c| c.abs() <= MAX_COORD_MM);
    match cloud.points.iter().position(beyond) {
        Some(i) => bail!(
            "{stage}: point {i} has a coordinate beyond ±{MAX_COORD_MM:e} mm or not finite ({:?})",
            cloud.points[i].coords.as_slice()
        ),
        None => Ok(()),
    }
}

/// Mean distance from every point to its k neighbours (eq. 1), in parallel. With `count_self`
/// the point is one of the k (Open3D); otherwise the k nearest other points (one zero-distance
/// match, the point itself, is skipped; duplicates of it still count at distance 0).
pub fn mean_distances(cloud: &PointCloud, k: usize, count_self: bool) -> Vec<f64> {
    let query = if count_self { k } else { k + 1 };
    let skip = usize::from(!count_self);
    Grid::knn_among(&cloud.points, query, f64::INFINITY, |_, found| {
        // Ascending order, summed first to last, as Open3D does (bit-exact means).
        let sum = found[skip..].iter().fold(0.0, |s, e| s + e.0.sqrt());
        sum / (found.len() - skip) as f64
    })
}

/// The statistical outlier filter, front function: eqs. 1-4 with `cfg`'s k and λ.
pub fn statistical_outlier_filter(cloud: &PointCloud, cfg: &SorConfig) -> Result<SorResult> {
    check(cfg, cloud.len())?;
    check_coordinates(cloud, "outlier filter")?;
    let d = mean_distances(cloud, cfg.k, cfg.count_self);
    let (mean, std, kept) = if cfg.count_self {
        open3d_statistics(&d, cfg.std_ratio)
    } else {
        paper_statistics(&d, cfg.std_ratio)
    };
    Ok(SorResult {
        removed: d.len() - kept.len(),
        kept,
        threshold: mean + cfg.std_ratio * std,
        mean_distances: d,
        mean,
        std,
    })
}

/// Eqs. 2-4: μ = Σd̄ᵢ/n, σ = √(Σ(d̄ᵢ-μ)²/n), keep d̄ᵢ <= μ + λσ.
fn paper_statistics(d: &[f64], lambda: f64) -> (f64, f64, Vec<usize>) {
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let std = (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n).sqrt();
    let threshold = mean + lambda * std;
    let kept = (0..d.len()).filter(|&i| d[i] <= threshold).collect();
    (mean, std, kept)
}

/// Open3D 0.20's `RemoveStatisticalOutliers` arithmetic, operation for operation: zero means
/// add nothing to either sum but count in both divisors; Bessel's correction; keep
/// 0 < d̄ᵢ < threshold.
fn open3d_statistics(d: &[f64], lambda: f64) -> (f64, f64, Vec<usize>) {
    let valid = d.len() as f64;
    let mean = d.iter().fold(0.0, |s, &y| if y > 0.0 { s + y } else { s }) / valid;
    let sq_sum = d.iter().fold(0.0, |s, &x| {
        s + if x > 0.0 {
            (x - mean) * (x - mean)
        } else {
            0.0
        }
    });
    let std = (sq_sum / (valid - 1.0)).sqrt();
    let threshold = mean + lambda * std;
    let kept = (0..d.len())
        .filter(|&i| d[i] > 0.0 && d[i] < threshold)
        .collect();
    (mean, std, kept)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;

    fn line_with_outlier() -> PointCloud {
        let mut pts: Vec<Point3<f64>> = (0..50).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        pts.push(Point3::new(25.0, 40.0, 0.0));
        PointCloud::from_points(pts)
    }

    #[test]
    fn coordinates_near_1e300_are_refused_naming_the_point() {
        let mut cloud = line_with_outlier();
        cloud.points[7].y = 1e300;
        let err = statistical_outlier_filter(&cloud, &SorConfig::default()).unwrap_err();
        assert!(err.to_string().contains("point 7"), "{err}");
        cloud.points[7].y = f64::NAN;
        assert!(statistical_outlier_filter(&cloud, &SorConfig::default()).is_err());
    }

    #[test]
    fn removes_the_far_point() {
        let cloud = line_with_outlier();
        let r = statistical_outlier_filter(
            &cloud,
            &SorConfig {
                k: 4,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(r.removed, 1);
        assert!(!r.kept.contains(&50));
        // End points have mean (1+2+3+4)/4 = 2.5 to their 4 other neighbours.
        assert_eq!(r.mean_distances[0], 2.5);
        let o3d = SorConfig {
            k: 5,
            count_self: true,
            ..Default::default()
        };
        let r3 = statistical_outlier_filter(&cloud, &o3d).unwrap();
        assert_eq!(r3.mean_distances[0], 2.0);
        assert!(!r3.kept.contains(&50));
    }

    #[test]
    fn bad_parameters_are_one_line_errors() {
        let cloud = line_with_outlier();
        let bad = [
            SorConfig {
                k: 0,
                ..Default::default()
            },
            SorConfig {
                k: 51,
                ..Default::default()
            },
            SorConfig {
                std_ratio: -1.0,
                ..Default::default()
            },
            SorConfig {
                std_ratio: f64::NAN,
                ..Default::default()
            },
        ];
        for cfg in bad {
            let e = statistical_outlier_filter(&cloud, &cfg)
                .unwrap_err()
                .to_string();
            assert!(!e.contains('\n') && e.starts_with("outlier filter:"), "{e}");
        }
        let e = statistical_outlier_filter(&PointCloud::default(), &SorConfig::default());
        assert!(e.unwrap_err().to_string().contains("empty"));
    }
}

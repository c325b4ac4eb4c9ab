//! The stage front: outlier filter, then optional voxel and curvature-aware down-sampling.
use std::time::Instant;

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use super::curvature::{curvature_sample, CurvatureSample, CurvatureSampleConfig};
use super::sor::{check_coordinates, statistical_outlier_filter, SorConfig, SorResult};
use super::voxel::{check_voxel, voxel_downsample};

/// How the voxel edge is set, for messages: `filter --voxel` or `voxel_mm` in a config file.
const VOXEL_OPTION: &str = "voxel down-sampling (--voxel / voxel_mm)";
use crate::cloud::PointCloud;

/// Settings of the preprocessing stage (TOML: `filter_outliers`, `voxel_mm`, `[sor]`,
/// `[curvature_sample]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PreprocessConfig {
    /// Run the statistical outlier filter. Default true.
    pub filter_outliers: bool,
    /// Outlier filter settings (k 20, λ 2, paper convention).
    pub sor: SorConfig,
    /// Voxel edge for centroid down-sampling, mm. Default none.
    pub voxel_mm: Option<f64>,
    /// Curvature-aware down-sampling. Default none.
    pub curvature_sample: Option<CurvatureSampleConfig>,
}

impl Default for PreprocessConfig {
    fn default() -> Self {
        PreprocessConfig {
            filter_outliers: true,
            sor: SorConfig::default(),
            voxel_mm: None,
            curvature_sample: None,
        }
    }
}

/// The preprocessed cloud and what each step did.
#[derive(Debug, Clone)]
pub struct Preprocessed {
    /// The result.
    pub cloud: PointCloud,
    /// Points in the input.
    pub input_points: usize,
    /// The outlier filter's result (indices into the input), when it ran.
    pub sor: Option<SorResult>,
    /// Points after voxel down-sampling, when it ran.
    pub after_voxel: Option<usize>,
    /// The curvature sample (indices into the cloud it was given: after the filter and the
    /// voxel step), when it ran.
    pub curvature: Option<CurvatureSample>,
    /// Wall time of the whole stage, s.
    pub seconds: f64,
}

/// Runs the stage: SOR -> voxel -> curvature-aware sampling, each when configured.
pub fn preprocess(cloud: &PointCloud, cfg: &PreprocessConfig) -> Result<Preprocessed> {
    let start = Instant::now();
    check_coordinates(cloud, "preprocess")?;
    if let Some(v) = cfg.voxel_mm {
        check_voxel(cloud, v, VOXEL_OPTION)?;
    }
    if cloud.is_empty() {
        bail!("preprocess: the cloud is empty");
    }
    let (mut out, sor) = if cfg.filter_outliers {
        let r = statistical_outlier_filter(cloud, &cfg.sor)?;
        (r.apply(cloud), Some(r))
    } else {
        (cloud.clone(), None)
    };
    let after_voxel = cfg.voxel_mm.map(|v| {
        out = voxel_downsample(&out, v);
        out.len()
    });
    let curvature = match &cfg.curvature_sample {
        Some(c) => {
            let s = curvature_sample(&out, c)?;
            out = out.select(&s.indices);
            Some(s)
        }
        None => None,
    };
    Ok(Preprocessed {
        cloud: out,
        input_points: cloud.len(),
        sor,
        after_voxel,
        curvature,
        seconds: start.elapsed().as_secs_f64(),
    })
}

impl Preprocessed {
    /// One line: points in and out, outliers removed and threshold, each down-sampling, time.
    pub fn summary(&self) -> String {
        let mut s = format!("kept {} of {} points", self.cloud.len(), self.input_points);
        if let Some(r) = &self.sor {
            s += &format!(
                "; outlier filter removed {} (threshold {:.4} mm)",
                r.removed, r.threshold
            );
        }
        if let Some(v) = self.after_voxel {
            s += &format!("; voxel grid left {v}");
        }
        if let Some(c) = &self.curvature {
            s += &format!(
                "; curvature sampling kept {} feature + {} other ({} feature points)",
                c.kept_feature, c.kept_flat, c.feature_points
            );
        }
        s + &format!("; {:.3} s", self.seconds)
    }
}

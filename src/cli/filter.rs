//! `polishbot filter IN -o OUT`: statistical outlier filter, optional voxel and
//! curvature-aware down-sampling; prints a one-line summary.
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use super::common::GeometryInput;
use crate::cloud::{self, PlyPrecision};
use crate::preprocess::{preprocess, CurvatureSampleConfig, PreprocessConfig};

/// Arguments of `filter` (they override the `--config` file's values).
#[derive(Debug, Args)]
pub struct FilterArgs {
    /// Input point cloud (a mesh's vertices are taken).
    pub input: PathBuf,
    /// Output PLY file.
    #[arg(short, long)]
    pub output: PathBuf,
    #[command(flatten)]
    /// Units and format of the input.
    pub geometry: GeometryInput,
    /// Neighbours per point for the outlier statistics [default: 20].
    #[arg(long)]
    pub k: Option<usize>,
    /// λ: outliers have a mean neighbour distance above mean + λ·std [default: 2.0].
    #[arg(long, allow_hyphen_values = true)]
    pub std_ratio: Option<f64>,
    /// Open3D's convention: the point counts as the first of its k neighbours, Bessel's
    /// correction, keep strictly below the threshold (same kept set as
    /// `remove_statistical_outlier`).
    #[arg(long)]
    pub count_self: bool,
    /// Skip the outlier filter.
    #[arg(long)]
    pub no_outlier_filter: bool,
    /// Voxel edge (mm): replace each voxel's points by their centroid. At least 1e-9 of the
    /// cloud's longest side and at most that side.
    #[arg(long, value_name = "MM", allow_hyphen_values = true)]
    pub voxel: Option<f64>,
    /// Curvature-aware down-sampling to N points.
    #[arg(long, value_name = "N")]
    pub curvature_sample: Option<usize>,
    /// Feature threshold: mean normal angle to neighbours, degrees [default: 5].
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    pub feature_angle: Option<f64>,
    /// J: share of N drawn from the non-feature region; the feature region gives N·(1-J)
    /// [default: 0.5].
    #[arg(long, value_name = "J", allow_hyphen_values = true)]
    pub uniform_ratio: Option<f64>,
}

/// Loads, preprocesses, writes the result and prints the summary.
pub fn run(args: FilterArgs, config: Option<&std::path::Path>) -> anyhow::Result<()> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: PreprocessConfig = file.parse()?;
    // the config file's values, with their lines; the flags over them are checked by the
    // stage against the cloud (sor::check, preprocess's check_voxel, naming the file)
    super::settings::check_filter(&file, "sor", &cfg.sor, cfg.voxel_mm)?;
    if let Some(k) = args.k {
        cfg.sor.k = k;
    }
    if let Some(r) = args.std_ratio {
        cfg.sor.std_ratio = r;
    }
    cfg.sor.count_self |= args.count_self;
    cfg.filter_outliers &= !args.no_outlier_filter;
    if args.voxel.is_some() {
        cfg.voxel_mm = args.voxel;
    }
    if args.curvature_sample.is_some()
        || args.feature_angle.is_some()
        || args.uniform_ratio.is_some()
    {
        let c = cfg
            .curvature_sample
            .get_or_insert_with(CurvatureSampleConfig::default);
        c.target = args.curvature_sample.unwrap_or(c.target);
        c.feature_angle_deg = args.feature_angle.unwrap_or(c.feature_angle_deg);
        c.uniform_ratio = args.uniform_ratio.unwrap_or(c.uniform_ratio);
    }
    let input = cloud::load_cloud(&args.input, args.geometry.format, args.geometry.units)?;
    let done = preprocess(&input, &cfg).with_context(|| args.input.display().to_string())?;
    cloud::write_ply(&args.output, &done.cloud, None, PlyPrecision::F64)?;
    println!(
        "filter: {} -> {}: {}",
        args.input.display(),
        args.output.display(),
        done.summary()
    );
    Ok(())
}

//! `polishbot register --reference R --scan S -o DIR`: writes DIR/registration.json.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;

use super::common::GeometryInput;
use crate::cloud;
use crate::register::RegisterConfig;

/// Arguments of `register` (flags override the `--config` file's values).
#[derive(Debug, Args)]
pub struct RegisterArgs {
    /// The reference: a point cloud, or a mesh (sampled area-uniformly).
    #[arg(long)]
    pub reference: PathBuf,
    /// The scan to bring into the reference frame.
    #[arg(long)]
    pub scan: PathBuf,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Units and format of both files.
    #[command(flatten)]
    pub input: GeometryInput,
    /// Points sampled on a mesh reference [default: 400000].
    #[arg(long, default_value_t = 400_000)]
    pub reference_samples: usize,
    /// Seed of the mesh sampling [default: 1].
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Voxel size of the coarse stage, mm [default: 5 x mean point spacing].
    #[arg(long)]
    pub voxel: Option<f64>,
}

/// Registers and writes registration.json (also on failure, with `"status": "failed"`).
pub fn run(args: RegisterArgs, config: Option<&Path>) -> Result<()> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: RegisterConfig = file.parse()?;
    cfg.check().map_err(|m| file.refuse("", &m))?;
    if args.voxel.is_some() {
        cfg.voxel = args.voxel;
        cfg.check().map_err(|m| anyhow::anyhow!("--voxel: {m}"))?;
    }
    let reference = super::common::load_reference(
        &args.reference,
        &args.input,
        args.reference_samples,
        args.seed,
    )?;
    let scan = cloud::load_cloud(&args.scan, args.input.format, args.input.units)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create", args.out.display()))?;
    let out = args.out.join("registration.json");
    let files = (args.scan.as_path(), args.reference.as_path());
    let reg = crate::inspect::register_scan(&scan, &reference, &cfg)
        .map_err(|e| crate::inspect::files::record_failure(e, &out, files, None))?;
    crate::inspect::files::record_ok(&reg, &out, files, None)?;
    println!(
        "register: fitness {:.4}, inlier RMSE {:.4} mm, {} ICP iterations, {:.2} s -> {}",
        reg.fitness,
        reg.inlier_rmse,
        reg.fine.map_or(0, |f| f.iterations),
        reg.times.total,
        out.display()
    );
    Ok(())
}

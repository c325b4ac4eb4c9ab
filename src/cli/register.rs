//! `polishbot register --reference R --scan S -o DIR`: writes DIR/registration.json.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::{json, Value};

use super::common::GeometryInput;
use crate::cloud;
use crate::register::{RegisterConfig, RegisterError, Registration};

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

fn write_json(path: &Path, value: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").with_context(|| format!("{}: cannot write", path.display()))
}

/// Registers and writes registration.json (also on failure, with `"status": "failed"`).
pub fn run(args: RegisterArgs, config: Option<&Path>) -> Result<()> {
    let mut cfg: RegisterConfig = super::common::load_config(config)?;
    if args.voxel.is_some() {
        cfg.voxel = args.voxel;
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
        .map_err(|e| record_failure(e, &out, files))?;
    record_ok(&reg, &out, files)?;
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

/// registration.json of a registration with `"status"`, `"reason"` and the two files.
fn with_status<T: serde::Serialize>(
    reg: &T,
    status: &str,
    reason: Option<&str>,
    files: (&Path, &Path),
) -> Result<Value> {
    let mut v = serde_json::to_value(reg)?;
    v["status"] = json!(status);
    v["reason"] = json!(reason);
    v["scan"] = json!(files.0.display().to_string());
    v["reference"] = json!(files.1.display().to_string());
    Ok(v)
}

/// Records a registration that succeeded in `out` (registration.json, `"status": "ok"`);
/// `files` are the scan's and the reference's.
pub fn record_ok(reg: &Registration, out: &Path, files: (&Path, &Path)) -> Result<()> {
    write_json(out, &with_status(reg, "ok", None, files)?)
}

/// Records a registration that failed in `out` (`"status": "failed"` with the diagnostics)
/// and returns the one-line error that says so.
pub fn record_failure(err: RegisterError, out: &Path, files: (&Path, &Path)) -> anyhow::Error {
    let RegisterError::Failed {
        reason,
        diagnostics,
    } = err
    else {
        return err.into();
    };
    let value = with_status(&*diagnostics, "failed", Some(&reason), files);
    if let Err(e) = value.and_then(|v| write_json(out, &v)) {
        return e;
    }
    anyhow::anyhow!(
        "registration failed: {reason} (correspondences {}, inlier ratio {:.3}, cliques {}, hypotheses {}, fitness {:.3}; diagnostics in {})",
        diagnostics.coarse.correspondences,
        diagnostics.coarse.inlier_ratio,
        diagnostics.coarse.mac.cliques_found,
        diagnostics.coarse.mac.hypotheses,
        diagnostics.fitness,
        out.display()
    )
}

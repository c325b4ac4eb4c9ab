//! `polishbot register --reference R --scan S -o DIR`: writes DIR/registration.json.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use serde_json::{json, Value};

use super::GeometryInput;
use crate::cloud::{self, Geometry, PointCloud};
use crate::register::{
    register_with_progress, RegisterConfig, RegisterError, Registration, PROGRESS_STEPS,
};

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

/// Loads a reference file: a cloud as is, a mesh sampled with facet normals.
fn load_reference(args: &RegisterArgs) -> Result<PointCloud> {
    let loaded = cloud::load(&args.reference, args.input.format, args.input.units)?;
    Ok(match loaded.geometry {
        Geometry::Cloud(c) => c,
        Geometry::Mesh { mesh, .. } => {
            cloud::sample_mesh(&mesh, args.reference_samples, args.seed)
                .with_context(|| args.reference.display().to_string())?
                .cloud
        }
    })
}

fn write_json(path: &Path, value: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").with_context(|| format!("{}: cannot write", path.display()))
}

/// Registers and writes registration.json (also on failure, with `"status": "failed"`).
pub fn run(args: RegisterArgs, config: Option<&Path>) -> Result<()> {
    let mut cfg: RegisterConfig = super::load_config(config)?;
    if args.voxel.is_some() {
        cfg.voxel = args.voxel;
    }
    let reference = load_reference(&args)?;
    let scan = cloud::load_cloud(&args.scan, args.input.format, args.input.units)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create", args.out.display()))?;
    let out = args.out.join("registration.json");
    let reg = register_and_record(&scan, &reference, &cfg, &out, &args.scan, &args.reference)?;
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

/// Registers `scan` onto `reference` with a progress bar and records the outcome in `out`
/// (registration.json, `"status"` ok or failed with the diagnostics); a failure is also the
/// returned one-line error.
pub fn register_and_record(
    scan: &PointCloud,
    reference: &PointCloud,
    cfg: &RegisterConfig,
    out: &Path,
    scan_path: &Path,
    reference_path: &Path,
) -> Result<Registration> {
    let bar = crate::progress::bar(PROGRESS_STEPS, "register");
    let result = register_with_progress(scan, reference, cfg, &|step| {
        bar.set_message(step.to_string());
        bar.inc(1);
    });
    bar.finish_and_clear();
    let with_status = |reg, status: &str, reason: Option<&str>| -> Result<Value> {
        let mut v = serde_json::to_value(reg)?;
        v["status"] = json!(status);
        v["reason"] = json!(reason);
        v["scan"] = json!(scan_path.display().to_string());
        v["reference"] = json!(reference_path.display().to_string());
        Ok(v)
    };
    match result {
        Ok(reg) => {
            write_json(out, &with_status(&reg, "ok", None)?)?;
            Ok(reg)
        }
        Err(RegisterError::Failed {
            reason,
            diagnostics,
        }) => {
            write_json(out, &with_status(&*diagnostics, "failed", Some(&reason))?)?;
            anyhow::bail!(
                "registration failed: {reason} (correspondences {}, inlier ratio {:.3}, cliques {}, hypotheses {}, fitness {:.3}; diagnostics in {})",
                diagnostics.coarse.correspondences,
                diagnostics.coarse.inlier_ratio,
                diagnostics.coarse.mac.cliques_found,
                diagnostics.coarse.mac.hypotheses,
                diagnostics.fitness,
                out.display()
            )
        }
        Err(e) => Err(e.into()),
    }
}

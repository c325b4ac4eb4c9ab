//! `polishbot demo`: the whole chain on a built-in part against the simulated arm. Stages are
//! added here as they land; today it makes the synthetic part and reads it back.
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use crate::cloud::{self, Units};
use crate::synth::{synth, SynthConfig};

/// Arguments of `demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, default_value = "polishbot-demo")]
    pub out: PathBuf,
    /// Seed of the synthetic part.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// Runs the chain and prints a summary.
pub fn run(args: DemoArgs, _config: Option<&std::path::Path>) -> anyhow::Result<()> {
    let start = Instant::now();
    let cfg = SynthConfig {
        seed: args.seed,
        ..SynthConfig::default()
    };
    let case = synth(&cfg)?;
    case.write(&args.out)?;
    let scan = cloud::load_cloud(&args.out.join("scan.ply"), None, Some(Units::Mm))?;
    let reference = cloud::load_cloud(&args.out.join("reference.ply"), None, Some(Units::Mm))?;
    println!("demo: wrote {}", args.out.display());
    println!("  part: {}", case.truth.source);
    println!(
        "  reference: {} points; scan: {} points",
        reference.len(),
        scan.len()
    );
    println!(
        "  planted: {} defects, {} outliers, noise {} mm",
        case.truth.defects.len(),
        case.truth.outliers.scattered.len() + case.truth.outliers.clustered.len(),
        case.truth.noise_mm
    );
    for d in &case.truth.defects {
        println!(
            "    defect {}: {:?} height {:+.3} mm width {:.2} mm",
            d.id, d.kind, d.height, d.width
        );
    }
    println!("  stages still to land: inspect, plan, run (see the issues)");
    println!("  time: {:.2} s", start.elapsed().as_secs_f64());
    Ok(())
}

//! `polishbot cell design --reference R --surface S -o DIR`: searches a turntable cell for a
//! part's articular surface and writes the cell folder (crate::design).
use std::path::PathBuf;
use std::time::Instant;

use clap::{Args, Subcommand};

use crate::cloud::Units;
use crate::design::{self, DesignConfig, Part, SourceCell};
use crate::robot::units::mm;

/// Arguments of `cell`.
#[derive(Debug, Args)]
pub struct CellArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: CellAction,
}

/// The `cell` actions.
#[derive(Debug, Subcommand)]
pub enum CellAction {
    /// Search the part's mounting on a turntable, the table's axis and place and the tool's
    /// shank for the largest reachable share of the articular surface; write the cell.
    Design(DesignArgs),
}

/// Arguments of `cell design`.
#[derive(Debug, Args)]
pub struct DesignArgs {
    /// The whole part (closed mesh, the reference frame).
    #[arg(long)]
    pub reference: PathBuf,
    /// Its articular surface to reach (mesh, same frame).
    #[arg(long)]
    pub surface: PathBuf,
    /// Unit of --reference and --surface.
    #[arg(long, value_enum)]
    pub units: Option<Units>,
    /// Cell whose arm, servos (with the turntable's servo) and tool are used.
    #[arg(long, default_value = "calibration/turntable")]
    pub source: PathBuf,
    /// Folder of the designed cell.
    #[arg(short, long)]
    pub out: PathBuf,
    /// Seed of the surface samples [default: 1].
    #[arg(long)]
    pub seed: Option<u64>,
}

/// Runs `cell`.
pub fn run(args: CellArgs, _config: Option<&std::path::Path>) -> anyhow::Result<()> {
    let CellAction::Design(a) = args.action;
    let started = Instant::now();
    let mut cfg = DesignConfig::default();
    if let Some(s) = a.seed {
        cfg.seed = s;
    }
    let source = SourceCell::load(&a.source)?;
    let reference = design::load_mesh(&a.reference, a.units)?;
    let surface = design::load_mesh(&a.surface, a.units)?;
    let part = Part::new(&reference, &surface, &cfg)?;
    let d = design::design(&part, &source, &cfg)?;
    design::write::write_cell(&d, &source, &a.out)?;
    let c = &d.candidate;
    println!(
        "cell design: {} candidates scored in {:.1} s; table axis {:?}, part direction {:?} along it, centre {:?} m, shank {:.1} mm",
        d.candidates_scored,
        started.elapsed().as_secs_f64(),
        c.axis,
        c.mount,
        c.centre,
        mm(c.shank_m)
    );
    for (family, s, c) in &d.alternatives {
        println!(
            "cell design: best with a {family}: {:.1} % (axis {:?}, part direction {:?}, centre {:?} m, shank {:.1} mm)",
            100.0 * s,
            c.axis,
            c.mount,
            c.centre,
            mm(c.shank_m)
        );
    }
    for (rule, n) in &d.refused {
        println!("cell design: not reached: {n} samples by {rule}");
    }
    for (k, s) in d.setups.iter().enumerate() {
        println!(
            "cell design: setup {}: part direction {:?} along the table axis: {:.1} % alone, {:.1} % with the setups before it",
            k + 1,
            s.mount,
            100.0 * s.coverage,
            100.0 * s.union_coverage
        );
    }
    for m in &d.family {
        println!(
            "cell design: the part's family: {:.2} x{}: {:.1} % in setup 1, {:.1} % over the setups",
            m.scale,
            if m.mirrored { ", mirrored (the other knee)" } else { "" },
            100.0 * m.coverage,
            100.0 * m.union_coverage
        );
    }
    println!(
        "cell design: articular surface reached {:.1} % in setup 1, {:.1} % over {} setup(s) ({} samples); cell written to {}",
        100.0 * d.coverage,
        100.0 * design::union_coverage(&d),
        d.setups.len(),
        d.samples.len(),
        a.out.display()
    );
    Ok(())
}

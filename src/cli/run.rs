//! `polishbot run --plan plan.json (--port DEV | --sim) [--dry-run] [--resume journal.jsonl]`.
use std::path::{Path, PathBuf};

use clap::Args;
use serde::Deserialize;

use crate::bus::{self, Bus, BusConfig, Journal, ResumePoint, SimOptions, Transport};
use crate::plan::execute::{execute, RunConfig};
use crate::plan::file::CheckedPlan;
use crate::plan::{collide, frames, CollisionConfig, Inspection, Plan, ValidationConfig};
use crate::robot::{Robot, RobotConfig, Workcell};

/// Arguments of `run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The plan to stream.
    #[arg(long, value_name = "FILE")]
    pub plan: PathBuf,
    /// Serial device of the board (or the mock's pseudo-terminal).
    #[arg(long, value_name = "DEV")]
    pub port: Option<String>,
    /// Use the in-process simulated arm.
    #[arg(long, conflicts_with = "port")]
    pub sim: bool,
    /// Check the plan and print what would be sent; send nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Continue an interrupted run from this journal (appended to).
    #[arg(long, value_name = "FILE")]
    pub resume: Option<PathBuf>,
    /// Journal file [default: journal.jsonl next to the plan, or the --resume file].
    #[arg(long, value_name = "FILE")]
    pub journal: Option<PathBuf>,
}

/// `--config` TOML of `run`: `[robot]`, `[run]`, `[bus]` (timing; the servo map always comes
/// from servos.toml), `[sim]`, `[validation]`.
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunFileConfig {
    /// Robot description and calibration files.
    pub robot: RobotConfig,
    /// Streaming settings.
    pub run: RunConfig,
    /// Bus driver settings.
    pub bus: BusConfig,
    /// Simulated arm settings.
    pub sim: SimOptions,
    /// Tolerances of the re-validation.
    pub validation: ValidationConfig,
    /// The collision model of the re-check (solids.toml beside the workcell file adds its
    /// solids).
    pub collision: CollisionConfig,
}

/// Runs `run`.
pub fn run(args: RunArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let cfg: RunFileConfig = super::load_config(config)?;
    let robot = Robot::load(&cfg.robot.urdf, &cfg.robot.tool, &cfg.robot.servos)?;
    let plan = Plan::load(&args.plan)?;
    let checked = plan
        .check(&robot, &cfg.validation)
        .map_err(|e| anyhow::anyhow!("{}: refused: {e}", args.plan.display()))?;
    let workcell = Workcell::load(&cfg.robot.workcell)?;
    let mut collision = cfg.collision.clone();
    collision
        .solids
        .extend(collide::solids_beside(&cfg.robot.workcell)?);
    let inspection = Inspection::load(Path::new(&plan.inspection)).map_err(|e| {
        anyhow::anyhow!(
            "{}: refused: the part to check collisions against: {e}",
            args.plan.display()
        )
    })?;
    plan.check_clearance(&inspection, &robot, &workcell, &collision)
        .map_err(|e| anyhow::anyhow!("{}: refused: {e}", args.plan.display()))?;
    let from = match &args.resume {
        Some(j) => ResumePoint::from_journal(j)?.resume_from() as usize,
        None => 0,
    };
    if args.dry_run {
        println!(
            "run: dry run: {} passes, {} frames from frame {from}, {:.2} s at {} ms per frame; nothing sent",
            plan.passes.len(),
            checked.frames.len(),
            (checked.frames.len() - from.min(checked.frames.len())) as f64 * plan.period,
            checked.time_ms
        );
        return Ok(());
    }
    let journal_path = args
        .journal
        .or(args.resume.clone())
        .unwrap_or_else(|| args.plan.with_file_name("journal.jsonl"));
    let journal = Journal::append(&journal_path)?;
    let mut bus_cfg = cfg.bus;
    bus_cfg.servo_map = frames::servo_map(&robot)?;
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let _ = bus::install_ctrlc(stop.clone());
    let link = super::arm::open_link(
        args.port.as_deref(),
        args.sim,
        &cfg.sim,
        &bus_cfg.servo_map,
        "run",
    )?;
    stream(
        Bus::connect(link, bus_cfg, journal)?,
        &checked,
        &plan,
        from,
        &cfg.run,
        stop,
        &journal_path,
    )
}

fn stream<T: Transport>(
    mut bus: Bus<T>,
    checked: &CheckedPlan,
    plan: &Plan,
    from: usize,
    cfg: &RunConfig,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    journal: &Path,
) -> anyhow::Result<()> {
    bus.set_stop_flag(stop);
    let port = bus.transport().describe();
    match execute(&mut bus, checked, plan.period, from, cfg) {
        Ok(r) => {
            println!(
                "run: {port}: sent frames {}..{} ({} frames), {} read-backs (worst {} counts), final pose {:?} verified; journal {}",
                r.first,
                r.first + r.sent - 1,
                r.sent,
                r.readbacks,
                r.worst_readback_counts,
                r.final_raw,
                journal.display()
            );
            Ok(())
        }
        Err(e) => Err(anyhow::anyhow!(
            "run: {port}: stopped: {e}; journal {} (continue with --resume {})",
            journal.display(),
            journal.display()
        )),
    }
}

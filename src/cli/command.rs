//! The command line: the subcommands' argument structs by name, the dispatch to each one's
//! file, and the exit code of its error.
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use super::common::one_line;
use super::{
    arm, calibrate, cell, cycle, demo, filter, info, inspect, merge, plan, register, run, synth,
};

/// The subcommands of DESIGN.md's CLI contract.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Print one JSON object describing a geometry file: points, faces, bbox_min, bbox_max, units.
    Info(info::InfoArgs),
    /// Merge turntable range views into one cloud.
    Merge(Box<merge::MergeArgs>),
    /// Statistical outlier filter and down-sampling.
    Filter(filter::FilterArgs),
    /// Register a scan onto a reference: DIR/registration.json.
    Register(register::RegisterArgs),
    /// Whole metrology chain: registration, deviations, regions, report.
    Inspect(Box<inspect::InspectArgs>),
    /// Plan grinding passes and the joint trajectory from an inspection.
    Plan(plan::PlanArgs),
    /// Stream a plan to the arm (serial port, I2C bus or simulated arm).
    Run(run::RunArgs),
    /// Direct arm commands: ping, read, move, torque.
    Arm(arm::ArmArgs),
    /// Calibration routines: servos, tool, workcell, verify, removal.
    Calibrate(calibrate::CalibrateArgs),
    /// Cell design: search a turntable cell that reaches a part family's articular surface.
    Cell(cell::CellArgs),
    /// Write a synthetic reference, a defective moved scan and the truth.
    Synth(Box<synth::SynthArgs>),
    /// The whole chain on a built-in part against the simulated arm.
    Demo(demo::DemoArgs),
    /// The closed loop: inspect, plan, run, rescan, until within tolerance.
    Cycle(Box<cycle::CycleArgs>),
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    let config = cli.config.as_deref();
    match cli.command {
        Command::Info(args) => info::run(args, config),
        Command::Synth(args) => synth::run(*args, config),
        Command::Merge(args) => merge::run(*args, config),
        Command::Filter(args) => filter::run(args, config),
        Command::Register(args) => register::run(args, config),
        Command::Inspect(args) => inspect::run(*args, config),
        Command::Plan(args) => plan::run(args, config),
        Command::Run(args) => run::run(args, config),
        Command::Arm(args) => arm::run(args, config),
        Command::Calibrate(args) => calibrate::run(args, config),
        Command::Cell(args) => cell::run(args, config),
        Command::Demo(args) => demo::run(args, config),
        Command::Cycle(args) => cycle::run(*args, config),
    }
}

/// polishbot: finds where a part deviates from its reference and grinds it with a DOFBOT arm.
#[derive(Debug, Parser)]
#[command(name = "polishbot", version, about, long_about = None)]
pub struct Cli {
    /// Optional TOML file with settings for the command (its keys mirror the flags).
    #[arg(long, global = true, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The command to run.
    #[command(subcommand)]
    pub command: Command,
}

/// Parses the command line, runs the command and maps errors to a one-line message and exit 1.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    init_tracing();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) if err.is::<crate::inspect::Incomplete>() => {
            eprintln!("polishbot: {err}");
            ExitCode::from(crate::inspect::INCOMPLETE_EXIT)
        }
        Err(err) if err.is::<super::setup_stop::OperatorStop>() => {
            eprintln!("polishbot: {err}");
            ExitCode::from(super::setup_stop::OPERATOR_STOP_EXIT)
        }
        Err(err) if err.is::<cycle::NotFinished>() => {
            eprintln!("polishbot: {err}");
            ExitCode::from(cycle::NOT_FINISHED_EXIT)
        }
        Err(err) => {
            eprintln!("polishbot: {}", one_line(&err));
            ExitCode::FAILURE
        }
    }
}

fn init_tracing() {
    let _ = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_max_level(tracing::Level::WARN)
        .try_init();
}

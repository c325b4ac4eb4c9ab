//! `polishbot plan --inspection DIR [--workcell FILE] -o plan.json [--export-ros traj.yaml]`.
use std::path::{Path, PathBuf};

use clap::Args;

use crate::cycle::plan_into;
pub use crate::cycle::PlanFileConfig;
use crate::motion;
use crate::repair::Inspection;

/// Arguments of `plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Inspection folder holding deviations.csv and regions.json.
    #[arg(long, value_name = "DIR")]
    pub inspection: PathBuf,
    /// Cell folder: its dofbot.urdf, tool.toml, servos.toml and workcell.toml (and
    /// solids.toml) replace the `[robot]` files; a `[turntable]` in it turns the part between
    /// regions (e.g. calibration/turntable) [default: calibration].
    #[arg(long, value_name = "DIR")]
    pub cell: Option<PathBuf>,
    /// Workcell file (part placement in the robot frame) [default: calibration/workcell.toml].
    #[arg(long, value_name = "FILE")]
    pub workcell: Option<PathBuf>,
    /// Output plan file.
    #[arg(short = 'o', long = "out", value_name = "FILE")]
    pub out: PathBuf,
    /// Also write the joint trajectory as a ROS trajectory_msgs/JointTrajectory (YAML).
    #[arg(long, value_name = "FILE")]
    pub export_ros: Option<PathBuf>,
    /// Fail when any planned contact point is unreachable.
    #[arg(long)]
    pub require_full_reach: bool,
    /// Rigid (depth layers) or removal (a compliant tool's dwell map)
    /// [default: `mode` of [plan], else removal].
    #[arg(long, value_enum)]
    pub mode: Option<motion::PlanMode>,
}

/// Runs `plan`.
pub fn run(args: PlanArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: PlanFileConfig = file.parse()?;
    if let Some(dir) = &args.cell {
        cfg.robot.use_cell(dir);
    }
    if let Some(w) = args.workcell {
        cfg.robot.workcell = w;
    }
    cfg.plan.require_full_reach |= args.require_full_reach;
    if let Some(mode) = args.mode {
        cfg.plan.mode = mode;
    }
    let inspection = Inspection::load(&args.inspection)?;
    let refuse = |m: &str| file.refuse("plan", m);
    // the cell's files are read here, once; the planner parses them from memory
    let cell = cfg.robot.read_cell()?;
    plan_into(
        &cfg,
        &cell,
        None,
        &inspection,
        &args.out,
        args.export_ros.as_deref(),
        &refuse,
    )
    .map(drop)
}

//! `polishbot plan --inspection DIR [--workcell FILE] -o plan.json [--export-ros traj.yaml]`.
use std::path::{Path, PathBuf};

use clap::Args;
use serde::Deserialize;

use crate::motion::{self, ros, Inspection, PlanConfig};
use crate::robot::{self, RobotConfig};

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

/// `--config` TOML of `plan` and `run`: `[robot]` (RobotConfig: urdf, tool, servos, workcell,
/// ik) and `[plan]` (PlanConfig).
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanFileConfig {
    /// Robot description and calibration files.
    pub robot: RobotConfig,
    /// Planner settings.
    pub plan: PlanConfig,
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
    let (robot, workcell) = robot::load(&cfg.robot)?;
    // the tool file's [removal] checked here, so that its errors name the file's full path
    crate::removal::ToolModel::load(&cfg.robot.tool)?;
    cfg.plan.check(&robot).map_err(|e| match e {
        motion::PlanError::Config(m) => file.refuse("plan", &m),
        e => e.into(),
    })?;
    let solids = motion::collide::solids_beside(&cfg.robot.workcell)?;
    cfg.plan.collision.solids.extend(solids);
    let inspection = Inspection::load(&args.inspection)?;
    let table = robot::Turntable::load(&cfg.robot.servos, &cfg.robot.workcell)?;
    let plan = motion::plan(&inspection, &robot, &workcell, table.as_ref(), &cfg.plan)?;
    plan.save(&args.out)?;
    let provenance = super::plan_report::provenance(&args.inspection, &cfg.robot, &cfg.plan)?;
    provenance.stamp_json(&args.out)?;
    let page = super::plan_report::write_page(&args.out, &inspection, &plan, &provenance)?;
    if let Some(removal) = &plan.removal {
        write_removal(removal, &args.out, &cfg.plan)?;
    }
    if let Some(yaml) = &args.export_ros {
        std::fs::write(yaml, ros::joint_trajectory_yaml(&plan, "base_link"))
            .map_err(|e| anyhow::anyhow!("{}: {e}", yaml.display()))?;
    }
    println!("plan: report {}", page.display());
    print_summary(&plan, &args.inspection, &args.out);
    Ok(())
}

/// Removal mode: writes predicted.csv beside the plan and prints each region's prediction.
fn write_removal(
    removal: &crate::removal::prediction::RemovalReport,
    out: &Path,
    cfg: &PlanConfig,
) -> anyhow::Result<()> {
    let csv = out.with_file_name("predicted.csv");
    std::fs::write(
        &csv,
        crate::removal::prediction::predicted_csv(removal, &cfg.monte_carlo),
    )
    .map_err(|e| anyhow::anyhow!("{}: {e}", csv.display()))?;
    for r in &removal.regions {
        println!(
            "plan: region {}: predicted peak {:+.4} -> {:+.4} mm, RMS {:.4} -> {:.4} mm, \
             lowest {:+.4} mm (Monte Carlo low quantile {:+.4} mm), allowance {:.3} mm, {} \
             contacts",
            r.region,
            r.before.peak_mm,
            r.after.peak_mm,
            r.before.rms_mm,
            r.after.rms_mm,
            r.after.lowest_mm,
            r.after_low_p95_mm,
            r.allowance_mm,
            r.dwell.len()
        );
    }
    Ok(())
}

/// Prints what was planned: totals, accuracy, per region reach and warnings, table moves.
fn print_summary(plan: &motion::Plan, inspection: &Path, out: &Path) {
    let m = &plan.metrics;
    let planned: Vec<_> = plan
        .reachability
        .regions
        .iter()
        .filter(|r| r.layers > 0)
        .collect();
    println!(
        "plan: {} -> {}: {} region(s) planned, {} passes, {} path points, {} samples, predicted duration {:.2} s",
        inspection.display(),
        out.display(),
        planned.len(),
        plan.passes.len(),
        m.path_points,
        m.samples,
        m.predicted_duration_s
    );
    // no grinding sample at a steady cruise (every stroke too short to reach the set feed, or
    // a dwell plan): say so instead of "0.00..0.00 mm/s"
    let cruise = if m.cruise_feed_max_mm_s > 0.0 {
        format!(
            "cruise feed {:.4}..{:.4} mm/s (set {:.4})",
            m.cruise_feed_min_mm_s, m.cruise_feed_max_mm_s, m.feed_mm_s
        )
    } else {
        format!(
            "no stroke reaches a steady cruise at the set feed {:.4} mm/s",
            m.feed_mm_s
        )
    };
    println!(
        "plan: servo resolution alone moves the tool tip up to {:.3} mm (mean {:.3} mm); modelled tip within {:.4} mm of the path; {cruise}",
        m.resolution_error_max_mm,
        m.resolution_error_mean_mm,
        m.sample_to_path_max_mm.max(m.path_to_samples_max_mm),
    );
    for r in &planned {
        println!(
            "plan: region {}: {} layer(s), {:.0}% of its area unreachable, {:.1}% of the reachable part covered, {} of {} path points left out",
            r.id,
            r.layers,
            100.0 * r.unreachable_share,
            100.0 * r.coverage_of_reachable,
            r.unreachable_path_points,
            r.path_points
        );
        if r.peak_lower_bound {
            println!(
                "plan: warning: region {}: its peak {:+.4} mm is a lower bound (the inspection \
                 read it by single point pairs under a defect too narrow for a model): the \
                 layers reach down to it only; inspect again after grinding",
                r.id, r.peak_mm
            );
        }
        if r.touches_unmeasured {
            println!(
                "plan: warning: region {}: it touches an unmeasured area of the scan, so its peak \
                 {:+.4} mm and area are lower bounds and part of it may be unplanned; scan that \
                 area and inspect again",
                r.id, r.peak_mm
            );
        }
    }
    if let Some(t) = &plan.turntable {
        for r in &t.regions {
            println!(
                "plan: region {}: table at {:+.1} deg, {:.0}% of it reachable there ({:.0}% at 0 deg)",
                r.region,
                r.angle_deg,
                100.0 * r.reachable_share,
                100.0 * r.reachable_share_at_zero
            );
        }
        println!(
            "plan: turntable (servo {}): {} move(s), {:.2} s, ends at {:+.1} deg",
            t.servo_id,
            t.moves.len(),
            t.duration(plan.period),
            t.end().to_degrees()
        );
    }
    if let Some(u) = plan.reachability.unreachable.first() {
        println!(
            "plan: {} unreachable path point(s) left out (listed in plan.json), e.g. {u}",
            plan.reachability.unreachable.len()
        );
    }
}

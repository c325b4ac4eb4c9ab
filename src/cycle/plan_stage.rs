//! The planning stage with its files: [`plan_into`] plans from an inspection held in memory
//! (`motion::plan`) and writes plan.json with its provenance, plan.html, predicted.csv
//! (removal plans) and optionally the ROS trajectory, then prints what was planned.
//! `polishbot plan`, `demo` and the loop call it.
use std::path::{Path, PathBuf};

use anyhow::Result;
use serde::Deserialize;

use crate::motion::{self, ros, Plan, PlanConfig};
use crate::removal::prediction::{predicted_csv, RemovalReport};
use crate::removal::ToolModel;
use crate::repair::Inspection;
use crate::report::plan_html::write_plan_html;
use crate::report::provenance::{InputFile, Provenance};
use crate::robot::{CellFiles, RobotConfig, ToolText};

/// `--config` TOML of `plan` and `run`: `[robot]` (RobotConfig: urdf, tool, servos, workcell,
/// ik) and `[plan]` (PlanConfig).
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanFileConfig {
    /// Robot description and calibration files.
    pub robot: RobotConfig,
    /// Planner settings.
    pub plan: PlanConfig,
}

/// A plan made and written by [`plan_into`].
#[derive(Debug, Clone)]
pub struct Planned {
    /// The plan.
    pub plan: Plan,
    /// plan.json as written (with its provenance): a run's journal is tied to its SHA-256.
    pub text: String,
    /// predicted.csv as written (removal plans).
    pub predicted_csv: Option<String>,
    /// The tool's removal model the plan was made with (plan.json's
    /// `provenance.config.removal_tool`); None when the tool file has none.
    pub removal_tool: Option<ToolModel>,
    /// The tool file the plan was made with, as held in memory.
    pub tool: ToolText,
}

/// Plans from `inspection` (read from or written to `inspection.dir`) with `cfg` and the
/// cell's files `cell` (held in memory; `cfg.robot` names them) and writes
/// `out` (plan.json), its provenance, plan.html beside it, predicted.csv (removal plans) and
/// `export_ros`; prints what was planned. A setting the planner refuses is reported through
/// `refuse` (the caller names its settings file and line). `found`: the inspection when this
/// process made it: the files it wrote ([`crate::inspect::Findings::written`]) are recorded in
/// the provenance and its report.html gets the plan's link from the page held, without reading
/// them back; without it, the inspection's files are hashed and its report edited on disk.
pub fn plan_into(
    cfg: &PlanFileConfig,
    cell: &CellFiles,
    found: Option<&crate::inspect::Findings>,
    inspection: &Inspection,
    out: &Path,
    export_ros: Option<&Path>,
    refuse: &dyn Fn(&str) -> anyhow::Error,
) -> Result<Planned> {
    let mut cfg = cfg.clone();
    let tool = &cell.tool;
    let (robot, workcell) = cell.load()?;
    // the tool file's [removal] checked here, so that its errors name the file's full path
    let removal_tool = ToolModel::of_text(tool)?;
    cfg.plan.check(&robot).map_err(|e| match e {
        motion::PlanError::Config(m) => refuse(&m),
        e => e.into(),
    })?;
    let solids = motion::collide::solids_of(cell.solids.as_ref())?;
    // the cell's setups: setup 1 as held, then setup-N/ beside its workcell file
    let mut cells = vec![motion::setups::SetupCell {
        file: cfg.robot.workcell.clone(),
        workcell,
        table: cell.turntable()?,
        solids: solids.clone(),
    }];
    cells.extend(motion::setups::load_further(
        &cfg.robot.workcell,
        &cfg.robot.servos,
    )?);
    let tools = motion::tools::ToolRobot::of_cell(cell)?;
    let plan = motion::setups::plan(inspection, &tools, &cells, &cfg.plan)?;
    cfg.plan.collision.solids.extend(solids);
    let compact =
        serde_json::to_string(&plan).map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    let written = found.map_or(&[][..], |f| &f.written[..]);
    let provenance = provenance(&inspection.dir, &cfg.robot, cell, written, &cfg.plan)?;
    let text = provenance.stamp(&compact, out)?;
    std::fs::write(out, &text).map_err(|e| anyhow::anyhow!("{}: {e}", out.display()))?;
    let report = found.and_then(|f| f.report_html.as_deref());
    let page = write_plan_html(out, inspection, &plan, &provenance, report)?;
    let predicted_csv = match &plan.removal {
        Some(removal) => Some(write_removal(removal, out, &cfg.plan)?),
        None => None,
    };
    if let Some(yaml) = export_ros {
        std::fs::write(yaml, ros::joint_trajectory_yaml(&plan, "base_link"))
            .map_err(|e| anyhow::anyhow!("{}: {e}", yaml.display()))?;
    }
    println!("plan: report {}", page.display());
    print_summary(&plan, &inspection.dir, out);
    Ok(Planned {
        plan,
        text,
        predicted_csv,
        removal_tool: Some(removal_tool),
        tool: tool.clone(),
    })
}

/// The files a plan is made from, by role: the inspection's (under `inspection`) and the
/// cell's. plan.json's provenance records their SHA-256; `run` compares them with the files
/// it is given and refuses a plan made for other files.
pub fn plan_inputs(inspection: &Path, robot: &RobotConfig) -> Vec<(&'static str, PathBuf)> {
    vec![
        ("inspection regions", inspection.join("regions.json")),
        ("inspection deviations", inspection.join("deviations.csv")),
        ("robot description", robot.urdf.clone()),
        ("tool", robot.tool.clone()),
        ("servo calibration", robot.servos.clone()),
        ("workcell", robot.workcell.clone()),
        ("solids", robot.solids()),
    ]
}

/// The provenance of a plan: the inspection's files it read (those in `written` as written),
/// the cell's files as held (`cell`), the settings.
fn provenance(
    inspection: &Path,
    robot: &RobotConfig,
    cell: &CellFiles,
    written: &[InputFile],
    plan: &PlanConfig,
) -> Result<Provenance> {
    use rayon::prelude::*;
    let held = |p: &Path| written.iter().find(|f| f.path == p.display().to_string());
    let cell_files = cell.by_role();
    let of_cell = |role: &str| cell_files.iter().find(|(r, _)| *r == role).map(|c| c.1);
    let inputs = (plan_inputs(inspection, robot).into_par_iter())
        .filter(|(role, p)| match role.strip_prefix("inspection") {
            Some(_) => held(p).is_some() || p.is_file(),
            None => of_cell(role).is_some(),
        })
        .map(|(role, p)| match (of_cell(role), held(&p)) {
            (Some(f), _) => Ok(InputFile::held(role, &f.path, f.text.as_bytes())),
            (_, Some(f)) => Ok(InputFile {
                role: role.to_string(),
                ..f.clone()
            }),
            _ => InputFile::hash(role, &p),
        })
        .collect::<Result<Vec<_>>>()?;
    // the removal model the plan used (its k is what `calibrate removal` scales from)
    let removal_tool = ToolModel::of_text(&cell.tool).ok();
    let config = serde_json::json!({ "robot": robot, "plan": plan, "removal_tool": removal_tool });
    Provenance::of_inputs(
        "plan",
        "inspection in mm (reference frame); robot in m and rad (URDF base frame)",
        inputs,
        &config,
    )
}

/// Removal mode: writes predicted.csv beside the plan, prints each region's prediction and
/// returns the file's text.
fn write_removal(removal: &RemovalReport, out: &Path, cfg: &PlanConfig) -> anyhow::Result<String> {
    let csv = out.with_file_name("predicted.csv");
    let text = predicted_csv(removal, &cfg.monte_carlo);
    std::fs::write(&csv, &text).map_err(|e| anyhow::anyhow!("{}: {e}", csv.display()))?;
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
    Ok(text)
}

/// Prints what was planned: totals, accuracy, per region reach and warnings, table moves.
fn print_summary(plan: &Plan, inspection: &Path, out: &Path) {
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
    if let Some(c) = &plan.compensation {
        println!(
            "plan: compliance compensated; {} of {} grinding samples only partly (a joint limit; least share {:.2})",
            c.partial_samples, c.grinding_samples, c.least_share
        );
    }
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

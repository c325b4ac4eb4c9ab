//! The report side of `plan`: the provenance block of plan.json (and plan.html). Reads only
//! what plan.json already holds, so the planner's own files stay untouched.
use std::path::Path;

use anyhow::Result;

use crate::plan::PlanConfig;
use crate::report::provenance::Provenance;
use crate::robot::RobotConfig;

/// The provenance of a plan: the inspection's files it read, the cell's files, the settings.
pub fn provenance(inspection: &Path, robot: &RobotConfig, plan: &PlanConfig) -> Result<Provenance> {
    let (regions, deviations) = (
        inspection.join("regions.json"),
        inspection.join("deviations.csv"),
    );
    let files = [
        ("inspection regions", regions.as_path()),
        ("inspection deviations", deviations.as_path()),
        ("robot description", robot.urdf.as_path()),
        ("tool", robot.tool.as_path()),
        ("servo calibration", robot.servos.as_path()),
        ("workcell", robot.workcell.as_path()),
    ];
    let existing: Vec<(&str, &Path)> = files.into_iter().filter(|(_, p)| p.is_file()).collect();
    let config = serde_json::json!({ "robot": robot, "plan": plan });
    Provenance::new(
        "plan",
        "inspection in mm (reference frame); robot in m and rad (URDF base frame)",
        &existing,
        &config,
    )
}

//! Planning with a tool library (issue 51; the library: `robot::tool_library`): per region
//! the largest ball that fits without touching a second face and reaches. Every region is
//! planned with the largest ball first; a region it leaves short of good coverage (the ball
//! on a second face, the shank or a link against the part, out of reach) goes to the next
//! smaller ball that covers more of it ([`super::alternatives::assign`]). Regions are grouped
//! by tool, so a setup changes to each tool at most once; plan.json records the tool sequence
//! (`tools[]`), per region its tool, and per region left out every tool tried with its reason.
//!
//! Front function: [`plan`] with the library [`ToolRobot::of_cell`] reads.
use super::alternatives::{assign, merge_reports, Taken};
use super::config::PlanConfig;
use super::error::PlanError;
use super::file::{Plan, ToolPart};
use super::table::planned;
use crate::repair::{Inspection, RegionInfo};
use crate::robot::{sha256_hex, CellFiles, Robot, RobotError, Turntable, Workcell};

/// One tool of the library: the arm with that tool on its flange.
#[derive(Debug)]
pub struct ToolRobot {
    /// Its library name (tool.toml: `tool`).
    pub name: String,
    /// Its file.
    pub file: String,
    /// SHA-256 of its file's text.
    pub sha256: String,
    /// The arm carrying it.
    pub robot: Robot,
}

impl ToolRobot {
    /// The library of `cell` (tool.toml and `tools/*.toml`), largest ball first (equal balls:
    /// tool.toml, then by name).
    pub fn of_cell(cell: &CellFiles) -> Result<Vec<ToolRobot>, RobotError> {
        let mut out = cell
            .library()
            .into_iter()
            .map(|(name, text)| {
                Ok(ToolRobot {
                    robot: cell.with_tool(text).robot()?,
                    file: text.path.display().to_string(),
                    sha256: sha256_hex(text.text.as_bytes()),
                    name,
                })
            })
            .collect::<Result<Vec<_>, RobotError>>()?;
        out.sort_by(|a, b| b.robot.tool.radius.total_cmp(&a.robot.tool.radius));
        Ok(out)
    }

    /// The tool as plan.json lists it, with what it took.
    fn part(&self, taken: Taken) -> ToolPart {
        let tool = &self.robot.tool;
        ToolPart {
            tool: self.name.clone(),
            file: self.file.clone(),
            tool_sha256: self.sha256.clone(),
            ball_radius_mm: tool.radius_mm(),
            shank_length_mm: crate::robot::units::mm(tool.shank_length()),
            regions: taken.regions,
            tried: taken.tried,
            plan: taken.plan,
        }
    }

    /// `name (ball R mm, shank L mm)`.
    fn describe(&self) -> String {
        let tool = &self.robot.tool;
        format!(
            "{} (ball {:.1} mm, shank {:.1} mm)",
            self.name,
            tool.radius_mm(),
            crate::robot::units::mm(tool.shank_length())
        )
    }
}

/// Plans `inspection` with the part on `workcell` (and `table`) and the library `tools`
/// (largest ball first; one tool: exactly [`super::plan`]).
pub fn plan(
    inspection: &Inspection,
    tools: &[ToolRobot],
    workcell: &Workcell,
    table: Option<&Turntable>,
    config: &PlanConfig,
) -> Result<Plan, PlanError> {
    let Some(first) = tools.first() else {
        return Err(PlanError::Config("a cell with no tool".into()));
    };
    let plan_with =
        |k: usize, part: &Inspection| super::plan(part, &tools[k].robot, workcell, table, config);
    if tools.len() == 1 {
        return plan_with(0, inspection);
    }
    let eligible = |r: &RegionInfo| planned(r, config, &first.robot);
    let (mut top, taken) = assign(inspection, tools.len(), &eligible, &plan_with)?;
    let mark = |r: &mut super::RegionReport, k: usize| r.tool = Some(tools[k].name.clone());
    merge_reports(&mut top, &taken, inspection, &mark);
    name_tools_tried(&mut top, &taken, tools);
    top.tools = tools.iter().zip(taken).map(|(t, k)| t.part(k)).collect();
    Ok(top)
}

/// Every point left out names, after its own reason (the rule of the tool its region is
/// planned with), each other tool tried on its region and why that did not take it.
fn name_tools_tried(top: &mut Plan, taken: &[Taken], tools: &[ToolRobot]) {
    let tried_on = |region: usize| -> String {
        let named: Vec<String> = taken
            .iter()
            .zip(tools)
            .filter_map(|(t, tool)| {
                let tried = t.tried.iter().find(|x| x.region == region)?;
                let why = tried.refused.as_deref().unwrap_or("no better");
                Some(format!(
                    "{}: covers {:.1} %, {why}",
                    tool.describe(),
                    100.0 * tried.coverage
                ))
            })
            .collect();
        match named.is_empty() {
            true => String::new(),
            false => format!("; tools tried: {}", named.join("; ")),
        }
    };
    let mut by_region = std::collections::BTreeMap::new();
    for u in &mut top.reachability.unreachable {
        let text = by_region
            .entry(u.region)
            .or_insert_with(|| tried_on(u.region));
        u.reason.push_str(text);
    }
}

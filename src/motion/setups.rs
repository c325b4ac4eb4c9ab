//! Planning over several setups (fixturings) of the part (issue 51): a designed cell may hold
//! further setups in `setup-N/` beside its workcell.toml (N = 2, 3, ...; each a workcell.toml
//! with the part re-fixtured and the same `[turntable]`, and its solids.toml). Every region is
//! planned in setup 1 first; a region setup 1 leaves short of the table planner's good
//! coverage (or refuses) is planned in the next setup that covers more of it, and setup 1 is
//! planned again without it. The plan of setup 1 is the plan itself; each further setup's plan
//! rides in `setups[]` and streams after the operator re-fixtures the part. Per setup the plan
//! records the placement's SHA-256 (`run` refuses to stream a setup to another placement),
//! per region its setup, and per region the setups that did not take it and why.
//!
//! Front function: [`plan`] with the cells [`load`] reads.
use std::path::{Path, PathBuf};

use super::alternatives::{assign, merge_reports};
use super::config::PlanConfig;
use super::error::PlanError;
use super::file::Plan;
pub use super::file::{SetupPart, TriedSetup};
use super::table::planned;
use super::tools::ToolRobot;
use super::Solid;
use crate::repair::{Inspection, RegionInfo};
use crate::robot::{RobotError, Turntable, Workcell};

/// Name of a further setup's folder beside the cell's workcell.toml, before its number.
pub const SETUP_DIR: &str = "setup-";

/// Most setups read from a cell (setup-2 .. setup-9): a part has few stable fixturings.
const MAX_SETUPS: usize = 9;

/// One setup of the cell as read from its files.
#[derive(Debug, Clone)]
pub struct SetupCell {
    /// Its workcell.toml.
    pub file: PathBuf,
    /// The part's placement at table angle 0.
    pub workcell: Workcell,
    /// The turntable (its `[turntable]`).
    pub table: Option<Turntable>,
    /// Its solids.toml's solids.
    pub solids: Vec<Solid>,
}

/// SHA-256 (hex) of a placement's 16 numbers to 9 decimals (a further setup's workcell.toml
/// holds 9).
pub fn placement_sha256(wc: &Workcell) -> String {
    let m = &wc.robot_from_reference;
    let text: String = (0..4)
        .flat_map(|r| (0..4).map(move |c| (r, c)))
        .map(|(r, c)| format!("{:.9}\n", m[(r, c)] + 0.0))
        .collect();
    crate::robot::sha256_hex(text.as_bytes())
}

/// The workcell file of setup `n` (1: `workcell` itself).
pub fn setup_file(workcell: &Path, n: usize) -> PathBuf {
    if n <= 1 {
        return workcell.to_path_buf();
    }
    let dir = workcell.parent().unwrap_or(Path::new("."));
    dir.join(format!("{SETUP_DIR}{n}")).join("workcell.toml")
}

/// The further setups of the cell whose setup 1 is `workcell` (servo calibration `servos`):
/// `setup-2/workcell.toml`, `setup-3/...` beside it while they exist.
pub fn load_further(workcell: &Path, servos: &Path) -> Result<Vec<SetupCell>, RobotError> {
    let mut out = Vec::new();
    for n in 2..=MAX_SETUPS {
        let file = setup_file(workcell, n);
        if !file.is_file() {
            break;
        }
        out.push(SetupCell {
            workcell: Workcell::load(&file)?,
            table: Turntable::load(servos, &file)?,
            solids: super::collide::solids_beside(&file)?,
            file,
        });
    }
    Ok(out)
}

/// The setups of the cell whose setup 1 is `workcell`: setup 1 read from its files, then
/// [`load_further`].
pub fn load(workcell: &Path, servos: &Path) -> Result<Vec<SetupCell>, RobotError> {
    let mut out = vec![SetupCell {
        workcell: Workcell::load(workcell)?,
        table: Turntable::load(servos, workcell)?,
        solids: super::collide::solids_beside(workcell)?,
        file: workcell.to_path_buf(),
    }];
    out.extend(load_further(workcell, servos)?);
    Ok(out)
}

/// `config` with `cell`'s solids added.
fn with_solids(config: &PlanConfig, cell: &SetupCell) -> PlanConfig {
    let mut c = config.clone();
    c.collision.solids.extend(cell.solids.iter().cloned());
    c
}

/// Plans `inspection` over the setups `cells` (setup 1 first) with the tool library `tools`
/// (largest ball first, [`super::tools::plan`] per setup; one setup and one tool: exactly
/// [`super::plan`] with its solids added to `config`).
pub fn plan(
    inspection: &Inspection,
    tools: &[ToolRobot],
    cells: &[SetupCell],
    config: &PlanConfig,
) -> Result<Plan, PlanError> {
    let (false, Some(tool)) = (cells.is_empty(), tools.first()) else {
        return Err(PlanError::Config("a cell with no setup or no tool".into()));
    };
    let plan_with = |k: usize, part: &Inspection| {
        let cell = &cells[k];
        let table = cell.table.as_ref();
        super::tools::plan(
            part,
            tools,
            &cell.workcell,
            table,
            &with_solids(config, cell),
        )
    };
    let eligible = |r: &RegionInfo| planned(r, config, &tool.robot);
    let (mut top, taken) = assign(inspection, cells.len(), &eligible, &plan_with)?;
    if cells.len() == 1 {
        return Ok(top);
    }
    merge_reports(&mut top, &taken, inspection, &|r, k| r.setup = Some(k + 1));
    top.setups = cells
        .iter()
        .zip(taken)
        .enumerate()
        .map(|(k, (c, t))| SetupPart {
            setup: k + 1,
            workcell: c.file.display().to_string(),
            placement_sha256: placement_sha256(&c.workcell),
            regions: t.regions,
            tried: t.tried,
            plan: t.plan,
        })
        .collect();
    Ok(top)
}

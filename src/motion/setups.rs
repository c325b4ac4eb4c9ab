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
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::config::PlanConfig;
use super::error::PlanError;
use super::file::Plan;
pub use super::file::{SetupPart, TriedSetup};
use super::table::{coverage, first_clause, planned, GOOD_COVERAGE};
use super::Solid;
use crate::repair::Inspection;
use crate::robot::{Robot, RobotError, Turntable, Workcell};

/// Name of a further setup's folder beside the cell's workcell.toml, before its number.
pub const SETUP_DIR: &str = "setup-";

/// Most setups read from a cell (setup-2 .. setup-9): a part has few stable fixturings.
const MAX_SETUPS: usize = 9;

/// A coverage gain below this counts as none (a region is moved to a later setup only when
/// that covers more of it).
const GAIN_EPS: f64 = 1e-9;

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

/// `inspection` with the regions `keep` accepts.
fn only(inspection: &Inspection, keep: impl Fn(usize) -> bool) -> Inspection {
    let mut part = inspection.clone();
    part.regions.retain(|r| keep(r.id));
    part
}

/// Plans `inspection` over the setups `cells` (setup 1 first; one setup: exactly
/// [`super::plan`] with its solids added to `config`).
pub fn plan(
    inspection: &Inspection,
    robot: &Robot,
    cells: &[SetupCell],
    config: &PlanConfig,
) -> Result<Plan, PlanError> {
    let Some(first) = cells.first() else {
        return Err(PlanError::Config("a cell with no setup".into()));
    };
    let plan_in = |cell: &SetupCell, part: &Inspection| {
        super::plan(
            part,
            robot,
            &cell.workcell,
            cell.table.as_ref(),
            &with_solids(config, cell),
        )
    };
    let whole = plan_in(first, inspection)?;
    if cells.len() == 1 {
        return Ok(whole);
    }
    // best coverage so far per planned region, and the setup holding it
    let mut best: BTreeMap<usize, (usize, f64)> = inspection
        .regions
        .iter()
        .filter(|r| planned(r, config, robot))
        .map(|r| (r.id, (1, coverage(Some(&whole), r.id))))
        .collect();
    let mut parts: Vec<SetupPart> = cells
        .iter()
        .enumerate()
        .map(|(k, c)| SetupPart {
            setup: k + 1,
            workcell: c.file.display().to_string(),
            placement_sha256: placement_sha256(&c.workcell),
            regions: Vec::new(),
            tried: Vec::new(),
            plan: None,
        })
        .collect();
    for (k, cell) in cells.iter().enumerate().skip(1) {
        let short: Vec<usize> = best
            .iter()
            .filter(|(_, &(s, c))| s == 1 && c < GOOD_COVERAGE)
            .map(|(&id, _)| id)
            .collect();
        if short.is_empty() {
            break;
        }
        let trial = plan_in(cell, &only(inspection, |id| short.contains(&id)));
        let moved = judge(&trial, &short, &mut best, k + 1, &mut parts[k].tried);
        if moved.is_empty() {
            continue;
        }
        let sub = match (trial, moved.len() == short.len()) {
            (Ok(p), true) => p,
            _ => plan_in(cell, &only(inspection, |id| moved.contains(&id)))?,
        };
        parts[k].regions = moved;
        parts[k].plan = Some(Box::new(sub));
    }
    let moved: Vec<usize> = best
        .iter()
        .filter(|(_, &(s, _))| s > 1)
        .map(|(&id, _)| id)
        .collect();
    let mut top = if moved.is_empty() {
        whole
    } else {
        plan_in(first, &only(inspection, |id| !moved.contains(&id)))?
    };
    parts[0].regions = top.reachability.planned_ids();
    merge_reports(&mut top, &mut parts, inspection);
    top.setups = parts;
    Ok(top)
}

/// Which of the `short` regions the setup `setup`'s `trial` plan covers better than `best`
/// (updated to it); the others go into `tried` with the trial's coverage and reason.
fn judge(
    trial: &Result<Plan, PlanError>,
    short: &[usize],
    best: &mut BTreeMap<usize, (usize, f64)>,
    setup: usize,
    tried: &mut Vec<TriedSetup>,
) -> Vec<usize> {
    let mut moved = Vec::new();
    for &id in short {
        let had = best.get(&id).map_or(0.0, |b| b.1);
        let (c, why) = match trial {
            Err(e) => (0.0, Some(first_clause(&e.to_string()))),
            Ok(p) => {
                let c = coverage(Some(p), id);
                let why = p
                    .reachability
                    .unreachable
                    .iter()
                    .find(|u| u.region == id)
                    .map(|u| first_clause(&u.reason));
                (c, why)
            }
        };
        if c > had + GAIN_EPS {
            best.insert(id, (setup, c));
            moved.push(id);
        } else {
            let refused = why.or_else(|| {
                Some(format!(
                    "covers {:.1} % of it, no more than before",
                    100.0 * c
                ))
            });
            tried.push(TriedSetup {
                region: id,
                coverage: c,
                refused,
            });
        }
    }
    moved
}

/// Setup 1's plan `top` reports every region: each planned region gets its setup, and the
/// reports (and points left out) of the regions moved to a later setup come from that
/// setup's plan, in regions.json order.
fn merge_reports(top: &mut Plan, parts: &mut [SetupPart], inspection: &Inspection) {
    for r in &mut top.reachability.regions {
        r.setup = Some(1);
    }
    for part in parts.iter().skip(1) {
        let Some(sub) = &part.plan else { continue };
        let of = |id: usize| part.regions.contains(&id);
        for r in sub.reachability.regions.iter().filter(|r| of(r.id)) {
            let mut r = r.clone();
            r.setup = Some(part.setup);
            top.reachability.regions.retain(|x| x.id != r.id);
            top.reachability.regions.push(r);
        }
        let left = sub.reachability.unreachable.iter().filter(|u| of(u.region));
        top.reachability.unreachable.extend(left.cloned());
    }
    let order = |id: usize| inspection.regions.iter().position(|r| r.id == id);
    top.reachability.regions.sort_by_key(|r| order(r.id));
}

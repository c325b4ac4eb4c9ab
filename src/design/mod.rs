//! Cell design (issue 51): searches the part's mounting on a turntable (which direction of the
//! part lies along the table axis), the table axis (vertical, horizontal or tilted on a
//! bracket), the table's place beside the arm and the tool's shank length for the largest
//! share of the articular surface the arm can grind. A surface sample counts as reached when
//! at some table angle the planner's own IK (`Robot::ik`: reach, joint limits, the 45 degree
//! cone of the tool axis about the arm plane) places the ball on its normal and the planner's
//! collision model (`motion::collide::Scene`, rule `Grind`: no second face, shank and links
//! clear of the part and of the cell's solids, including the table's fixture) accepts the
//! pose. Front: [`design`]; files: [`write::write_cell`]. Method: docs/ALGORITHMS.md, "Cell
//! design".
mod config;
mod eval;
pub mod family;
mod part;
mod search;
pub mod setups;
pub mod write;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use nalgebra::Matrix4;
use serde::Serialize;

use crate::motion::{PlanConfig, Solid};
use crate::robot::{Robot, Servos, Tool};

pub use config::DesignConfig;
pub use eval::Candidate;
pub use part::{load_mesh, Part, SampleVerdict};

/// The source cell: the arm, its servos (with the turntable's servo) and the tool.
pub struct SourceCell {
    /// Folder the files came from.
    pub dir: PathBuf,
    urdf: urdf_rs::Robot,
    tool: Tool,
    servos: Servos,
}

impl SourceCell {
    /// Reads `dir`'s dofbot.urdf, servos.toml (it must have a `[turntable]` servo) and
    /// tool.toml.
    pub fn load(dir: &Path) -> Result<SourceCell> {
        let urdf_file = dir.join("dofbot.urdf");
        let urdf = urdf_rs::read_file(&urdf_file)
            .map_err(|e| anyhow::anyhow!("{}: {e}", urdf_file.display()))?;
        let tool = Tool::load(&dir.join("tool.toml"))?;
        let servos = Servos::load(&dir.join("servos.toml"))?;
        anyhow::ensure!(
            servos.turntable.is_some(),
            "{}: no [turntable] servo; cell design needs a cell with a part turntable (e.g. calibration/turntable)",
            dir.join("servos.toml").display()
        );
        Ok(SourceCell {
            dir: dir.to_path_buf(),
            urdf,
            tool,
            servos,
        })
    }

    /// The robot with a tool whose ball centre sits `shank` metres past the flange along the
    /// wrist-roll axis (the shank as long).
    pub fn robot(&self, shank: f64) -> Result<Robot> {
        let mut tool = self.tool.clone();
        tool.tip_offset = [0.0, 0.0, shank];
        tool.shank_length = Some(shank);
        let servos_file = self.dir.join("servos.toml");
        Ok(Robot::from_parts(
            self.urdf.clone(),
            &self.dir.join("dofbot.urdf"),
            tool,
            self.servos.clone(),
            &servos_file,
        )?)
    }
}

/// The designed cell and its score.
#[derive(Debug, Clone, Serialize)]
pub struct Design {
    /// The winning candidate.
    pub candidate: Candidate,
    /// robot_from_reference at table angle 0 (metres, as workcell.toml).
    pub robot_from_reference: [[f64; 4]; 4],
    /// The fixed solids: the base plane and the table's spindle, housing and post.
    pub solids: Vec<(String, [f64; 3], [f64; 3])>,
    /// Share of the articular surface reached (area-uniform samples).
    pub coverage: f64,
    /// Per refusing rule, the samples it refused.
    pub refused: BTreeMap<String, usize>,
    /// Every final sample's verdict.
    pub samples: Vec<SampleVerdict>,
    /// Candidates scored.
    pub candidates_scored: usize,
    /// The best of each table-axis family (vertical, horizontal, tilted) and its coverage at
    /// the ranking stage: the alternatives tried.
    pub alternatives: Vec<(String, f64, Candidate)>,
    /// The fixturings of the part: the candidate's mounting first, then the further ones
    /// (`setups::setups`), each with its own coverage and the coverage of all up to it.
    pub setups: Vec<setups::Fixturing>,
    /// The cell of each further setup (setup 2 on), written to the cell folder's `setup-N/`
    /// (not in design.json: `setups` there names their mountings).
    #[serde(skip)]
    pub setup_cells: Vec<FurtherSetup>,
    /// The cell's coverage of the part's family (`family::MEMBERS`: its sizes at the ends of
    /// an implant family and its mirror image), each member held as the part is; scored by
    /// [`design`], not by [`assess`].
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub family: Vec<family::FamilyMember>,
}

/// A further setup's placement and solids, as written to `setup-N/workcell.toml` and
/// `setup-N/solids.toml`.
#[derive(Debug, Clone)]
pub struct FurtherSetup {
    /// The candidate with this setup's mounting.
    pub candidate: Candidate,
    /// robot_from_reference at table angle 0 (metres, as workcell.toml).
    pub robot_from_reference: [[f64; 4]; 4],
    /// The fixed solids with this mounting's spindle.
    pub solids: Vec<(String, [f64; 3], [f64; 3])>,
    /// Share of the articular surface this setup reaches alone.
    pub coverage: f64,
}

/// Searches the cell for `part` from `source`'s arm, servos and tool.
pub fn design(part: &Part, source: &SourceCell, cfg: &DesignConfig) -> Result<Design> {
    let plan = PlanConfig::default();
    let robots = cfg
        .shanks_m
        .iter()
        .map(|&s| source.robot(s))
        .collect::<Result<Vec<_>>>()?;
    let ctx = context(part, source, &robots, &cfg.shanks_m, &plan)?;
    let found = search::run(&ctx, cfg);
    let mut d = assess_in(&ctx, &found.best, cfg)?;
    d.candidates_scored = found.scored;
    d.alternatives = found.alternatives;
    d.family = family::family(
        &ctx,
        &d.candidate,
        &d.setups,
        cfg.final_samples,
        cfg.final_step_deg,
    );
    Ok(d)
}

/// Scores one given cell (`candidate`) on the final samples, as [`design`] scores its winner.
pub fn assess(
    part: &Part,
    source: &SourceCell,
    cfg: &DesignConfig,
    candidate: &Candidate,
) -> Result<Design> {
    let plan = PlanConfig::default();
    let robot = source.robot(candidate.shank_m)?;
    let robots = vec![robot];
    let shanks = [candidate.shank_m];
    let ctx = context(part, source, &robots, &shanks, &plan)?;
    let one = Candidate {
        shank: 0,
        ..candidate.clone()
    };
    assess_in(&ctx, &one, cfg)
}

/// The share of the final samples the setups of `d` reach together (its coverage with one).
pub fn union_coverage(d: &Design) -> f64 {
    d.setups.last().map_or(d.coverage, |s| s.union_coverage)
}

/// The scoring context of `part` in `source`'s cell with one arm per shank.
fn context<'a>(
    part: &'a Part,
    source: &SourceCell,
    robots: &'a [Robot],
    shanks: &'a [f64],
    plan: &'a PlanConfig,
) -> Result<eval::Context<'a>> {
    Ok(eval::Context {
        part,
        robots,
        shanks,
        plan,
        servo: source
            .servos
            .turntable
            .clone()
            .context("no turntable servo")?,
    })
}

fn assess_in(ctx: &eval::Context, best: &Candidate, cfg: &DesignConfig) -> Result<Design> {
    let part = ctx.part;
    let fin = eval::score(ctx, best, cfg.final_samples, cfg.final_step_deg, true)
        .context("the cell is not buildable: its fixture or the part meets the base plane, or the arm's home pose meets the part")?;
    let wc = eval::placement(best, &part.centroid);
    let solids: Vec<Solid> = eval::solids(best, part).unwrap_or_default();
    let mut refused = BTreeMap::new();
    for v in &fin.verdicts {
        if let Some(r) = &v.refused_by {
            *refused.entry(r.clone()).or_insert(0) += 1;
        }
    }
    let reached: Vec<bool> = fin.verdicts.iter().map(|v| v.angle_deg.is_some()).collect();
    let setups = setups::setups(ctx, best, &reached, cfg, cfg.final_step_deg);
    let setup_cells = setups
        .iter()
        .skip(1)
        .map(|s| {
            let candidate = Candidate {
                mount: s.mount,
                ..best.clone()
            };
            FurtherSetup {
                robot_from_reference: rows(&eval::placement(&candidate, &part.centroid)),
                solids: boxes(eval::solids(&candidate, part).unwrap_or_default()),
                coverage: s.coverage,
                candidate,
            }
        })
        .collect();
    Ok(Design {
        candidate: best.clone(),
        robot_from_reference: rows(&wc),
        solids: boxes(solids),
        coverage: fin.coverage,
        refused,
        samples: fin.verdicts,
        candidates_scored: 1,
        alternatives: Vec::new(),
        setups,
        setup_cells,
        family: Vec::new(),
    })
}

/// A workcell's robot_from_reference as rows.
fn rows(wc: &crate::robot::Workcell) -> [[f64; 4]; 4] {
    let m: Matrix4<f64> = wc.robot_from_reference;
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// Solids as (name, min, max).
fn boxes(solids: Vec<Solid>) -> Vec<(String, [f64; 3], [f64; 3])> {
    solids.into_iter().map(|s| (s.name, s.min, s.max)).collect()
}

//! Cell design (issue 51): searches the part's mounting on a turntable (which direction of the
//! part lies along the table axis), the table axis (vertical, horizontal or tilted on a
//! bracket), the table's place beside the arm and the tool's shank length for the largest
//! share of the articular surface the arm can grind. A surface sample counts as reached when
//! at some table angle the planner's own IK (`Robot::ik`: reach, joint limits, the 45 degree
//! cone of the tool axis about the arm plane) places the ball on its normal and the planner's
//! collision model (`plan::collide::Scene`, rule `Grind`: no second face, shank and links
//! clear of the part and of the cell's solids, including the table's fixture) accepts the
//! pose. Front: [`design`]; files: [`write::write_cell`]. Method: docs/ALGORITHMS.md, "Cell
//! design".
mod eval;
mod search;
pub mod write;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use nalgebra::{Matrix4, Point3, Vector3};
use serde::Serialize;

use crate::cloud::{self, Geometry, Mesh, Units};
use crate::plan::{PlanConfig, Solid, SurfacePoint};
use crate::robot::{Robot, Servos, Tool};
use crate::spatial::Neighbours;

pub use eval::Candidate;

/// Settings of the cell design. Every field has a documented default.
#[derive(Debug, Clone)]
pub struct DesignConfig {
    /// Articular-surface samples scored per candidate in the coarse grid (80: the grid has
    /// thousands of candidates; 80 samples tell a 90 % mounting from a 60 % one).
    pub coarse_samples: usize,
    /// Samples scored per candidate in the ranking and refinement stages (250).
    pub samples: usize,
    /// Samples of the final score printed and drawn (1,500: about 3 per square centimetre of a
    /// femoral articular surface, 0.1 % steps).
    pub final_samples: usize,
    /// Points of the part's collision model (6,000: about 1.7 mm apart on a femoral component,
    /// under the 3 mm ball radius the second-face test needs).
    pub part_points: usize,
    /// Table angle step of the coarse grid, degrees (30).
    pub coarse_step_deg: f64,
    /// Table angle step of the later stages, degrees (10).
    pub step_deg: f64,
    /// Shank lengths tried (ball centre to flange), metres (19.3 mm, the shipped tool; 35 and
    /// 50 mm, stock long-shank burrs).
    pub shanks_m: Vec<f64>,
    /// Distances of the table centre from the base axis along the arm plane, metres.
    pub distances_m: Vec<f64>,
    /// Heights of the table centre above the base plane, metres.
    pub heights_m: Vec<f64>,
    /// Candidates of the coarse grid kept for ranking (16).
    pub keep: usize,
    /// Rounds of local refinement around the best candidate (3).
    pub rounds: usize,
    /// Seed of the surface samples (1).
    pub seed: u64,
    /// Table axes of the grid, robot frame (default: vertical; horizontal across and along
    /// the arm plane; tilted 45 degrees on a bracket towards, away from and across it).
    pub axes: Vec<[f64; 3]>,
}

impl Default for DesignConfig {
    fn default() -> Self {
        DesignConfig {
            coarse_samples: 80,
            samples: 250,
            final_samples: 1500,
            part_points: 6000,
            coarse_step_deg: 30.0,
            step_deg: 10.0,
            shanks_m: vec![0.0193, 0.035, 0.05],
            distances_m: vec![0.14, 0.19, 0.24],
            heights_m: vec![0.06, 0.11, 0.16, 0.21],
            keep: 16,
            rounds: 3,
            seed: 1,
            axes: search::AXES.to_vec(),
        }
    }
}

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

/// The part: its collision model and the articular surface's samples (reference frame, mm).
pub struct Part {
    /// Points of the whole part with outward normals.
    pub points: Vec<SurfacePoint>,
    /// Centroid of those points, mm: it sits on the table axis.
    pub centroid: Point3<f64>,
    /// Articular-surface samples with outward normals, in a random order (any prefix is a
    /// uniform sample).
    pub surface: Vec<(Point3<f64>, Vector3<f64>)>,
}

impl Part {
    /// Samples `reference` (the whole part, a closed mesh) and `surface` (its articular
    /// surface, same frame); the surface's normals are turned to agree with the nearest
    /// outward normal of the part.
    pub fn new(reference: &Mesh, surface: &Mesh, cfg: &DesignConfig) -> Result<Part> {
        let mut mesh = reference.clone();
        mesh.orient_outward();
        let whole = cloud::sample_mesh(&mesh, cfg.part_points, cfg.seed)?.cloud;
        let normals = whole.normals.clone().context("sampled normals")?;
        let points: Vec<SurfacePoint> = whole
            .points
            .iter()
            .zip(&normals)
            .map(|(p, n)| SurfacePoint {
                position: *p,
                normal: *n,
                distance: 0.0,
                region: -1,
            })
            .collect();
        let n = points.len().max(1) as f64;
        let centroid = Point3::from(
            points
                .iter()
                .fold(Vector3::zeros(), |s, p| s + p.position.coords)
                / n,
        );
        let index = Neighbours::new(&whole.points);
        let art = cloud::sample_mesh(surface, cfg.final_samples, cfg.seed + 1)?.cloud;
        let art_normals = art.normals.clone().context("sampled normals")?;
        let surface = art
            .points
            .iter()
            .zip(&art_normals)
            .map(|(p, nrm)| {
                let outward = index.nearest(p).map_or(*nrm, |k| normals[k.index]);
                (*p, if nrm.dot(&outward) < 0.0 { -nrm } else { *nrm })
            })
            .collect();
        Ok(Part {
            points,
            centroid,
            surface,
        })
    }
}

/// Loads a mesh file (reference or surface) in `units`.
pub fn load_mesh(path: &Path, units: Option<Units>) -> Result<Mesh> {
    match cloud::load(path, None, units)?.geometry {
        Geometry::Mesh { mesh, .. } => Ok(mesh),
        Geometry::Cloud(_) => {
            anyhow::bail!("{}: has no faces; cell design needs a mesh", path.display())
        }
    }
}

/// The verdict on one articular-surface sample in the designed cell.
#[derive(Debug, Clone, Serialize)]
pub struct SampleVerdict {
    /// Position, reference frame, mm.
    pub position_mm: [f64; 3],
    /// Outward normal.
    pub normal: [f64; 3],
    /// The table angle that reaches it, degrees (none: not reached).
    pub angle_deg: Option<f64>,
    /// Not reached: the rule that refused it at the table angle that came nearest (a
    /// collision after a solved IK is nearer than joint limits, which are nearer than the
    /// wrist out of reach, which is nearer than the tool axis off the arm plane).
    pub refused_by: Option<String>,
    /// That nearest table angle, degrees.
    pub nearest_angle_deg: Option<f64>,
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
}

/// Searches the cell for `part` from `source`'s arm, servos and tool.
pub fn design(part: &Part, source: &SourceCell, cfg: &DesignConfig) -> Result<Design> {
    let plan = PlanConfig::default();
    let robots = cfg
        .shanks_m
        .iter()
        .map(|&s| source.robot(s))
        .collect::<Result<Vec<_>>>()?;
    let ctx = eval::Context {
        part,
        robots: &robots,
        shanks: &cfg.shanks_m,
        plan: &plan,
        servo: source
            .servos
            .turntable
            .clone()
            .context("no turntable servo")?,
    };
    let found = search::run(&ctx, cfg);
    let mut d = assess_in(&ctx, &found.best, cfg)?;
    d.candidates_scored = found.scored;
    d.alternatives = found.alternatives;
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
    let ctx = eval::Context {
        part,
        robots: &robots,
        shanks: &shanks,
        plan: &plan,
        servo: source
            .servos
            .turntable
            .clone()
            .context("no turntable servo")?,
    };
    let one = Candidate {
        shank: 0,
        ..candidate.clone()
    };
    assess_in(&ctx, &one, cfg)
}

fn assess_in(ctx: &eval::Context, best: &Candidate, cfg: &DesignConfig) -> Result<Design> {
    let part = ctx.part;
    let fin = eval::score(ctx, best, cfg.final_samples, cfg.step_deg, true)
        .context("the cell is not buildable: its fixture or the part meets the base plane, or the arm's home pose meets the part")?;
    let wc = eval::placement(best, &part.centroid);
    let solids: Vec<Solid> = eval::solids(best, part).unwrap_or_default();
    let mut refused = BTreeMap::new();
    for v in &fin.verdicts {
        if let Some(r) = &v.refused_by {
            *refused.entry(r.clone()).or_insert(0) += 1;
        }
    }
    let m: Matrix4<f64> = wc.robot_from_reference;
    Ok(Design {
        candidate: best.clone(),
        robot_from_reference: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
        solids: solids.into_iter().map(|s| (s.name, s.min, s.max)).collect(),
        coverage: fin.coverage,
        refused,
        samples: fin.verdicts,
        candidates_scored: 1,
        alternatives: Vec::new(),
    })
}

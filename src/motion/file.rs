//! plan.json on disk: writing, reading, and the full re-check a plan must pass before `run`
//! sends anything (the file is never trusted).
use std::path::Path;

use dofbot_protocol::servo::SERVO_COUNT;

use super::error::PlanError;
use super::frames;
use super::program::{PlannedPass, Segment};
use super::report::{Metrics, Reachability};
use super::table_file::TablePlan;
use super::trajectory::JointTrajectory;
use super::validate::{validate, ValidationConfig};
use crate::robot::Robot;
use serde::{Deserialize, Serialize};

/// One joint-trajectory sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Time, s (index x period).
    pub t: f64,
    /// Joint angles, rad, URDF order.
    pub q: Vec<f64>,
}

/// How much of the compliance correction a compensated plan's `commands` carry: near a joint
/// limit a stretch keeps only a share of it (docs/ALGORITHMS.md, "Compliance compensation").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompensationReport {
    /// Grinding samples in the plan.
    pub grinding_samples: usize,
    /// Grinding samples commanded with only a share of their correction (partial).
    pub partial_samples: usize,
    /// The smallest share of its correction any grinding sample keeps (1: all whole).
    pub least_share: f64,
}

/// A grinding plan: the contents of plan.json (docs/FORMATS.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// "polishbot-plan".
    pub format: String,
    /// Format version (1).
    pub version: u32,
    /// The inspection folder planned from.
    pub inspection: String,
    /// Bus period, s: one sample and one frame per period.
    pub period: f64,
    /// URDF joint names, the order of every `q`.
    pub joint_names: Vec<String>,
    /// Tool (ball) radius, mm.
    pub tool_radius_mm: f64,
    /// The raster geometry used, mm.
    pub stepover_mm: f64,
    /// Footprint radius used for coverage, mm.
    pub footprint_mm: f64,
    /// Predicted duration of the motion, s.
    pub predicted_duration_s: f64,
    /// Reachable pieces of the passes with their tool poses and joint solutions.
    pub passes: Vec<PlannedPass>,
    /// What each stretch of samples does.
    pub segments: Vec<Segment>,
    /// The joint trajectory at the bus period.
    pub samples: Vec<Sample>,
    /// The servo command stream: one 0x1D frame per sample after the first (hex).
    pub frames: Vec<String>,
    /// The joint angles the servos are commanded per sample, rad, when the plan compensates
    /// the arm's compliance (servos.toml `[compliance]`; `samples` are then the loaded joints
    /// the plan wants, and the frames are made from these); absent: the frames are made from
    /// `samples`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commands: Option<Vec<Vec<f64>>>,
    /// How much of the compliance correction `commands` carry (absent without `commands`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compensation: Option<CompensationReport>,
    /// Reach and coverage per region, every point left out and why.
    pub reachability: Reachability,
    /// Measured quality of the plan.
    pub metrics: Metrics,
    /// Removal mode: the strokes the plan used (a raster, or finishing strokes with their
    /// preload and turns: `motion::finish`); absent in rigid mode and in older plans.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strokes: Option<super::finish::StrokeRecord>,
    /// Removal mode: the dwell map and the predicted part per region (absent in rigid mode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub removal: Option<crate::removal::prediction::RemovalReport>,
    /// The turntable's angles and moves (absent in a cell without a turntable).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turntable: Option<TablePlan>,
    /// A cell with further setups (`setup-N/` beside its workcell.toml): per setup its
    /// placement's hash, the regions planned in it and, from setup 2 on, its own plan, which
    /// streams after the operator re-fixtures the part (absent in a cell with one setup).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub setups: Vec<SetupPart>,
    /// A cell with a tool library (`tools/` beside tool.toml): the tool sequence of this plan
    /// (largest ball first), per tool its file's hash, the regions it grinds and, from the
    /// second tool on, its own plan, which streams after the operator mounts that tool
    /// (absent with one tool; docs/FORMATS.md).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tools: Vec<ToolPart>,
}

/// A tool of the library in plan.json, in the order the run mounts them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ToolPart {
    /// The tool's library name (tool.toml: `tool`; `tools/NAME.toml`: NAME).
    pub tool: String,
    /// Its file as planned with.
    pub file: String,
    /// SHA-256 of that file: the tool's stage streams only when the cell's file of that name
    /// gives the same.
    pub tool_sha256: String,
    /// Ball radius, mm.
    pub ball_radius_mm: f64,
    /// Shank length from the ball centre, mm.
    pub shank_length_mm: f64,
    /// Regions ground with this tool.
    pub regions: Vec<usize>,
    /// Regions tried with this tool and left where they were: what it covered and why not more.
    pub tried: Vec<TriedSetup>,
    /// This tool's plan (second tool on; the first tool's is the plan holding this list).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<Box<Plan>>,
}

/// A setup in plan.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetupPart {
    /// Setup number, 1 first.
    pub setup: usize,
    /// The workcell file planned on.
    pub workcell: String,
    /// SHA-256 of the placement (`setups::placement_sha256`): the setup streams only to a cell
    /// whose workcell file gives the same.
    pub placement_sha256: String,
    /// Regions planned in this setup.
    pub regions: Vec<usize>,
    /// Regions tried in this setup and left where they were: what it covered and why not more.
    pub tried: Vec<TriedSetup>,
    /// This setup's plan (setup 2 on; setup 1's is the plan holding this list).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<Box<Plan>>,
}

/// A region tried in a setup that did not take it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TriedSetup {
    /// The region.
    pub region: usize,
    /// Share of its core points the setup's plan covered (0: refused).
    pub coverage: f64,
    /// The first reason the setup's plan gives (the rule that refused the region's contacts,
    /// or the planner's error); None when it covered no less than the region's setup.
    pub refused: Option<String>,
}

/// A plan that passed [`Plan::check`]: its frames as bytes and their raw poses.
#[derive(Debug, Clone)]
pub struct CheckedPlan {
    /// One 0x1D frame per sample.
    pub frames: Vec<Vec<u8>>,
    /// Raw positions of servos 1..6 per frame.
    pub raw: Vec<[u16; SERVO_COUNT]>,
    /// Move time of every frame, ms (the period).
    pub time_ms: u16,
    /// The turntable's moves (`None`: the plan turns no table; see [`Plan::check_cell`]).
    pub table: Option<super::table_file::CheckedTable>,
}

impl Plan {
    /// Writes plan.json.
    pub fn save(&self, path: &Path) -> Result<(), PlanError> {
        let text = serde_json::to_string(self)
            .map_err(|e| PlanError::input(path, "file", e.to_string()))?;
        std::fs::write(path, text).map_err(|e| PlanError::input(path, "file", e.to_string()))
    }

    /// Reads plan.json (no checks beyond the format: see [`Plan::check`]).
    pub fn load(path: &Path) -> Result<Plan, PlanError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| PlanError::input(path, "file", e.to_string()))?;
        Plan::parse(path, &text)
    }

    /// Parses a plan file's text; `path` names it in errors. The rules of [`Plan::load`]
    /// (which reads the file and calls this), for callers that also need the bytes.
    pub fn parse(path: &Path, text: &str) -> Result<Plan, PlanError> {
        let plan: Plan = serde_json::from_str(text).map_err(|e| {
            PlanError::input(
                path,
                format!("line {} column {}", e.line(), e.column()),
                e.to_string(),
            )
        })?;
        if plan.format != "polishbot-plan" || plan.version != 1 {
            let msg = format!(
                "format {:?} version {}, expected \"polishbot-plan\" 1",
                plan.format, plan.version
            );
            return Err(PlanError::input(path, "format", msg));
        }
        Ok(plan)
    }

    /// Checks everything `run` relies on against `robot`: joint names and period, sample
    /// times, every sample within joint limits, servo ranges and velocity / acceleration /
    /// jerk limits, and every frame equal byte for byte to the frame the sample makes, with
    /// raw steps between frames within the velocity limits.
    pub fn check(
        &self,
        robot: &Robot,
        config: &ValidationConfig,
    ) -> Result<CheckedPlan, PlanError> {
        let bad = |m: String| Err(PlanError::Frames(m));
        if (self.turntable.as_ref()).is_some_and(|t| !t.moves.is_empty() || !t.synced.is_empty()) {
            return bad(
                "the plan turns the part turntable: it needs the cell's turntable to be checked (run --cell DIR)".into(),
            );
        }
        let names: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
        if self.joint_names != names {
            return bad(format!(
                "joint names {:?} differ from the robot's {names:?}",
                self.joint_names
            ));
        }
        if (self.period - robot.servos.period).abs() > 1e-12 {
            return bad(format!(
                "period {} differs from servos.toml's {}",
                self.period, robot.servos.period
            ));
        }
        if self.samples.is_empty() {
            return bad("no samples".into());
        }
        let mut traj = JointTrajectory::starting_at(&self.samples[0].q, self.period);
        for (i, s) in self.samples.iter().enumerate() {
            if s.q.len() != robot.dof() || s.q.iter().any(|v| !v.is_finite()) {
                return bad(format!(
                    "sample {i}: needs {} finite joint angles",
                    robot.dof()
                ));
            }
            if (s.t - i as f64 * self.period).abs() > 1e-9 {
                return bad(format!("sample {i}: t {} is not {i} periods", s.t));
            }
            if i > 0 {
                traj.push(&s.q);
            }
        }
        let violations = validate(&traj, robot, config);
        if !violations.is_empty() {
            return Err(PlanError::Invalid(violations));
        }
        let qs = self.commanded(robot, config)?;
        if self.frames.len() != self.samples.len() {
            return bad(format!(
                "{} frames for {} samples",
                self.frames.len(),
                self.samples.len()
            ));
        }
        let map = frames::servo_map(robot)?;
        let hold = frames::gripper_hold_deg(robot)?;
        let expected = frames::encode(&qs, &map, hold, self.period)?;
        let time_ms = frames::frame_time_ms(self.period)?;
        let mut raw = Vec::with_capacity(expected.len());
        for (i, (text, want)) in self.frames.iter().zip(&expected).enumerate() {
            let (pose, ms) =
                frames::decode(text).map_err(|e| PlanError::Frames(format!("frame {i}: {e}")))?;
            if ms != time_ms || frames::to_hex(want) != *text {
                return bad(format!(
                    "frame {i} is not the frame sample {i} makes ({})",
                    frames::to_hex(want)
                ));
            }
            raw.push(pose);
        }
        for (k, spec) in robot.joints.iter().enumerate() {
            let servo = robot.servos.servos.iter().find(|s| s.id == spec.servo_id);
            let per_rad = servo.map_or(0.0, |s| s.counts_per_degree().to_degrees());
            let most = (spec.velocity * self.period * per_rad * (1.0 + config.derivative_tolerance))
                .ceil() as u16
                + 1;
            for (i, w) in raw.windows(2).enumerate() {
                let step = w[1][k].abs_diff(w[0][k]);
                if step > most {
                    return bad(format!("frames {i}..{}: servo {} steps {step} counts, the velocity limit allows {most}", i + 1, spec.servo_id));
                }
            }
        }
        Ok(CheckedPlan {
            frames: expected,
            raw,
            time_ms,
            table: None,
        })
    }

    /// The joint angles the frames must encode: `commands` when present (checked: one per
    /// sample, finite, within [`MAX_COMMAND_OFFSET_RAD`] of its sample, within the limits, and
    /// only for a robot whose servos.toml has `[compliance]`), else the samples.
    fn commanded(
        &self,
        robot: &Robot,
        config: &ValidationConfig,
    ) -> Result<Vec<Vec<f64>>, PlanError> {
        let bad = |m: String| Err(PlanError::Frames(m));
        let Some(commands) = &self.commands else {
            return Ok(self.samples.iter().map(|s| s.q.clone()).collect());
        };
        if robot.servos.compliance.is_none() {
            return bad(
                "the plan compensates the arm's compliance (`commands`) but servos.toml has no [compliance]"
                    .into(),
            );
        }
        if commands.len() != self.samples.len() {
            return bad(format!(
                "{} commands for {} samples",
                commands.len(),
                self.samples.len()
            ));
        }
        let mut traj = JointTrajectory::starting_at(&self.samples[0].q, self.period);
        traj.positions.clear();
        for (i, (c, s)) in commands.iter().zip(&self.samples).enumerate() {
            if c.len() != s.q.len() || c.iter().any(|v| !v.is_finite()) {
                return bad(format!(
                    "command {i}: needs {} finite joint angles",
                    s.q.len()
                ));
            }
            if let Some(why) = offset_refused(i, c, &s.q) {
                return bad(why);
            }
            traj.push(c);
        }
        let violations = validate(&traj, robot, config);
        if !violations.is_empty() {
            return Err(PlanError::Invalid(violations));
        }
        Ok(commands.clone())
    }
}

/// Why command `i` is refused for lying more than [`MAX_COMMAND_OFFSET_RAD`] from its sample
/// `sample` (largest joint difference), or None: the check `run` makes on a compensated plan,
/// and the planner on its own commands before it writes them.
pub fn offset_refused(i: usize, command: &[f64], sample: &[f64]) -> Option<String> {
    let off = super::program::max_step(command, sample);
    (off > MAX_COMMAND_OFFSET_RAD).then(|| {
        format!(
            "command {i} lies {off:.4} rad from its sample, more than the {MAX_COMMAND_OFFSET_RAD} rad a compliance correction makes"
        )
    })
}

/// Largest joint difference between a command and its sample a plan may hold, rad (0.05,
/// 2.9 degrees: three times the largest correction the DOFBOT's model makes, a 0.5 degree
/// band plus the bending of 2 N and the arm's weight, about 0.015 rad; more is a damaged file).
pub const MAX_COMMAND_OFFSET_RAD: f64 = 0.05;

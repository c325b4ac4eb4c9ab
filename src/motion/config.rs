//! The planner's settings ([`PlanConfig`], `[plan]` in a config file) with their accepted
//! ranges, and the work bound checked before rastering.
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use super::aim::Aim;
use super::collide::CollisionConfig;
use super::error::PlanError;
use super::finish::FinishConfig;
use super::raster::RasterGeometry;
use super::trajectory::TrajectoryConfig;
use super::validate::ValidationConfig;
use crate::removal;
use crate::repair::Inspection;
use crate::robot::{IkConfig, Robot};

/// How `plan` removes material.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum PlanMode {
    /// A compliant tool pressed at its preload, one raster per region, the dwell of every
    /// contact from Preston's law (the default: the DOFBOT's tool-point error is far above
    /// any depth a layer could hold, docs/ALGORITHMS.md "Removal mode of `plan`").
    #[default]
    Removal,
    /// Depth layers of `depth_step_mm` at one feed (`--mode rigid`): a rigid burr on a stiff
    /// machine.
    Rigid,
}

/// Settings of the grinding planner. Lengths on the part in millimetres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlanConfig {
    /// Distance between raster lines as a share of the tool (ball) radius (0.8).
    pub stepover: f64,
    /// Radius of the tool footprint on the surface as a share of the tool radius (0.5): the
    /// width a pass grinds, used to place the lines and to measure coverage.
    pub footprint: f64,
    /// Spacing of contact points along a pass, mm (0.5).
    pub spacing_mm: f64,
    /// Depth removed per layer, mm (0.1): a region of peak h gets ceil(h / step) layers.
    pub depth_step_mm: f64,
    /// Material left above nominal after the last layer, mm (0.0).
    pub allowance_mm: f64,
    /// Extra distance of the ball from the contact along the normal, mm (0.0; the ball's
    /// radius from tool.toml is always added).
    pub contact_offset_mm: f64,
    /// Feed speed of the tool tip along passes, mm/s (5.0).
    pub feed_mm_s: f64,
    /// Path acceleration at the ends of a stroke, m/s^2 (0.05).
    pub path_acceleration: f64,
    /// Path jerk at the ends of a stroke, m/s^3 (1.0).
    pub path_jerk: f64,
    /// Share of each joint limit strokes may use (0.9); rest-to-rest moves use the full limit.
    pub joint_margin: f64,
    /// Approach and retract height along the normal, mm (5.0; halved up to twice when the
    /// arm cannot reach it).
    pub retract_mm: f64,
    /// Largest joint change between neighbouring contact points, rad (0.05): larger jumps
    /// (an IK branch change) split the stroke.
    pub max_joint_step: f64,
    /// Largest angle between a stroke's mean surface normal and any of its points' normals for
    /// the stroke to be ground with one fixed tool axis, degrees (20). The achieved axis is
    /// always checked against each point's own normal (`ik.max_axis_miss_deg`).
    pub axis_spread_deg: f64,
    /// Joint angles the program starts and ends at, rad ([0, 0, 0, 0, 0]: every servo at 90
    /// degrees).
    pub home: Vec<f64>,
    /// Fail when any planned contact point is unreachable (false: report and splice around).
    pub require_full_reach: bool,
    /// Largest accepted distance between the modelled tool tip and the planned path, mm (0.1).
    pub max_path_error_mm: f64,
    /// Inverse kinematics (default: IkConfig's defaults with `limit_margin` 0.01 rad, so the
    /// splines between IK solutions stay inside the joint limits).
    pub ik: IkConfig,
    /// Sampling of the trajectory (the bus period).
    pub trajectory: TrajectoryConfig,
    /// Validation tolerances.
    pub validation: ValidationConfig,
    /// The collision model: margins, link radii, fixed solids.
    pub collision: CollisionConfig,
    /// Removal (default) or rigid depth layers.
    pub mode: PlanMode,
    /// The dwell solve of removal mode.
    pub removal: removal::RemovalConfig,
    /// The Monte Carlo of the arm's error in removal mode.
    pub monte_carlo: removal::montecarlo::MonteCarloConfig,
    /// Share of each servo's rated torque the contact force may take (0.5, issue 28).
    pub force_share: f64,
    /// Tolerance of the removal mode when the inspection names none, mm (0.05, issue 28).
    pub tolerance_mm: f64,
    /// Where to aim the contacts: the removal shift measured on earlier grinds, carried by
    /// the loop (`motion::aim`; empty: aim where the removal is wanted).
    #[serde(skip_serializing_if = "Aim::is_empty")]
    pub aim: Aim,
    /// Command the servos so that the loaded joints sit on the plan where servos.toml has a
    /// `[compliance]` table, and keep the grinding contacts' joints room for that correction
    /// from their limits (true; without `[compliance]` it does nothing; measured on the
    /// demo-like part, tests/compensation.rs: the simulated loaded tip's median / p95 / max
    /// distance from the planned tip 1.463 / 2.173 / 2.225 mm uncompensated, 0.148 / 0.156 /
    /// 2.056 mm compensated: docs/ALGORITHMS.md, "Compliance compensation").
    pub compensate_compliance: bool,
    /// The loop's later grinds as finishing strokes (`motion::finish`: a smaller influence,
    /// a cross-hatch, the removal capped); the loop sets `finish.grind`.
    #[serde(skip_serializing_if = "FinishConfig::is_default")]
    pub finish: FinishConfig,
    /// In a cell with a turntable, the most further pieces a region short of 95 % covered
    /// may be split into, each planned at another table angle (2; 0: no split; docs/
    /// ALGORITHMS.md, "Turntable", step 5).
    pub table_pieces: usize,
    /// In a cell with a turntable, rigid mode: the most strokes per region still short after
    /// its pieces that are ground with the table turning during the stroke (the table as a
    /// sixth axis, `motion::table_sync`; 0: none).
    #[serde(skip_serializing_if = "is_default_sync")]
    pub table_sync: usize,
}

/// Whether `n` is [`TABLE_SYNC`] (left out of a written plan.toml, as before the setting).
fn is_default_sync(n: &usize) -> bool {
    *n == TABLE_SYNC
}

/// Most strokes per short region ground with the table turning during the stroke: each one is
/// a trip from home with a table move before it, so a handful bounds the plan's time.
pub const TABLE_SYNC: usize = 8;

impl Default for PlanConfig {
    fn default() -> Self {
        PlanConfig {
            stepover: 0.8,
            footprint: 0.5,
            spacing_mm: 0.5,
            depth_step_mm: 0.1,
            allowance_mm: 0.0,
            contact_offset_mm: 0.0,
            feed_mm_s: 5.0,
            path_acceleration: 0.05,
            path_jerk: 1.0,
            joint_margin: 0.9,
            retract_mm: 5.0,
            max_joint_step: 0.05,
            axis_spread_deg: 20.0,
            home: vec![0.0; 5],
            require_full_reach: false,
            max_path_error_mm: 0.1,
            ik: IkConfig {
                limit_margin: 0.01,
                ..IkConfig::default()
            },
            trajectory: TrajectoryConfig::default(),
            validation: ValidationConfig::default(),
            collision: CollisionConfig::default(),
            mode: PlanMode::Removal,
            removal: removal::RemovalConfig::default(),
            monte_carlo: removal::montecarlo::MonteCarloConfig::default(),
            force_share: removal::force::DEFAULT_FORCE_SHARE,
            tolerance_mm: DEFAULT_TOLERANCE_MM,
            aim: Aim::default(),
            compensate_compliance: true,
            finish: FinishConfig::default(),
            table_pieces: TABLE_PIECES,
            table_sync: TABLE_SYNC,
        }
    }
}

/// Most further pieces per region split by table angle: each costs a table move and an
/// approach from home. On femoral_dm's uniform case 5100 (removal mode) 2 pieces took the
/// planned share from 63.3 to 67.6 % in the turntable cell and from 67.6 to 71.2 % in the
/// designed cell, and 3 added nothing (tests/uniform.rs,
/// `uniform_defects_split_by_table_angle`).
pub const TABLE_PIECES: usize = 2;
/// Most accepted `table_pieces`: each piece plans the region again at up to 3 table angles,
/// so the setting bounds the planning time.
const MAX_TABLE_PIECES: usize = 10;

/// Tolerance of removal mode when the inspection names none, mm: the acceptance
/// tolerance.
pub const DEFAULT_TOLERANCE_MM: f64 = 0.05;

impl PlanConfig {
    /// The defaults in rigid mode (today's depth layers).
    pub fn rigid() -> Self {
        PlanConfig {
            mode: PlanMode::Rigid,
            ..PlanConfig::default()
        }
    }
}

/// Accepted range and unit of every numeric [`PlanConfig`] setting: wide around the defaults,
/// narrow enough that no setting makes the work grow without bound (a depth step of 1e-9 mm
/// would mean a billion layers, a spacing of 1e-9 mm a billion points per line).
const RANGES: [(&str, f64, f64, &str); 13] = [
    ("stepover", 0.01, 2.0, "× tool radius"),
    ("footprint", 0.01, 1.0, "× tool radius"),
    ("spacing_mm", 0.01, 50.0, "mm"),
    ("depth_step_mm", 0.001, 10.0, "mm"),
    ("allowance_mm", 0.0, 10.0, "mm"),
    ("contact_offset_mm", -10.0, 10.0, "mm"),
    ("feed_mm_s", 0.01, 100.0, "mm/s"),
    ("path_acceleration", 1e-4, 10.0, "m/s^2"),
    ("path_jerk", 1e-3, 1000.0, "m/s^3"),
    ("retract_mm", 0.01, 100.0, "mm"),
    ("max_joint_step", 1e-4, 1.0, "rad"),
    ("axis_spread_deg", 0.0, 90.0, "deg"),
    ("max_path_error_mm", 1e-3, 10.0, "mm"),
];

/// Most depth layers over one region: 100 layers are 10 mm at the default 0.1 mm step, far
/// beyond a defect a grinder should remove; more means a bad peak or step.
pub const MAX_LAYERS: f64 = 100.0;
/// Most contact points over all regions and layers (estimated from each region's extent
/// before rastering): at the default 0.5 mm spacing and 5 mm/s feed, 200,000 points grind
/// for about 5.5 hours.
pub const MAX_CONTACT_POINTS: f64 = 200_000.0;

/// Largest `[plan.ik] max_axis_miss_deg`, degrees (90): a tool axis farther than square to
/// the wanted one grinds with the shank, not the ball (the default cone is 45 degrees).
const MAX_AXIS_MISS_DEG: f64 = 90.0;
/// Largest `[plan.ik] verify_tolerance` (1e-3: a millimetre or a milliradian between FK(IK)
/// and the target; the default is 1e-9, solutions are exact to about that).
const MAX_IK_VERIFY: f64 = 1e-3;
/// Largest `[plan.ik] limit_margin`, rad (0.5, 29 degrees: the DOFBOT's joints turn 180
/// degrees, so a wider margin leaves under two thirds of a joint's range).
const MAX_IK_LIMIT_MARGIN: f64 = 0.5;

impl PlanConfig {
    /// Checks every setting against its range ([`RANGES`]: the message names the key in
    /// backticks, with the value and unit), the home pose and the period against `robot`.
    pub fn check(&self, robot: &Robot) -> Result<(), PlanError> {
        let values = [
            self.stepover,
            self.footprint,
            self.spacing_mm,
            self.depth_step_mm,
            self.allowance_mm,
            self.contact_offset_mm,
            self.feed_mm_s,
            self.path_acceleration,
            self.path_jerk,
            self.retract_mm,
            self.max_joint_step,
            self.axis_spread_deg,
            self.max_path_error_mm,
        ];
        for ((name, lo, hi, unit), v) in RANGES.iter().zip(values) {
            if !(v.is_finite() && (*lo..=*hi).contains(&v)) {
                return Err(PlanError::Config(format!(
                    "`{name}` = {v:?} {unit} is outside {lo}..={hi} {unit}"
                )));
            }
        }
        self.collision
            .check(robot.dof())
            .map_err(PlanError::Config)?;
        self.removal.check().map_err(PlanError::Config)?;
        self.monte_carlo.check().map_err(PlanError::Config)?;
        (self.validation.check()).map_err(|m| PlanError::Config(format!("validation: {m}")))?;
        self.aim.check().map_err(PlanError::Config)?;
        self.finish.check().map_err(PlanError::Config)?;
        for (name, v, hi) in [
            ("force_share", self.force_share, 1.0),
            ("tolerance_mm", self.tolerance_mm, 10.0),
            (
                "ik.max_axis_miss_deg",
                self.ik.max_axis_miss_deg,
                MAX_AXIS_MISS_DEG,
            ),
            (
                "ik.verify_tolerance",
                self.ik.verify_tolerance,
                MAX_IK_VERIFY,
            ),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= hi) {
                return Err(PlanError::Config(format!(
                    "`{name}` = {v:?} is outside 0 (excluded)..={hi}"
                )));
            }
        }
        let m = self.ik.limit_margin;
        if !(m.is_finite() && (0.0..=MAX_IK_LIMIT_MARGIN).contains(&m)) {
            return Err(PlanError::Config(format!(
                "`ik.limit_margin` = {m:?} rad is outside 0..={MAX_IK_LIMIT_MARGIN} rad"
            )));
        }
        if self.table_pieces > MAX_TABLE_PIECES {
            return Err(PlanError::Config(format!(
                "`table_pieces` = {} is outside 0..={MAX_TABLE_PIECES}",
                self.table_pieces
            )));
        }
        if !(self.joint_margin > 0.0 && self.joint_margin <= 1.0) {
            let m = self.joint_margin;
            return Err(PlanError::Config(format!(
                "`joint_margin` = {m:?} is outside 0 (excluded)..=1"
            )));
        }
        if self.home.len() != robot.dof() {
            let msg = format!(
                "`home` has {} joints, the arm {}",
                self.home.len(),
                robot.dof()
            );
            return Err(PlanError::Config(msg));
        }
        if let Some(i) = robot.limit_violation(&self.home, 0.0) {
            let msg = format!("`home` is outside the limits of {}", robot.joints[i].name);
            return Err(PlanError::Config(msg));
        }
        if (self.trajectory.period - robot.servos.period).abs() > 1e-12 {
            let msg = format!(
                "`period` {} s of [plan.trajectory] differs from the bus period {} s of servos.toml",
                self.trajectory.period, robot.servos.period
            );
            return Err(PlanError::Config(msg));
        }
        Ok(())
    }

    /// The raster geometry for a tool of radius `radius_mm`.
    pub fn geometry(&self, radius_mm: f64) -> RasterGeometry {
        RasterGeometry {
            stepover: self.stepover * radius_mm,
            footprint: self.footprint * radius_mm,
            spacing: self.spacing_mm,
            depth_step: self.depth_step_mm,
            allowance: self.allowance_mm,
        }
    }
}

/// Refuses an inspection whose planning would exceed [`MAX_LAYERS`] layers on a region or
/// [`MAX_CONTACT_POINTS`] contact points in all: layers from each repairable region's peak,
/// points from the extent of its members across the raster (lines × points per line).
pub(crate) fn check_work(inspection: &Inspection, g: &RasterGeometry) -> Result<(), PlanError> {
    let file = inspection.dir.join("regions.json");
    let mut total = 0.0;
    for r in inspection.regions.iter().filter(|r| r.repairable) {
        let layers = ((r.peak - g.allowance) / g.depth_step).ceil().max(0.0);
        if layers > MAX_LAYERS {
            let msg = format!(
                "peak {} mm above an allowance of {} mm at a depth step of {} mm needs {layers} \
                 layers, more than {MAX_LAYERS}",
                r.peak, g.allowance, g.depth_step
            );
            return Err(PlanError::input(&file, format!("region {}", r.id), msg));
        }
        let members = inspection.region_points(r.id);
        let extent = members.iter().fold(0.0f64, |m, &i| {
            let d = inspection.points[i].position - Point3::from(r.centroid);
            m.max(d.norm())
        });
        let lines = 2.0 * extent / g.stepover + 1.0;
        let per_line = 2.0 * extent / g.spacing + 1.0;
        total += layers * lines * per_line;
    }
    if total > MAX_CONTACT_POINTS {
        return Err(PlanError::Config(format!(
            "the regions of {} would take about {total:.0} contact points, more than \
             {MAX_CONTACT_POINTS} (`spacing_mm` {} mm, `stepover` {} mm, `depth_step_mm` {} mm)",
            inspection.dir.display(),
            g.spacing,
            g.stepover,
            g.depth_step
        )));
    }
    Ok(())
}

//! The simulated cell grinds a virtual part (issue 29): while the simulated arm executes a
//! plan, material is removed where its tool ball physically is, by the *true* removal law of
//! this module. It is deliberately not the planner's model: its own code, its own parameters
//! (`[sim.grinding]` of `run`'s config, [`GrindConfig`]), its own forward kinematics (from
//! DOFBOT.md, not `robot/`) and its own true mounting of the part. Nothing in `plan/` reads it.
//!
//! Chain of frames: the part file's points (scan frame) go into the reference frame by the
//! inspection's `registration.json` (`scan_to_reference`: where the scanned material sits
//! relative to the CAD frame); the part's CAD frame sits on the fixture at the workcell's
//! nominal `robot_from_reference` moved by the hidden offsets `mount_offset_mm` and
//! `mount_rotation_deg` (given in the reference frame). The servos' physical angles over
//! virtual time ([`trace::ServoTrace`]) give the ball centre through [`fk`] and the sim's own
//! `tip_offset_mm`, through the gear backlash and the gravity sag of [`slack`]. Method and
//! parameters: docs/ALGORITHMS.md, "Simulated grinding".
//!
//! Front function: [`grind`] with a [`GrindConfig`]; result: [`GrindReport`].
pub mod fk;
pub mod law;
pub mod part;
pub mod slack;
pub mod trace;

use nalgebra::{Matrix4, Point3, Vector3};
use serde::Serialize;

pub use super::grinding::{GrindConfig, MountGive};
pub use law::{preston_rate, HertzContact, KField};
pub use part::{ToolState, VirtualPart};
pub use trace::ServoTrace;

/// Fixed step of the removal integration over virtual time, s: a tenth of the bus period
/// (20 ms), so the servos' linear moves between frames are sampled ten times; at the planner's
/// default feed (5 mm/s) the ball moves 0.01 mm per step, a thirtieth of the smallest Hertz
/// patch the default tool makes at 0.01 mm penetration (0.36 mm radius).
pub const SIM_STEP_S: f64 = 0.002;

/// What a simulated grind did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct GrindReport {
    /// Integration steps.
    pub steps: usize,
    /// Steps with the ball in contact.
    pub contact_steps: usize,
    /// Largest contact force, N.
    pub peak_force_n: f64,
    /// Largest removal at a point, mm.
    pub peak_removal_mm: f64,
    /// Points with any removal.
    pub points_ground: usize,
}

/// Grinds `part` (reference frame, mm) over virtual time `0..t_end` s at [`SIM_STEP_S`], the
/// tool where the replayed servos put it through the sim's own kinematics, the part mounted at
/// `nominal` (`robot_from_reference`, metres) moved by the hidden offsets of `cfg`.
pub fn grind(
    part: &mut VirtualPart,
    trace: &mut ServoTrace,
    t_end: f64,
    nominal: &Matrix4<f64>,
    cfg: &GrindConfig,
) -> GrindReport {
    let mount = cfg.true_robot_from_reference(nominal);
    let reference_from_robot = mount
        .try_inverse()
        .expect("a rigid transform has an inverse");
    let mut arm = slack::Arm::new(cfg);
    let lag = cfg.tracking_lag_s();
    let joints_at = |trace: &mut ServoTrace, t: f64| {
        let deg = trace.physical_deg((t - lag).max(0.0));
        std::array::from_fn(|k| fk::joint_of_servo_deg(deg[k]))
    };
    let origin = Point3::new(mount[(0, 3)], mount[(1, 3)], mount[(2, 3)]);
    let absorbed = absorbed_offset(&arm, &mut trace.clone(), t_end, &origin, &joints_at);
    let mut force = Vector3::zeros();
    let mut report = GrindReport::default();
    let steps = (t_end / SIM_STEP_S).ceil().max(0.0) as usize;
    let mut prev = None;
    for s in 0..=steps {
        let t = s as f64 * SIM_STEP_S;
        let (c, axis) = arm.tool(joints_at(trace, t), force);
        let centre =
            Point3::from(reference_from_robot.transform_point(&(c - absorbed)).coords * 1e3);
        let axis = reference_from_robot.transform_vector(&axis).normalize();
        let Some(before) = prev.replace(centre) else {
            continue;
        };
        let tool = ToolState {
            centre,
            axis,
            velocity: (centre - before) / SIM_STEP_S,
        };
        report.steps += 1;
        force = Vector3::zeros();
        if let Some(c) = part.grind_step(&tool, SIM_STEP_S, cfg) {
            report.contact_steps += 1;
            report.peak_force_n = report.peak_force_n.max(c.force_n);
            if let Some((i, _)) = part.penetration(&centre, cfg.ball_radius_mm) {
                force = mount.transform_vector(&part.normals()[i]).normalize() * c.force_n;
            }
        }
    }
    report.peak_removal_mm = part.removal().iter().copied().fold(0.0, f64::max);
    report.points_ground = part.removal().iter().filter(|r| **r > 0.0).count();
    report
}

/// Step between the poses [`absorbed_offset`] looks at, s: one bus period (20 ms).
const ABSORB_STEP_S: f64 = 0.02;

/// Spread of the cell's calibration touch-offs around the part's origin, m (5 mm): the
/// calibration touched the fixture near the origin more than once, a few millimetres apart,
/// so what it absorbed is the mean offset over those touches; the run's poses are weighted by
/// `exp(-((d - d_min) / spread)^2)` with `d` the tip's distance from the origin, so that two
/// nearly tied poses with different offsets do not make the absorbed offset jump.
const TOUCH_SPREAD_M: f64 = 0.005;
/// Weight under which a pose is left out of that mean (1e-3: beyond 2.6 spreads).
const TOUCH_MIN_WEIGHT: f64 = 1e-3;

/// What the workcell calibration absorbed of the arm's sag and backlash, m (robot frame): the
/// cell was calibrated by touching the fixture with the arm loaded by its weight, so the
/// ball's offset there (gravity on each loaded joint's flank, no contact force) went into the
/// calibrated part pose. A weighted mean over the run's poses whose tip lies near the part's
/// origin `origin` ([`TOUCH_SPREAD_M`]).
fn absorbed_offset(
    arm: &slack::Arm,
    trace: &mut ServoTrace,
    t_end: f64,
    origin: &Point3<f64>,
    joints_at: &dyn Fn(&mut ServoTrace, f64) -> [f64; 5],
) -> Vector3<f64> {
    let tip_m = arm.tip_m();
    let n = (t_end / ABSORB_STEP_S).ceil().max(0.0) as usize;
    let poses: Vec<([f64; 5], f64)> = (0..=n)
        .map(|s| {
            let q = joints_at(trace, s as f64 * ABSORB_STEP_S);
            (q, (fk::tool(&q, &tip_m).0 - origin).norm())
        })
        .collect();
    let nearest = poses.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let (mut sum, mut weight) = (Vector3::zeros(), 0.0);
    for (q, d) in &poses {
        let w = (-((d - nearest) / TOUCH_SPREAD_M).powi(2)).exp();
        if w >= TOUCH_MIN_WEIGHT {
            sum += (arm.held(*q, Vector3::zeros()).0 - fk::tool(q, &tip_m).0) * w;
            weight += w;
        }
    }
    if weight > 0.0 {
        sum / weight
    } else {
        Vector3::zeros()
    }
}

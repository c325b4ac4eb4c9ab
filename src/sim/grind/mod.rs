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
//! `tip_offset_mm`, through the gear backlash and the gravity sag of [`slack`]. Method and parameters: docs/ALGORITHMS.md, "Simulated grinding".
//!
//! Front function: [`grind`] with a [`GrindConfig`]; result: [`GrindReport`].
pub mod fk;
pub mod law;
pub mod part;
pub mod slack;
pub mod trace;

use nalgebra::{Matrix4, Point3};
use serde::Serialize;

pub use super::grinding::GrindConfig;
pub use law::{preston_rate, Contact, KField};
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
    let tip_m = cfg.tip_offset_mm.map(|v| v * 1e-3);
    let mut backlash = slack::Backlash::new(&cfg.backlash_deg);
    let r0 = nominal[(0, 3)].hypot(nominal[(1, 3)]);
    let sag = slack::Sag::new(cfg.sag_full_reach_mm, tip_m[2], r0);
    let mut tool_at = |trace: &mut ServoTrace, t: f64| {
        let deg = trace.physical_deg(t);
        let q = backlash.follow(std::array::from_fn(|k| fk::joint_of_servo_deg(deg[k])));
        let (c, axis) = fk::tool(&q, &tip_m);
        let c = sag.apply(c);
        let c_ref = reference_from_robot.transform_point(&c) * 1e3;
        let axis_ref = reference_from_robot.transform_vector(&axis).normalize();
        (Point3::from(c_ref.coords), axis_ref)
    };
    let mut report = GrindReport::default();
    let steps = (t_end / SIM_STEP_S).ceil().max(0.0) as usize;
    let (mut prev, _) = tool_at(trace, 0.0);
    for s in 1..=steps {
        let t = s as f64 * SIM_STEP_S;
        let (centre, axis) = tool_at(trace, t);
        let tool = ToolState {
            centre,
            axis,
            velocity: (centre - prev) / SIM_STEP_S,
        };
        prev = centre;
        report.steps += 1;
        if let Some(c) = part.grind_step(&tool, SIM_STEP_S, cfg) {
            report.contact_steps += 1;
            report.peak_force_n = report.peak_force_n.max(c.force_n);
        }
    }
    report.peak_removal_mm = part.removal().iter().copied().fold(0.0, f64::max);
    report.points_ground = part.removal().iter().filter(|r| **r > 0.0).count();
    report
}

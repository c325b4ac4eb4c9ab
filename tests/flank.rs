//! Issue 50, build item 2: "every contact is approached so that each joint sits on the same
//! flank". The compensated plan's commands replayed in time order through the simulator's
//! mechanics (`common::replay`), where a joint whose load torque is under the simulator's hold
//! threshold trails its motion (the base yaw and the wrist roll carry no gravity torque): how
//! far each gear's history moves the tip at the grinding samples and at the presses in.
mod common;

use common::replay::{fully_compensated_p95, print_replayed};
use polishbot::motion::{plan_part, Plan, PlanConfig};
use polishbot::robot::Workcell;
use polishbot::sim::GrindConfig;

/// The 95th percentile of the compensated tip's error along the surface, replayed in time
/// order (history of the gears), over the samples the plan compensated in full, must stay
/// under this, mm (0.5, tests/compensation.rs's bound for the poses held still: the history
/// must not add to it). The samples the plan corrects only in part (a joint at its limit) are
/// the largest errors whether held still or replayed: under the rim guard they are 6.5 % of
/// the samples and the p95 of all, 0.760 mm replayed against 0.762 held still (2026-12-06).
const REPLAYED_LATERAL_P95_MM: f64 = 0.5;
/// Largest share of grinding samples where some gear's history moves the tip more than
/// `common::replay::HISTORY_MOVE_MM` (0.06). Measured 0.002 on the demo-like part (8 of 4,035
/// samples, the elbow where gravity and the contact force cancel) while the replay pressed
/// along each pass's nominal normal; pressed along the part's normal the inspection measured
/// under the pass (what the plan now loads the arm with, `PlannedPass::contact_normal`: the
/// simulated arm follows the part's own normal, and the nominal one put its base yaw on the
/// other flank at 5-22 % of survey case 161's grinding samples), 0.047 (2026-12-06, with the
/// guard's feasible lift): where the measured normal points at the base's axis the yaw's load
/// is under the simulator's hold torque and its gear trails the motion; 0.046 (2026-12-07)
/// with the model's gear trailing its motion there (`Compliance::deflection_trailing`) and the
/// yaw set on the way down ([`PRESS_YAW_P95_MM`]): the history is now modelled, the share of
/// samples it acts on is the part's. Bounded here so that it cannot grow unseen.
const HISTORY_SHARE: f64 = 0.06;
/// Largest 95th percentile, over the presses onto a first contact, of how far the base yaw's
/// gear sits from its load's flank when the press starts, mm at the tip (0.5, the replayed
/// error's own bound): the way down turns the yaw through 1.5 bands so that the gear touches
/// down on the flank its contact loads (`motion::free_motion`'s yaw set). Measured
/// 2026-12-07 on the demo-like part: median / p95 / max 0.000 / 0.000 / 1.102 mm over 84
/// presses with the set, 0.090 / 1.657 / 2.174 mm without it (the gear where the transit left
/// it): on a bump of a face looking at the base both flanks hold themselves once pressed, so
/// the flank it touches down on is the one it grinds on.
const PRESS_YAW_P95_MM: f64 = 0.5;

/// The compensated plan replayed in time order through the simulator's mechanics (issue 50,
/// build item 2: each joint on a known flank at every contact). A joint under the hold torque
/// would trail its motion by half its band, a lateral error (1.1 mm of base yaw at 0.25 m)
/// that flips with the stroke direction and that a pose held still does not show; the planned
/// 2 N along the nominal normal gave the base yaw 0.013-0.22 N m on this part, so every gear
/// but the wrist roll's (no torque; the ball sits on its axis) was held on its load's flank;
/// along the measured normal the yaw trails at 4.7 % of the samples ([`HISTORY_SHARE`]).
/// Measured 2026-12-06 before the rim guard: replayed error median / p95 / max 0.145 / 0.156 /
/// 1.587 mm (0.143 / 0.155 / 1.587 along the surface); under it 0.140 / 0.760 / 1.648 along
/// the surface, 0.140 / 0.762 / 1.662 held still (the p95 a partly compensated sample); a
/// gear's history moves the tip over 0.05 mm at 0.2 % of the grinding samples; with a tenth
/// of the force (0.2 N) the base yaw trails at 75 % of them (1.1 mm p95) and this fails.
/// 2026-12-07, with the gears trailing their motion in the model and the yaw set on the way
/// down: the fully compensated samples' p95 along the surface 0.276 mm (0.368 before, 0.361
/// with the trailing model alone).
#[test]
fn compensated_tip_replayed_in_time_order_stays_on_the_planned_contacts() {
    let dir = common::tempdir();
    let inspection = common::synthetic::demo_like(&dir.path().join("inspection"));
    let wc = Workcell::load(&common::calib("workcell.toml")).unwrap();
    let arm = GrindConfig::default();
    let compliant = common::dofbot();
    let cfg = PlanConfig {
        compensate_compliance: true,
        ..PlanConfig::default()
    };
    let plan = plan_part(&inspection, &compliant, &wc, &cfg).expect("compensated plan");
    assert!(plan.commands.is_some(), "no commands");
    let (lateral, moved, yaw_press) = print_replayed(&plan, &compliant, &wc, &arm);
    let p95 = fully_compensated_p95(&lateral, plan.compensation.as_ref());
    println!("fully compensated samples: p95 along the surface {p95:.3} mm");
    assert!(
        p95 < REPLAYED_LATERAL_P95_MM && moved < HISTORY_SHARE && yaw_press < PRESS_YAW_P95_MM,
        "replayed error along the surface, p95 of the fully compensated samples {p95:.3} mm, \
         {moved} of the samples on a flank their load does not set, the base yaw {yaw_press:.3} \
         mm off its flank at the presses' start (p95)"
    );
}

/// [`print_replayed`] of the plan.json named by `POLISHBOT_REPLAY_PLAN` (e.g. a kept
/// acceptance run's grind), on the shipped cell and the documented arm: a measurement to run
/// by hand.
#[test]
#[ignore]
fn replay_a_plan_file() {
    let path = std::env::var("POLISHBOT_REPLAY_PLAN").expect("POLISHBOT_REPLAY_PLAN");
    let plan = Plan::load(std::path::Path::new(&path)).unwrap();
    let wc = Workcell::load(&common::calib("workcell.toml")).unwrap();
    let _ = print_replayed(&plan, &common::dofbot(), &wc, &GrindConfig::default());
}

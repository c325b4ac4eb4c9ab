//! The planner's compliance compensation against the simulated cell's arm (issue 50, "compensate
//! what repeats"): `calibrate compliance` fits the `[compliance]` table on the simulator's
//! documented arm (backlash 0.5 degree per joint on the loaded flank, 5 mm of sag at full
//! reach) through the bus; the demo's part is planned with and without that table; every
//! grinding sample's servo command then goes through the simulator's own mechanics
//! (`sim::grind::slack`: its kinematics, flanks and bending, under the arm's weight and the
//! tool's 2 N along the contact normal), less the offset a workcell calibration without force
//! absorbed (the simulator's rule: the gravity-only offset at the pose nearest the part's
//! origin), and lands at a distance from the tip the plan wants. Uncompensated the loaded tip
//! sits 1-2 mm off along the surface (the wrist-pitch gear crossing its band under the contact
//! force, and the sag); compensated it must be much nearer.
mod common;

use nalgebra::{Point3, Vector3};
use polishbot::motion::{plan_part, Plan, PlanConfig, SegmentKind};
use polishbot::robot::{Robot, Workcell};
use polishbot::sim::grind::{fk, slack};
use polishbot::sim::GrindConfig;

/// The compensated tip error's 95th percentile must stay under this, mm (0.5: the plan's
/// Monte Carlo assumed 0.12 mm of tip error; uncompensated the documented arm is 2.2 mm off).
const COMPENSATED_P95_MM: f64 = 0.5;

/// A grinding sample with a joint nearer its limit than this, rad, gets only part of its
/// correction (0.02: the largest correction the model makes on the documented arm is about
/// 0.02 rad).
const NEAR_LIMIT_RAD: f64 = 0.02;

/// The planner's joint angles as the simulator's (through the servo degrees of servos.toml
/// and DOFBOT.md's convention).
fn sim_joints(robot: &Robot, q: &[f64]) -> [f64; 5] {
    std::array::from_fn(|k| {
        let servo = robot.servos.for_joint(&robot.joints[k].name).unwrap();
        fk::joint_of_servo_deg(servo.servo_deg(q[k]))
    })
}

/// The simulated loaded tip's distance from the planned tip at every grinding sample of
/// `plan` (robot frame, mm).
fn tip_errors(plan: &Plan, robot: &Robot, wc: &Workcell, arm: &GrindConfig) -> Vec<f64> {
    let sim = slack::Arm::new(arm);
    let tip = sim.tip_m();
    let sent: Vec<[f64; 5]> = match &plan.commands {
        Some(c) => c.iter().map(|q| sim_joints(robot, q)).collect(),
        None => plan
            .samples
            .iter()
            .map(|s| sim_joints(robot, &s.q))
            .collect(),
    };
    let m = &wc.robot_from_reference;
    let origin = Point3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    let nearest = sent
        .iter()
        .min_by(|a, b| {
            let d = |q: &[f64; 5]| (fk::tool(q, &tip).0 - origin).norm();
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    let absorbed = sim.held(*nearest, Vector3::zeros()).0 - fk::tool(nearest, &tip).0;
    let force = polishbot::removal::ToolModel::of_robot(robot)
        .unwrap()
        .force_n();
    let mut out = Vec::new();
    for seg in &plan.segments {
        let (SegmentKind::Grind, Some(pass)) = (seg.kind, seg.pass) else {
            continue;
        };
        let range = seg.first_sample..=seg.last_sample;
        for (s, q) in plan.samples[range.clone()].iter().zip(&sent[range]) {
            let planned = fk::tool(&sim_joints(robot, &s.q), &tip).0;
            let p = plan.passes[pass]
                .points
                .iter()
                .min_by(|a, b| {
                    let d = |t: &[f64; 3]| (Vector3::from(*t) - planned.coords).norm();
                    d(&a.tip_m).total_cmp(&d(&b.tip_m))
                })
                .unwrap();
            let nrm = wc
                .direction_from_reference(&Vector3::from(p.normal))
                .normalize();
            let loaded = sim.held(*q, nrm * force).0 - absorbed;
            out.push((loaded - planned).norm() * 1e3);
        }
    }
    out
}

/// Grinding samples of `plan` with some joint within `margin` rad of its limit (the planned,
/// loaded joints), and the largest joint difference between a command and its sample, rad.
fn limit_stats(plan: &Plan, robot: &Robot, margin: f64) -> (usize, [usize; 5], f64) {
    let mut any = 0;
    let mut per = [0; 5];
    for seg in &plan.segments {
        if seg.kind != SegmentKind::Grind {
            continue;
        }
        for s in &plan.samples[seg.first_sample..=seg.last_sample] {
            let near: Vec<bool> = robot
                .joints
                .iter()
                .zip(&s.q)
                .map(|(j, q)| q - j.lower < margin || j.upper - q < margin)
                .collect();
            any += usize::from(near.iter().any(|&b| b));
            for (k, b) in near.iter().enumerate().take(5) {
                per[k] += usize::from(*b);
            }
        }
    }
    let most = plan.commands.as_ref().map_or(0.0, |c| {
        c.iter()
            .zip(&plan.samples)
            .flat_map(|(c, s)| c.iter().zip(&s.q).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max)
    });
    (any, per, most)
}

/// Median, 95th percentile and largest of `x`.
fn quantiles(mut x: Vec<f64>) -> [f64; 3] {
    assert!(!x.is_empty(), "no grinding sample");
    x.sort_by(f64::total_cmp);
    let at = |q: f64| x[((x.len() - 1) as f64 * q).round() as usize];
    [at(0.5), at(0.95), x[x.len() - 1]]
}

/// Compensated with the shipped cell's `[compliance]` (the table `calibrate compliance --sim`
/// fitted on the documented arm; `POLISHBOT_COMPENSATION_SERVOS` plans with a servos.toml
/// given by hand instead, to take the fit's error apart from the model's), the simulated
/// loaded tip lands nearer the planned tip than uncompensated (the same cell without the
/// table): median, 95th percentile and largest distance over every grinding sample all
/// smaller, and the 95th percentile under [`COMPENSATED_P95_MM`]. Measured 2026-12-05 (the
/// absorbed offset as the least joint change, joints kept `LIMIT_MARGIN_RAD` from their
/// limits where a tilt allows): median / p95 / max 0.148 / 0.156 / 2.056 mm compensated
/// against 1.463 / 2.173 / 2.225 uncompensated, 385 of 7381 grinding samples partial (the
/// elbow on its lower limit), 359 grinding samples with the elbow within 0.02 rad of its
/// limit (493 without the margin search). Without the compensation (no `commands`) it fails.
#[test]
fn compensation_puts_the_simulated_loaded_tip_nearer_the_planned_contacts() {
    let dir = common::tempdir();
    let inspection = common::synthetic::demo_like(&dir.path().join("inspection"));
    let wc = Workcell::load(&common::calib("workcell.toml")).unwrap();
    let arm = GrindConfig::default();
    let load = || match std::env::var("POLISHBOT_COMPENSATION_SERVOS") {
        Ok(path) => Robot::load(
            &common::calib("dofbot.urdf"),
            &common::calib("tool.toml"),
            std::path::Path::new(&path),
        )
        .unwrap(),
        Err(_) => common::dofbot(),
    };
    let compliant = load();
    println!("[compliance]: {:?}", compliant.servos.compliance);
    let mut rigid = load();
    rigid.servos.compliance = None;
    let cfg = PlanConfig {
        compensate_compliance: true,
        ..PlanConfig::default()
    };
    let plain = plan_part(&inspection, &rigid, &wc, &cfg).expect("plan");
    let compensated = plan_part(&inspection, &compliant, &wc, &cfg).expect("compensated plan");
    assert!(plain.commands.is_none());
    assert!(
        compensated.commands.is_some(),
        "no commands: the corrected commands broke a limit, see the warning"
    );
    let mut near = Vec::new();
    for (name, plan) in [("uncompensated", &plain), ("compensated", &compensated)] {
        for margin in [NEAR_LIMIT_RAD, 0.05] {
            let (any, per, most) = limit_stats(plan, &compliant, margin);
            println!(
                "{name}: grinding samples within {margin} rad of a limit {any} (per joint {per:?}); \
                 largest command offset {most:.4} rad"
            );
            let all = plan
                .segments
                .iter()
                .filter(|s| s.kind == SegmentKind::Grind);
            let samples: usize = all.map(|s| s.last_sample + 1 - s.first_sample).sum();
            if margin == NEAR_LIMIT_RAD {
                near.push(any as f64 / samples as f64);
            }
        }
    }
    // the compensating plan re-tilts strokes to keep room for the correction
    assert!(
        near[1] < near[0],
        "share of grinding samples near a limit {near:?}"
    );
    let before = quantiles(tip_errors(&plain, &rigid, &wc, &arm));
    let after = quantiles(tip_errors(&compensated, &compliant, &wc, &arm));
    println!(
        "loaded tip against the planned tip over the grinding samples, median / p95 / max, \
         mm: uncompensated {before:.3?}, compensated {after:.3?}; {:?}",
        compensated.compensation
    );
    assert!(
        after[1] < COMPENSATED_P95_MM && (0..3).all(|k| after[k] < before[k]),
        "median / p95 / max compensated {after:?} against uncompensated {before:?}"
    );
}

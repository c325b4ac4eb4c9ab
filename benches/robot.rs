//! Robot and trajectory speed: closed-form IK (with the FK check through k) over a 5,000-point
//! raster, time-optimal moves, and sampling + validation of a trajectory.
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use polishbot::motion::{
    validate, JointTrajectory, Limits, Move, TrajectoryConfig, ValidationConfig,
};
use polishbot::robot::{IkConfig, IkTarget, Robot};

fn robot() -> Robot {
    let c = |n: &str| {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("calibration")
            .join(n)
    };
    Robot::load(&c("dofbot.urdf"), &c("tool.toml"), &c("servos.toml")).expect("calibration")
}

/// 5,000 tool poses: a 50 x 100 zig-zag raster (30 x 30 mm) across the tool axis of a pose
/// in front of the arm, tool axis fixed.
fn raster(robot: &Robot) -> Vec<IkTarget> {
    let home = robot.fk(&[0.0, 0.5, 0.9, 0.9, 0.0]);
    let e1 = home.axis.cross(&Vector3::z()).normalize();
    let e2 = home.axis.cross(&e1).normalize();
    let mut out = Vec::with_capacity(5000);
    for row in 0..50 {
        for k in 0..100 {
            let col = if row % 2 == 0 { k } else { 99 - k };
            let p = home.position
                + e1 * (-0.015 + 0.03 * col as f64 / 99.0)
                + e2 * (-0.015 + 0.03 * row as f64 / 49.0);
            out.push(IkTarget {
                position: p,
                axis: home.axis,
                roll: None,
            });
        }
    }
    out
}

fn bench(c: &mut Criterion) {
    let robot = robot();
    let targets = raster(&robot);
    let config = IkConfig::default();
    let solve_all = || {
        let mut prev = vec![0.0, 0.5, 0.9, 0.9, 0.0];
        let mut solved = Vec::with_capacity(targets.len());
        for t in &targets {
            if let Ok(s) = robot.ik(t, &prev, &config) {
                prev.clone_from(&s.q);
                solved.push(s.q);
            }
        }
        solved
    };
    let solved = solve_all();
    assert_eq!(solved.len(), targets.len(), "raster must be reachable");
    c.bench_function("ik_5000_raster_points", |b| b.iter(solve_all));

    let limits = Limits::from_joints(&robot.joints);
    let tc = TrajectoryConfig::default();
    let (a, z) = (&solved[0], &solved[solved.len() - 1]);
    c.bench_function("ruckig_move_5_joints", |b| {
        b.iter(|| Move::new(a, z, &limits, &tc).unwrap().duration())
    });

    // a 5,000-sample trajectory (100 s at 20 ms): rest-to-rest moves through raster rows' ends
    let mut waypoints: Vec<Vec<f64>> = solved.iter().step_by(100).cloned().collect();
    waypoints.extend(solved.iter().skip(99).step_by(100).cloned());
    let build = || {
        let mut traj = JointTrajectory::starting_at(&solved[0], tc.period);
        while traj.len() < 5000 {
            traj.append_moves(&waypoints, &limits, &tc).unwrap();
        }
        traj
    };
    let traj = build();
    c.bench_function("moves_and_sampling_5000_samples", |b| b.iter(build));
    let vc = ValidationConfig::default();
    assert!(validate(&traj, &robot, &vc).is_empty());
    c.bench_function("validate_5000_samples", |b| {
        b.iter(|| validate(&traj, &robot, &vc).len())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);

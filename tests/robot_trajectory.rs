//! Time-optimal trajectories of the robot: Ruckig against the official ruckig (PyPI), and
//! validation of sampled moves against every limit.
mod common;

use polishbot::motion::{
    validate, JointTrajectory, LimitKind, Limits, Move, TrajectoryConfig, ValidationConfig,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use common::{dofbot, random_q};

#[derive(serde::Serialize)]
struct Case {
    from: Vec<f64>,
    to: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    j: Vec<f64>,
}

const RUCKIG_ORACLE: &str = r#"
import json, sys
from ruckig import InputParameter, Ruckig, Trajectory, Result, DurationDiscretization, Synchronization
cases = json.load(open(sys.argv[1]))
period = float(sys.argv[2])
out = []
for c in cases:
    row = []
    for discrete in (False, True):
        n = len(c["from"])
        otg = Ruckig(n, period)
        inp = InputParameter(n)
        inp.current_position = c["from"]
        inp.target_position = c["to"]
        inp.max_velocity = c["v"]
        inp.max_acceleration = c["a"]
        inp.max_jerk = c["j"]
        inp.synchronization = Synchronization.Time
        if discrete:
            inp.duration_discretization = DurationDiscretization.Discrete
        traj = Trajectory(n)
        res = otg.calculate(inp, traj)
        assert res in (Result.Working, Result.Finished), res
        row.append(traj.duration)
    out.append(row)
print(json.dumps(out))
"#;

#[test]
fn move_durations_equal_official_ruckig() {
    let Some(python) = common::oracle_python() else {
        return;
    };
    let robot = dofbot();
    let mut rng = ChaCha8Rng::seed_from_u64(19);
    let cases: Vec<Case> = (0..400)
        .map(|i| {
            let scale = |x: f64, rng: &mut ChaCha8Rng| x * rng.gen_range(0.2..2.0);
            let from = random_q(&robot, &mut rng);
            // every tenth case moves a single joint by a tiny amount (short, jerk-limited moves)
            let to = if i % 10 == 0 {
                let mut t = from.clone();
                t[i % 5] += 1e-3;
                t
            } else {
                random_q(&robot, &mut rng)
            };
            Case {
                v: robot
                    .joints
                    .iter()
                    .map(|j| scale(j.velocity, &mut rng))
                    .collect(),
                a: robot
                    .joints
                    .iter()
                    .map(|j| scale(j.acceleration, &mut rng))
                    .collect(),
                j: robot
                    .joints
                    .iter()
                    .map(|j| scale(j.jerk, &mut rng))
                    .collect(),
                from,
                to,
            }
        })
        .collect();
    let dir = common::tempdir();
    let file = dir.path().join("cases.json");
    std::fs::write(&file, serde_json::to_string(&cases).unwrap()).unwrap();
    let period = 0.02;
    let out = common::run_python(
        &python,
        RUCKIG_ORACLE,
        &[file.to_str().unwrap(), &period.to_string()],
    );
    let oracle: Vec<[f64; 2]> = serde_json::from_str(out.trim()).unwrap();
    let mut worst = 0.0f64;
    for (case, expect) in cases.iter().zip(&oracle) {
        let limits = Limits {
            velocity: case.v.clone(),
            acceleration: case.a.clone(),
            jerk: case.j.clone(),
        };
        for (k, discrete) in [false, true].into_iter().enumerate() {
            let config = TrajectoryConfig {
                period,
                discrete_duration: discrete,
            };
            let mv = Move::new(&case.from, &case.to, &limits, &config).unwrap();
            worst = worst.max((mv.duration() - expect[k]).abs());
        }
    }
    println!(
        "worst duration difference to official ruckig: {worst:.3e} s over {} cases x 2",
        cases.len()
    );
    assert!(worst <= 1e-9, "worst {worst:e} s");
}

#[test]
fn sampled_moves_stay_within_every_limit_and_violations_are_found() {
    let robot = dofbot();
    let limits = Limits::from_joints(&robot.joints);
    let config = TrajectoryConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let waypoints: Vec<Vec<f64>> = (0..20).map(|_| random_q(&robot, &mut rng)).collect();
    let mut traj = JointTrajectory::starting_at(&waypoints[0], config.period);
    traj.append_moves(&waypoints[1..], &limits, &config)
        .unwrap();
    let violations = validate(&traj, &robot, &ValidationConfig::default());
    assert!(violations.is_empty(), "{}", violations[0]);
    // the moves are time-optimal: some joint reaches near its velocity limit
    let h = traj.period;
    let vmax = (1..traj.len())
        .flat_map(|i| (0..5).map(move |j| (i, j)))
        .map(|(i, j)| ((traj.sample(i)[j] - traj.sample(i - 1)[j]) / h).abs())
        .fold(0.0, f64::max);
    assert!(vmax > 0.95 * limits.velocity[0], "peak {vmax}");
    assert!((traj.last().iter().zip(waypoints.last().unwrap())).all(|(a, b)| (a - b).abs() < 1e-12));
    // twice as fast (every other sample) breaks the limits, and validation says where
    let fast = JointTrajectory {
        period: h,
        dof: 5,
        positions: (0..traj.len())
            .step_by(2)
            .flat_map(|i| traj.sample(i).to_vec())
            .collect(),
    };
    let bad = validate(&fast, &robot, &ValidationConfig::default());
    assert!(bad.iter().any(|v| v.kind == LimitKind::Velocity));
    assert!(bad.iter().any(|v| v.kind == LimitKind::Jerk));
    // a position outside the limits is found too
    let mut out = traj.clone();
    out.positions[2] = 2.0;
    assert!(validate(&out, &robot, &ValidationConfig::default())
        .iter()
        .any(|v| v.kind == LimitKind::AboveUpper));
}

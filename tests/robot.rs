//! Robot model and IK: IK against FK through k, the Jacobian fallback, calibration files and
//! the cell held in memory, and servo-resolution error. The time-optimal trajectories (Ruckig
//! against the official ruckig, validation) are in robot_trajectory.rs.
mod common;

use std::path::Path;

use nalgebra::{UnitQuaternion, Vector3};
use polishbot::robot::{
    angle_between, resolution_error, IkConfig, IkTarget, Robot, Unreachable, Workcell,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use common::{calib, dofbot, random_q};

#[test]
fn ik_round_trip_on_10000_random_reachable_poses() {
    let robot = dofbot();
    assert!(
        robot.has_closed_form(),
        "the DOFBOT URDF must take the closed-form IK"
    );
    let config = IkConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut worst_p, mut worst_a) = (0.0f64, 0.0f64);
    for case in 0..10_000 {
        let q = random_q(&robot, &mut rng);
        let pose = robot.fk(&q);
        let previous = random_q(&robot, &mut rng);
        let target = IkTarget {
            position: pose.position,
            axis: pose.axis,
            roll: None,
        };
        let sol = robot
            .ik(&target, &previous, &config)
            .unwrap_or_else(|e| panic!("case {case} q {q:?}: {e}"));
        let back = robot.fk(&sol.q);
        worst_p = worst_p.max((back.position - pose.position).norm());
        worst_a = worst_a.max(angle_between(&back.axis, &pose.axis));
        assert_eq!(
            sol.q[4], previous[4],
            "free roll keeps the previous wrist roll"
        );
        assert!(robot.limit_violation(&sol.q, 0.0).is_none());
    }
    println!("FK(IK) worst: {worst_p:.3e} m, {worst_a:.3e} rad");
    assert!(
        worst_p <= 1e-9 && worst_a <= 1e-9,
        "worst {worst_p:e} m {worst_a:e} rad"
    );
}

#[test]
fn ik_picks_the_branch_nearest_the_previous_pose() {
    let robot = dofbot();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..2_000 {
        let q = random_q(&robot, &mut rng);
        let pose = robot.fk(&q);
        let target = IkTarget {
            position: pose.position,
            axis: pose.axis,
            roll: Some(q[4]),
        };
        let sol = robot
            .ik(&target, &q, &IkConfig::default())
            .expect("reachable");
        let d: f64 = sol
            .q
            .iter()
            .zip(&q)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(
            d < 1e-6,
            "starting at the answer must return it: {q:?} -> {:?}",
            sol.q
        );
    }
}

#[test]
fn off_plane_axis_is_projected_and_the_miss_reported() {
    let robot = dofbot();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..2_000 {
        let q = random_q(&robot, &mut rng);
        let pose = robot.fk(&q);
        let radial = Vector3::new(pose.position.x, pose.position.y, 0.0);
        if radial.norm() < 1e-3 {
            continue;
        }
        let normal = radial.cross(&Vector3::z()).normalize();
        let tilt = rng.gen_range(-40f64..40.0).to_radians();
        let axis = UnitQuaternion::from_axis_angle(
            &nalgebra::Unit::new_normalize(pose.axis.cross(&normal)),
            tilt,
        ) * pose.axis;
        let target = IkTarget {
            position: pose.position,
            axis,
            roll: None,
        };
        let sol = robot
            .ik(&target, &q, &IkConfig::default())
            .expect("within the accepted miss");
        assert!(
            (sol.axis_miss - tilt.abs()).abs() < 1e-9,
            "miss {} vs tilt {}",
            sol.axis_miss,
            tilt.abs()
        );
        let back = robot.fk(&sol.q);
        assert!((back.position - pose.position).norm() < 1e-9);
        assert!(
            angle_between(&back.axis, &pose.axis) < 1e-9,
            "the projection of the tilted axis is the original"
        );
    }
}

#[test]
fn unreachable_poses_say_why() {
    let robot = dofbot();
    let home = vec![0.0; 5];
    let config = IkConfig::default();
    let far = IkTarget {
        position: Vector3::new(0.0, 0.6, 0.1),
        axis: Vector3::y(),
        roll: None,
    };
    assert!(matches!(
        robot.ik(&far, &home, &config),
        Err(Unreachable::OutOfReach { .. })
    ));

    let q = [0.2, 0.5, 0.6, 0.3, 0.0];
    let pose = robot.fk(&q);
    let radial = Vector3::new(pose.position.x, pose.position.y, 0.0).normalize();
    let side = radial.cross(&Vector3::z());
    let axis = (pose.axis.normalize() * 0.5 + side * (60f64.to_radians().tan() * 0.5)).normalize();
    match robot.ik(
        &IkTarget {
            position: pose.position,
            axis,
            roll: None,
        },
        &home,
        &config,
    ) {
        Err(Unreachable::AxisOffPlane { degrees, .. }) => {
            assert!((degrees - 60.0).abs() < 1e-6, "{degrees}")
        }
        other => panic!("expected AxisOffPlane, got {other:?}"),
    }

    // narrow joint 3 to a sliver: a pose made with joint 3 far outside it cannot be reached
    let dir = common::tempdir();
    let servos = std::fs::read_to_string(calib("servos.toml")).unwrap();
    std::fs::write(dir.path().join("servos.toml"), narrow_joint3(&servos)).unwrap();
    let narrow = Robot::load(
        &calib("dofbot.urdf"),
        &calib("tool.toml"),
        &dir.path().join("servos.toml"),
    )
    .unwrap();
    let pose = robot.fk(&[0.1, 0.3, 1.2, 0.4, 0.0]);
    let target = IkTarget {
        position: pose.position,
        axis: pose.axis,
        roll: None,
    };
    let exact = IkConfig {
        axis_search: false,
        ..IkConfig::default()
    };
    match narrow.ik(&target, &home, &exact) {
        Err(Unreachable::JointLimit { joint, .. }) => {
            assert!(joint.starts_with("arm_joint"), "{joint}")
        }
        other => panic!("expected JointLimit, got {other:?}"),
    }
}

#[test]
fn axis_search_tilts_the_tool_in_the_arm_plane_only_as_far_as_needed() {
    let robot = dofbot();
    let exact = IkConfig {
        axis_search: false,
        ..IkConfig::default()
    };
    let search = IkConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(31);
    let (mut found, mut tried) = (0, 0);
    while tried < 300 {
        // a reachable pose, then its axis turned in the arm plane by 10..40 degrees
        let q = random_q(&robot, &mut rng);
        let pose = robot.fk(&q);
        let radial = Vector3::new(pose.position.x, pose.position.y, 0.0);
        if radial.norm() < 1e-3 {
            continue;
        }
        let normal = nalgebra::Unit::new_normalize(radial.cross(&Vector3::z()));
        let turn =
            rng.gen_range(10f64..40.0).to_radians() * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        let axis = UnitQuaternion::from_axis_angle(&normal, turn) * pose.axis;
        let target = IkTarget {
            position: pose.position,
            axis,
            roll: None,
        };
        if robot.ik(&target, &q, &exact).is_ok() {
            continue;
        }
        tried += 1;
        let sol = robot
            .ik(&target, &q, &search)
            .expect("the original axis is within the cone");
        let back = robot.fk(&sol.q);
        assert!((back.position - pose.position).norm() < 1e-9);
        // never worse than the known-feasible original axis (bisection to 1/128 degree)
        assert!(
            sol.axis_miss <= turn.abs() + 1f64.to_radians() / 100.0,
            "{} > {}",
            sol.axis_miss,
            turn.abs()
        );
        assert!((angle_between(&back.axis, &axis) - sol.axis_miss).abs() < 1e-9);
        // and the achieved axis stays in the arm plane
        assert!(back.axis.dot(&normal).abs() < 1e-9);
        found += 1;
    }
    assert_eq!(found, tried);
}

/// servos.toml with joint 3's joint_limits narrowed to [-0.1, 0.1].
fn narrow_joint3(text: &str) -> String {
    let mut out = String::new();
    let mut in3 = false;
    for line in text.lines() {
        if line == "joint = \"arm_joint3\"" {
            in3 = true;
        }
        if in3 && line.starts_with("joint_limits") {
            out.push_str("joint_limits = [-0.1, 0.1]\n");
            in3 = false;
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[test]
fn other_urdfs_fall_back_to_k_jacobian_ik() {
    // Yahboom's own rounding (1.5708) leaves the pitch axes 3.7 urad from parallel: no closed form.
    let text = std::fs::read_to_string(calib("dofbot.urdf"))
        .unwrap()
        .replace("1.5707963267948966", "1.5708");
    let description = urdf_rs::read_from_string(&text).unwrap();
    let tool = polishbot::robot::Tool::load(&calib("tool.toml")).unwrap();
    let servos = polishbot::robot::Servos::load(&calib("servos.toml")).unwrap();
    let robot = Robot::from_parts(
        description,
        Path::new("yahboom.urdf"),
        tool,
        servos,
        &calib("servos.toml"),
    )
    .unwrap();
    assert!(!robot.has_closed_form());
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut solved = 0;
    for _ in 0..50 {
        let q = random_q(&robot, &mut rng);
        let start: Vec<f64> = q.iter().map(|v| v + rng.gen_range(-0.05..0.05)).collect();
        let pose = robot.fk(&q);
        let target = IkTarget {
            position: pose.position,
            axis: pose.axis,
            roll: None,
        };
        if let Ok(sol) = robot.ik(&target, &start, &IkConfig::default()) {
            assert!((robot.fk(&sol.q).position - pose.position).norm() <= 1e-9);
            solved += 1;
        }
    }
    assert!(
        solved >= 40,
        "Jacobian fallback solved only {solved} of 50 nearby poses"
    );
}

#[test]
fn calibration_errors_name_file_and_key() {
    // the shipped files load, and the workcell maps reference millimetres to robot metres
    let (_, cell) = polishbot::robot::load(&polishbot::robot::RobotConfig {
        urdf: calib("dofbot.urdf"),
        tool: calib("tool.toml"),
        servos: calib("servos.toml"),
        workcell: calib("workcell.toml"),
        ..Default::default()
    })
    .unwrap();
    let origin = cell.point_from_reference_mm(&nalgebra::Point3::origin());
    let moved = cell.point_from_reference_mm(&nalgebra::Point3::new(0.0, 0.0, 1000.0));
    assert!(
        ((moved - origin).norm() - 1.0).abs() < 1e-12,
        "1000 mm must map to 1 m"
    );
    let dir = common::tempdir();
    let tool = dir.path().join("tool.toml");
    std::fs::write(
        &tool,
        "joint = \"tool_joint\"\ntip_offset = [0, 0, 0.02]\naxis = [0, 0, 1]\nradius = -1\n",
    )
    .unwrap();
    let err = polishbot::robot::Tool::load(&tool).unwrap_err().to_string();
    println!("{err}");
    assert!(err.contains("tool.toml") && err.contains("radius"), "{err}");

    let servos = dir.path().join("servos.toml");
    let text = std::fs::read_to_string(calib("servos.toml"))
        .unwrap()
        .replacen("velocity = 1.0", "velocity = \"fast\"", 1);
    std::fs::write(&servos, text).unwrap();
    let err = polishbot::robot::Servos::load(&servos)
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(
        err.contains("servos.toml") && err.contains("velocity"),
        "{err}"
    );

    let work = dir.path().join("workcell.toml");
    std::fs::write(
        &work,
        "robot_from_reference = [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n",
    )
    .unwrap();
    let err = Workcell::load(&work).unwrap_err().to_string();
    println!("{err}");
    assert!(
        err.contains("workcell.toml") && err.contains("robot_from_reference"),
        "{err}"
    );
}

#[test]
fn servo_resolution_error_bounds_the_quantised_tip() {
    let robot = dofbot();
    let mut rng = ChaCha8Rng::seed_from_u64(29);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for _ in 0..200 {
        let q = random_q(&robot, &mut rng);
        let bound = resolution_error(&robot, &q);
        (lo, hi) = (lo.min(bound), hi.max(bound));
        let tip = robot.fk(&q).position;
        let half: Vec<f64> = robot
            .joints
            .iter()
            .map(|j| {
                let s = robot
                    .servos
                    .servos
                    .iter()
                    .find(|s| s.id == j.servo_id)
                    .unwrap();
                (0.5 / s.counts_per_degree()).to_radians()
            })
            .collect();
        let mut corner_max = 0.0f64;
        for mask in 0..32u32 {
            let qq: Vec<f64> = q
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    v + if mask >> i & 1 == 1 {
                        half[i]
                    } else {
                        -half[i]
                    }
                })
                .collect();
            corner_max = corner_max.max((robot.fk(&qq).position - tip).norm());
        }
        // linear bound: corner max <= sum |J_i| d_i <= sqrt(5) * corner max (to first order)
        assert!(corner_max <= bound * 1.001, "{corner_max} > {bound}");
        assert!(
            bound <= 5f64.sqrt() * corner_max * 1.001,
            "{bound} vs {corner_max}"
        );
    }
    println!(
        "servo-resolution tip error bound over random poses: {:.3}..{:.3} mm",
        lo * 1e3,
        hi * 1e3
    );
}

#[test]
fn a_cell_held_in_memory_is_the_cell_on_disk_and_names_its_paths() {
    use polishbot::motion::collide::{solids_beside, solids_of};
    use polishbot::robot::{RobotConfig, Turntable};
    // the turntable cell: every file kind, solids.toml and a [turntable] in two files
    let mut cfg = RobotConfig::default();
    cfg.use_cell(&calib("turntable"));
    let mut held = cfg.read_cell().unwrap();
    let roles: Vec<&str> = held.by_role().iter().map(|(r, _)| *r).collect();
    assert_eq!(
        roles,
        [
            "robot description",
            "tool",
            "servo calibration",
            "workcell",
            "solids"
        ]
    );
    // the texts parsed at paths where no file is: what is parsed is what was read once
    let gone = calib("turntable").join("no-such-folder");
    for f in [
        &mut held.urdf,
        &mut held.tool,
        &mut held.servos,
        &mut held.workcell,
    ] {
        f.path = gone.join(f.path.file_name().unwrap());
    }
    let solids = held.solids.as_mut().unwrap();
    solids.path = gone.join("solids.toml");
    let robot = held.robot().unwrap();
    let on_disk = Robot::load(&cfg.urdf, &cfg.tool, &cfg.servos).unwrap();
    assert_eq!(robot.joints, on_disk.joints);
    assert_eq!(robot.tool, on_disk.tool);
    assert_eq!(
        held.workcell().unwrap(),
        Workcell::load(&cfg.workcell).unwrap()
    );
    let table = held.turntable().unwrap();
    assert!(table.is_some());
    assert_eq!(table, Turntable::load(&cfg.servos, &cfg.workcell).unwrap());
    assert_eq!(
        solids_of(held.solids.as_ref()).unwrap(),
        solids_beside(&cfg.workcell).unwrap()
    );
    // a bad value in a held file is named by the held path and the key or line
    let mut bad = held.clone();
    bad.servos.text = bad
        .servos
        .text
        .replacen("velocity = 1.0", "velocity = \"fast\"", 1);
    let err = bad.robot().unwrap_err().to_string();
    assert!(
        err.contains(&bad.servos.path.display().to_string()) && err.contains("velocity"),
        "{err}"
    );
    let mut bad = held.clone();
    bad.urdf.text = bad.urdf.text.replacen("<robot", "<robt", 1);
    let err = bad.robot().unwrap_err().to_string();
    assert!(err.contains(&bad.urdf.path.display().to_string()), "{err}");
    let mut bad = held.clone();
    bad.solids.as_mut().unwrap().text +=
        "\n[[solid]]\nname = \"flat\"\nmin = [0, 0, 0]\nmax = [1, 1, 0]\n";
    let err = solids_of(bad.solids.as_ref()).unwrap_err().to_string();
    assert!(
        err.contains("no-such-folder/solids.toml") && err.contains("flat"),
        "{err}"
    );
}

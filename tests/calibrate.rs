//! Calibration routines against planted truth: the simulated arm and the Python mock carry
//! hidden servo mounting offsets, read-back noise, a hidden tool tip and a hidden workcell;
//! this harness computes the joint poses that put the true tool tip on the pivot point and on
//! the fiducials (the operator's jogging) and the routines must recover the truth.
#[path = "calibrate/cli.rs"]
mod cli;
mod common;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nalgebra::{Matrix4, Point3, Rotation3, Vector3};
use polishbot::bus::{Bus, BusConfig, Journal, ServoMap};
use polishbot::calibrate::jog::Cell;
use polishbot::calibrate::{self, files, CalibrationConfig, Fiducial, Fixture, Scripted};
use polishbot::motion::frames;
use polishbot::robot::{self, Robot, RobotConfig, Servos, Tool, Workcell};
use polishbot::sim::model::raw_at_deg;
use polishbot::sim::{Mechanics, SimArm, SimOptions};

/// Hidden mounting offsets of servos 1..6, degrees.
const OFFSETS: [f64; 6] = [6.5, -7.8, 3.2, -5.1, 7.9, 0.0];
/// Hidden tool tip in the flange frame, metres (the files say 0, 0, 0.0193).
const TRUE_TIP: [f64; 3] = [0.0007, -0.0005, 0.0262];
/// The pivot point, robot frame, metres: high and near the base axis, where the tool can
/// reach it tilted either way by about 40 deg (the DOFBOT's long tool leaves little tilt
/// range elsewhere).
const PIVOT: [f64; 3] = [0.0, 0.02, 0.37];

fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration")
        .join(name)
}

/// Hidden workcell: robot_from_reference, metres.
fn true_workcell() -> Matrix4<f64> {
    let r = Rotation3::from_euler_angles(0.06, -0.04, 0.35);
    let mut m = r.to_homogeneous();
    m.fixed_slice_mut::<3, 1>(0, 3)
        .copy_from(&Vector3::new(0.03, 0.27, 0.05));
    m
}

/// Five fiducials spanning a tilted plate, mm, reference frame.
fn fixture() -> Fixture {
    let pts = [
        ("A", [-40.0, -30.0, 0.0]),
        ("B", [40.0, -30.0, 0.0]),
        ("C", [40.0, 30.0, 6.0]),
        ("D", [-40.0, 30.0, 12.0]),
        ("E", [0.0, 0.0, 25.0]),
    ];
    Fixture {
        fiducials: pts
            .iter()
            .map(|(n, p)| Fiducial {
                name: n.to_string(),
                position: *p,
            })
            .collect(),
    }
}

fn fixture_toml(f: &Fixture) -> String {
    let mut s = String::from("# test fixture\n");
    for fid in &f.fiducials {
        let p = fid.position;
        s.push_str(&format!(
            "[[fiducial]]\nname = \"{}\"\nposition = [{:?}, {:?}, {:?}]\n",
            fid.name, p[0], p[1], p[2]
        ));
    }
    s
}

/// The true arm: the shipped URDF with the hidden tool tip.
fn true_robot() -> Robot {
    let urdf = shipped("dofbot.urdf");
    let description = urdf_rs::read_file(&urdf).unwrap();
    let tool = Tool {
        tip_offset: TRUE_TIP,
        ..Tool::load(&shipped("tool.toml")).unwrap()
    };
    let servos = Servos::load(&shipped("servos.toml")).unwrap();
    Robot::from_parts(description, &urdf, tool, servos, &shipped("servos.toml")).unwrap()
}

/// Physical joints (rad) putting `robot`'s tool tip on `target`, nearest to `want`: Newton
/// steps on the joints `free` (the others stay at `want`) through the pseudo-inverse of the
/// numeric position Jacobian, with a null-space pull toward `want`.
fn touch_pose(robot: &Robot, target: Vector3<f64>, want: [f64; 5], free: &[usize]) -> [f64; 5] {
    let mut q = want;
    for _ in 0..400 {
        let f = target - robot.fk(&q).position;
        let mut j = nalgebra::SMatrix::<f64, 3, 5>::zeros();
        for &c in free {
            let (mut a, mut b) = (q, q);
            a[c] += 1e-6;
            b[c] -= 1e-6;
            j.set_column(c, &((robot.fk(&a).position - robot.fk(&b).position) / 2e-6));
        }
        let jp = j.pseudo_inverse(1e-12).unwrap();
        let null = nalgebra::SMatrix::<f64, 5, 5>::identity() - jp * j;
        let pull = nalgebra::SVector::<f64, 5>::from(want) - nalgebra::SVector::from(q);
        let mut dq = jp * f + null * pull * 0.3;
        if dq.norm() > 0.2 {
            dq *= 0.2 / dq.norm();
        }
        for c in 0..5 {
            q[c] += dq[c];
        }
    }
    let miss = (robot.fk(&q).position - target).norm();
    assert!(
        miss < 1e-9 && robot.limit_violation(&q, -0.03).is_none(),
        "no pose reaches {target:?} near {want:?}: {q:?} misses by {miss}"
    );
    q
}

/// The joint command that puts the arm at physical joints `q` (as the operator's jog ends):
/// each servo at the raw count nearest to physical + hidden offset, read through `map`.
fn command_for(map: &ServoMap, q: &[f64; 5]) -> [f64; 5] {
    std::array::from_fn(|i| {
        let raw = raw_at_deg(i, 90.0 + q[i].to_degrees() + OFFSETS[i]).round() as u16;
        map.joint_from_raw(i, raw).unwrap()
    })
}

/// Joints near which the pivot touches are found: yaw, tilt and roll spread.
const PIVOT_WANTS: [[f64; 5]; 8] = [
    [0.0, 0.6, 0.6, 0.6, 0.0],
    [0.0, 0.6, 0.6, 0.6, 1.5],
    [0.0, -0.6, -0.6, -0.6, 2.0],
    [0.0, 1.0, 0.3, -0.3, -1.0],
    [0.0, 0.2, 0.8, 0.9, 0.5],
    [0.0, -0.2, -0.8, -0.9, 2.8],
    [0.0, 0.5, 0.5, 0.2, -1.4],
    [0.0, -0.4, -0.7, -0.4, 0.7],
];

fn pivot_targets(map: &ServoMap) -> Vec<[f64; 5]> {
    let truth = true_robot();
    PIVOT_WANTS
        .iter()
        .map(|want| {
            command_for(
                map,
                &touch_pose(&truth, Vector3::from(PIVOT), *want, &[0, 1, 2, 3]),
            )
        })
        .collect()
}

fn fiducial_targets(map: &ServoMap, fixture: &Fixture) -> Vec<[f64; 5]> {
    let truth = true_robot();
    let w = true_workcell();
    fixture
        .fiducials
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let p = w.transform_point(&Point3::from(Vector3::from(f.position) * 1e-3));
            let yaw = p.x.atan2(p.y);
            let want = [yaw, -0.5, -0.5, -0.9, 0.3 * k as f64];
            command_for(map, &touch_pose(&truth, p.coords, want, &[0, 1, 2, 3]))
        })
        .collect()
}

fn targets_text(t: &[[f64; 5]]) -> String {
    let mut s = String::from("# joint targets, rad\n");
    for q in t {
        let v: Vec<String> = q.iter().map(|x| format!("{x:?}")).collect();
        s.push_str(&v.join(", "));
        s.push('\n');
    }
    s
}

fn mechanics(noise: u16) -> Mechanics {
    Mechanics {
        mount_offset_deg: OFFSETS,
        read_noise_counts: noise,
        noise_seed: 17,
        start_physical_deg: Some([90.0; 6]),
    }
}

fn robot_from(tool: &Path, servos: &Path) -> Robot {
    Robot::load(&shipped("dofbot.urdf"), tool, servos).unwrap()
}

fn bus_for(arm: &SimArm, robot: &Robot) -> Bus<polishbot::sim::SimTransport> {
    let cfg = BusConfig {
        servo_map: frames::servo_map(robot).unwrap(),
        ..BusConfig::default()
    };
    Bus::connect(arm.transport(), cfg, Journal::none()).unwrap()
}

fn rotation_angle_deg(a: &Matrix4<f64>, b: &Matrix4<f64>) -> f64 {
    let ra = a.fixed_slice::<3, 3>(0, 0).into_owned();
    let rb = b.fixed_slice::<3, 3>(0, 0).into_owned();
    let r = Rotation3::from_matrix_unchecked(ra.transpose() * rb);
    r.angle().to_degrees()
}

fn translation_error_mm(a: &Matrix4<f64>, b: &Matrix4<f64>) -> f64 {
    (a.fixed_slice::<3, 1>(0, 3) - b.fixed_slice::<3, 1>(0, 3)).norm() * 1000.0
}

#[test]
fn sim_chain_recovers_planted_offsets_tool_and_workcell_and_files_round_trip() {
    let dir = common::tempdir();
    let cfg = CalibrationConfig::default();
    let nominal = robot_from(&shipped("tool.toml"), &shipped("servos.toml"));
    let options = SimOptions {
        mechanics: mechanics(1),
        ..SimOptions::default()
    };
    let arm = SimArm::new(&options, &frames::servo_map(&nominal).unwrap()).unwrap();

    // 1. Servos: the arm is held at the physical zero pose.
    let (servos_file, zero) = servo_offsets_recovered(&arm, &nominal, &cfg, dir.path());

    // 2. Tool: pivot touches computed on the true arm, commanded through the new servo map.
    let robot = robot_from(&shipped("tool.toml"), &servos_file);
    let map = frames::servo_map(&robot).unwrap();
    for (i, j) in map.joints.iter().enumerate() {
        assert_eq!(
            j.zero_deg, zero[i].1,
            "run's servo map reads the new offsets"
        );
    }
    let mut bus = bus_for(&arm, &robot);
    let cell = Cell {
        robot: &robot,
        map: &map,
        gripper_deg: 90.0,
        cfg: &cfg,
    };
    let mut src = Scripted::new(pivot_targets(&map));
    let fit = calibrate::tool_tip(&mut bus, &cell, &mut src).unwrap();
    let tip_err = (Vector3::from(fit.tip_offset) - Vector3::from(TRUE_TIP)).norm() * 1000.0;
    let pivot_err = (Vector3::from(fit.pivot) - Vector3::from(PIVOT)).norm() * 1000.0;
    eprintln!(
        "tool: tip error {tip_err:.3} mm, pivot error {pivot_err:.3} mm, RMS {:.3} mm, spread {:.1} deg",
        fit.rms_mm, fit.spread_deg
    );
    assert!(tip_err < 0.5, "tool tip off by {tip_err} mm");
    assert_eq!(fit.residuals_mm.len(), PIVOT_WANTS.len());
    let tool_file = dir.path().join("tool.toml");
    let tool = files::write_tool(&shipped("tool.toml"), &tool_file, fit.tip_offset).unwrap();
    assert_eq!(tool.tip_offset, fit.tip_offset);

    // 3. Workcell.
    let robot = robot_from(&tool_file, &servos_file);
    let cell = Cell {
        robot: &robot,
        ..cell
    };
    let fix = fixture();
    let mut src = Scripted::new(fiducial_targets(&map, &fix));
    let fit = calibrate::workcell(&mut bus, &cell, &fix, &mut src).unwrap();
    let t_err = translation_error_mm(&fit.robot_from_reference, &true_workcell());
    let r_err = rotation_angle_deg(&fit.robot_from_reference, &true_workcell());
    eprintln!(
        "workcell: translation error {t_err:.3} mm, rotation error {r_err:.4} deg, RMS {:.3} mm, residuals {:?}",
        fit.rms_mm, fit.residuals_mm
    );
    assert!(t_err < 1.0 && r_err < 0.5);
    assert_eq!(fit.residuals_mm.len(), 5);
    let workcell_file = dir.path().join("workcell.toml");
    files::write_workcell(&workcell_file, &fit.robot_from_reference, "test").unwrap();

    // What `plan` and `run` load: robot::load and frames::servo_map on the written files.
    let (loaded, w) = robot::load(&RobotConfig {
        tool: tool_file.clone(),
        servos: servos_file.clone(),
        workcell: workcell_file.clone(),
        ..RobotConfig::default()
    })
    .unwrap();
    assert_eq!(w.robot_from_reference, fit.robot_from_reference);
    assert_eq!(loaded.tool.tip_offset, tool.tip_offset);
    assert_eq!(frames::servo_map(&loaded).unwrap(), map);

    // 4. Verify: default poses and the fiducials against the written workcell.
    let cell = Cell {
        robot: &loaded,
        ..cell
    };
    verify_puts_the_arm_where_the_files_say(&mut bus, &cell, &map, &fix, &w, &arm);
}

/// Servos: the arm (`nominal`'s servo map) held at the physical zero pose; every recovered
/// zero offset within 0.2 degrees of the planted one, written into `dir`'s servos.toml with
/// the shipped file's comments. Returns that file and the offsets (servo id, degrees).
fn servo_offsets_recovered(
    arm: &SimArm,
    nominal: &Robot,
    cfg: &CalibrationConfig,
    dir: &Path,
) -> (PathBuf, Vec<(u8, f64)>) {
    let mut bus = bus_for(arm, nominal);
    let map = frames::servo_map(nominal).unwrap();
    let r = calibrate::servo_offsets(&mut bus, &map, cfg, &mut || Ok(()), false).unwrap();
    for s in &r.servos {
        let err = s.zero_offset_deg - (90.0 + OFFSETS[s.id as usize - 1]);
        eprintln!("servo {}: offset error {err:+.4} deg", s.id);
        assert!(err.abs() < 0.2, "servo {}: {err} deg", s.id);
    }
    let servos_file = dir.join("servos.toml");
    let zero: Vec<(u8, f64)> = r.servos.iter().map(|s| (s.id, s.zero_offset_deg)).collect();
    files::write_servos(&shipped("servos.toml"), &servos_file, &zero).unwrap();
    let text = std::fs::read_to_string(&servos_file).unwrap();
    assert!(text.contains("# DOFBOT bus servos"), "comments kept");
    (servos_file, zero)
}

/// Verify with the calibrated `cell`: the default poses, and the fiducials of `fix` against
/// the written workcell `w`; and the arm really is where the calibrated model says (its
/// physical joints from the hidden truth).
fn verify_puts_the_arm_where_the_files_say(
    bus: &mut Bus<polishbot::sim::SimTransport>,
    cell: &Cell,
    map: &ServoMap,
    fix: &Fixture,
    w: &Workcell,
    arm: &SimArm,
) {
    let report =
        calibrate::verify(bus, cell, &calibrate::verify::DEFAULT_CHECK_POSES, None).unwrap();
    assert!(report.ok, "{report:?}");
    let per_count = 180.0 / 2200.0;
    for e in report.max_servo_error_deg {
        assert!(
            e <= per_count * 1.01,
            "servo error {e} deg beyond the noise"
        );
    }
    let poses = fiducial_targets(map, fix);
    let report = calibrate::verify(bus, cell, &poses, Some((fix, w))).unwrap();
    eprintln!("verify: fiducials {:?} mm", report.max_fiducial_error_mm);
    assert!(report.ok && report.max_fiducial_error_mm.unwrap() < 1.0);
    // The arm really is where the calibrated model says: physical joints from the hidden truth.
    let phys = arm.physical_deg();
    let last = poses.last().unwrap();
    for i in 0..5 {
        let want = 90.0 + last[i].to_degrees();
        assert!(
            (phys[i] - want).abs() < 0.25,
            "joint {}: {} vs {want}",
            i + 1,
            phys[i]
        );
    }
}

fn cell_run<F>(f: F)
where
    F: FnOnce(&mut Bus<polishbot::sim::SimTransport>, &Cell),
{
    let robot = robot_from(&shipped("tool.toml"), &shipped("servos.toml"));
    let map = frames::servo_map(&robot).unwrap();
    let cfg = CalibrationConfig::default();
    let arm = SimArm::new(&SimOptions::default(), &map).unwrap();
    let mut bus = bus_for(&arm, &robot);
    let cell = Cell {
        robot: &robot,
        map: &map,
        gripper_deg: 90.0,
        cfg: &cfg,
    };
    f(&mut bus, &cell)
}

#[test]
fn degenerate_input_is_refused_with_a_clear_message() {
    let cfg = CalibrationConfig::default();
    // Fewer than four fiducials.
    let mut few = fixture();
    few.fiducials.truncate(3);
    let e = calibrate::workcell::check_fixture(&few, &cfg).unwrap_err();
    assert!(
        e.to_string().contains("3 fiducials, need at least 4"),
        "{e}"
    );
    // Collinear fiducials.
    let mut line = fixture();
    for (k, f) in line.fiducials.iter_mut().enumerate() {
        f.position = [10.0 * k as f64, 5.0 * k as f64, 0.01 * (k % 2) as f64];
    }
    let e = calibrate::workcell::check_fixture(&line, &cfg).unwrap_err();
    assert!(e.to_string().contains("collinear"), "{e}");
    // No motion happens for a bad fixture.
    cell_run(|bus, cell| {
        let mut src = Scripted::new(vec![[0.3, 0.0, 0.0, 0.0, 0.0]; 5]);
        assert!(calibrate::workcell(bus, cell, &line, &mut src).is_err());
        let home = cell.map.home_raw(90.0).unwrap();
        // Within the simulated arm's documented read-back noise (one count); any move the
        // routine made would show as many counts.
        let read = bus.read_pose_raw().unwrap();
        assert!(
            read.iter().zip(&home).all(|(r, h)| r.abs_diff(*h) <= 1),
            "nothing moved: read {read:?}, home {home:?}"
        );
    });
    // Pivot poses too similar: the same wrist pose, rolled by a degree.
    let truth = true_robot();
    let similar: Vec<[f64; 5]> = (0..5)
        .map(|k| {
            let want = [0.0, 0.6, 0.6, 0.6, 0.5 + 0.017 * k as f64];
            touch_pose(&truth, Vector3::from(PIVOT), want, &[0, 1, 2, 3])
        })
        .collect();
    cell_run(|bus, cell| {
        let mut src = Scripted::new(similar);
        let e = calibrate::tool_tip(bus, cell, &mut src).unwrap_err();
        assert!(e.to_string().starts_with("pivot poses too similar"), "{e}");
    });
    // Too few pivot touches.
    cell_run(|bus, cell| {
        let mut src = Scripted::new(vec![[0.1, 0.2, 0.3, 0.0, 0.0]; 3]);
        let e = calibrate::tool_tip(bus, cell, &mut src).unwrap_err();
        assert!(e.to_string().contains("3 touches, need at least 4"), "{e}");
    });
    // Touches that do not share a point: refused on the residual.
    cell_run(|bus, cell| {
        let mut src = Scripted::new(vec![
            [0.0, 0.2, 0.3, 0.4, 0.0],
            [0.3, -0.2, 0.5, -0.4, 1.0],
            [-0.3, 0.4, 0.1, 0.6, -1.0],
            [0.2, 0.1, -0.3, 0.9, 2.0],
        ]);
        let e = calibrate::tool_tip(bus, cell, &mut src).unwrap_err();
        assert!(e.to_string().contains("RMS residual"), "{e}");
    });
}

/// The servo routine on a simulated arm held at the zero pose with the hidden offsets and
/// `noise` counts of read noise.
fn servo_run(
    noise: u16,
    store_mid: bool,
) -> (
    SimArm,
    Result<calibrate::ServoOffsets, calibrate::CalibError>,
) {
    let robot = robot_from(&shipped("tool.toml"), &shipped("servos.toml"));
    let map = frames::servo_map(&robot).unwrap();
    let options = SimOptions {
        mechanics: mechanics(noise),
        ..SimOptions::default()
    };
    let arm = SimArm::new(&options, &map).unwrap();
    let mut bus = bus_for(&arm, &robot);
    let cfg = CalibrationConfig::default();
    let r = calibrate::servo_offsets(&mut bus, &map, &cfg, &mut || Ok(()), store_mid);
    (arm, r)
}

#[test]
fn servo_reads_that_spread_are_refused_and_a_silent_servo_is_named() {
    let e = servo_run(3, false).1.unwrap_err();
    assert!(e.to_string().contains("reads spread"), "{e}");

    // Through the CLI: a servo that does not answer.
    let dir = common::tempdir();
    let config = dir.path().join("cfg.toml");
    std::fs::write(&config, "[sim.faults]\nabsent_servo = 3\n").unwrap();
    let out = common::polishbot()
        .args(["calibrate", "servos", "--sim", "--assume-pose", "--out"])
        .arg(dir.path())
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(
        stderr.contains("calibrate servos: servo 3 not answering"),
        "{stderr}"
    );
    assert!(!dir.path().join("servos.toml").exists());
}

#[test]
fn store_mid_sends_0x1c_per_joint_servo_and_checks_the_offset_state() {
    let (arm, r) = servo_run(1, true);
    assert!(r.unwrap().stored_mid);
    let got = arm.received();
    let stores: Vec<u8> = got
        .iter()
        .filter(|f| f.func == 0x1C)
        .map(|f| f.payload[0])
        .collect();
    assert_eq!(stores, vec![1, 2, 3, 4, 5]);
    assert_eq!(got.iter().filter(|f| f.func == 0x1B).count(), 5);
}

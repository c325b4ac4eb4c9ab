//! The DOFBOT bus end to end: the arm CLI and the driver against the Python mock board on a
//! pseudo-terminal (faults injected), the in-process simulator against the mock, resume from
//! the journal, and the range guarantee of the public API.
mod common;

use common::{raw_array, read_journal, Mock};

use std::path::Path;
use std::time::Duration;

use polishbot::bus::{
    Bus, BusConfig, BusError, Entry, EntryKind, Journal, ResumePoint, SerialTransport, ServoMap,
    JOINT_COUNT,
};
use polishbot::sim::{Faults, SimArm, SimOptions};
use proptest::prelude::*;

const Q: [f64; JOINT_COUNT] = [0.5, -0.3, 0.2, 0.1, 1.0];

#[test]
fn cli_move_then_read_over_pty_returns_the_commanded_joints() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let mock = Mock::start(&py, &[]);
    let dir = common::tempdir();
    let journal = dir.path().join("journal.jsonl");
    let joints = Q.map(|q| q.to_string()).join(",");
    common::succeed(
        common::polishbot()
            .args([
                "arm",
                "move",
                "--port",
                &mock.path,
                "--joints",
                &joints,
                "--gripper",
                "30",
                "--time",
                "1.2",
            ])
            .arg("--journal")
            .arg(&journal),
    );
    let out = common::succeed(common::polishbot().args(["arm", "read", "--port", &mock.path]));
    let read: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let map = ServoMap::default();
    let want = map.pose_raw(&Q, 30.0).unwrap();
    let got = raw_array(&read["raw"]);
    for i in 0..6 {
        assert!(
            got[i].abs_diff(want[i]) <= 1,
            "servo {}: {} vs {}",
            i + 1,
            got[i],
            want[i]
        );
    }
    for (i, q) in Q.iter().enumerate() {
        let per_count = 1.0 / map.joints[i].servo_scale().unwrap().counts_per_deg();
        let got_q = read["joints"][i].as_f64().unwrap();
        assert!(
            (got_q - q).abs() <= per_count.to_radians(),
            "joint {}: {got_q} vs {q}",
            i + 1
        );
    }
    // The journal holds the 0x1D frame exactly as the mock logged it.
    let entries = read_journal(&journal);
    let tx = entries
        .iter()
        .find(|e| e.motion == Some(0))
        .expect("motion frame journalled");
    let (state, logged) = mock.finish_logged();
    assert!(logged
        .iter()
        .any(|l| l["frame"].as_str() == tx.frame.as_deref()));
    assert!(entries.iter().any(|e| e.kind == EntryKind::Verified));
    assert_eq!(raw_array(&state["positions"]), got);
}

/// Runs `arm move` against a mock with `fault` flags; returns (stderr, journal entries).
fn cli_fault(py: &Path, fault: &[&str]) -> (String, Vec<Entry>) {
    let mock = Mock::start(py, fault);
    let dir = common::tempdir();
    let journal = dir.path().join("journal.jsonl");
    let out = common::polishbot()
        .args([
            "arm",
            "move",
            "--port",
            &mock.path,
            "--joints",
            "0.2,0.1,0,0,0",
            "--gripper",
            "90",
        ])
        .arg("--journal")
        .arg(&journal)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "fault {fault:?} went undetected");
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "not one line: {stderr}"
    );
    (stderr, read_journal(&journal))
}

#[test]
fn every_injected_fault_is_a_typed_one_line_error_and_the_journal_stays_consistent() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let cases: [(&[&str], &str, &str); 7] = [
        (&["--corrupt-every", "1"], "bad checksum", "bad_checksum"),
        (&["--drop-every", "1"], "timeout", "timeout"),
        (&["--delay-ms", "200"], "timeout", "timeout"),
        (
            &["--fail-read-servo", "3"],
            "read failure: servo 3",
            "read_failure",
        ),
        (&["--disconnect-after", "9"], "port lost", "port_lost"),
        (
            &["--stall-servo", "2"],
            "read-back mismatch: servo 2",
            "read_back_mismatch",
        ),
        (
            &["--absent-servo", "4"],
            "servo 4 not answering",
            "not_answering",
        ),
    ];
    for (flags, message, code) in cases {
        let (stderr, journal) = cli_fault(&py, flags);
        assert!(
            stderr.starts_with("polishbot: ") && stderr.contains(message),
            "{flags:?}: {stderr}"
        );
        assert!(
            journal.iter().any(|e| e.code.as_deref() == Some(code)),
            "{flags:?}: no {code} line in the journal"
        );
        // No motion is journalled as verified after a fault, and the read-back faults stop motion.
        assert!(
            journal.iter().all(|e| e.kind != EntryKind::Verified),
            "{flags:?}"
        );
    }
}

#[test]
fn intermittent_faults_are_retried_and_journalled() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let mock = Mock::start(
        &py,
        &[
            "--fail-read-every",
            "4",
            "--corrupt-every",
            "5",
            "--drop-every",
            "7",
        ],
    );
    let dir = common::tempdir();
    let journal = dir.path().join("journal.jsonl");
    let link = SerialTransport::open(&mock.path).unwrap();
    let mut bus = Bus::connect(
        link,
        BusConfig::default(),
        Journal::append(&journal).unwrap(),
    )
    .unwrap();
    let state = bus.move_joints(&Q, 45.0, None).unwrap();
    assert_eq!(state.raw, ServoMap::default().pose_raw(&Q, 45.0).unwrap());
    drop(bus);
    let entries = read_journal(&journal);
    for code in ["read_failure", "bad_checksum", "timeout"] {
        assert!(
            entries.iter().any(|e| e.code.as_deref() == Some(code)),
            "no retried {code}"
        );
    }
}

/// A sequence of motion frames: joint poses along a wave, 80 ms each.
fn plan() -> Vec<[u16; 6]> {
    let map = ServoMap::default();
    (0..12)
        .map(|k| {
            let s = k as f64 / 11.0;
            let q = [
                0.8 * s,
                -0.5 * s,
                0.6 * (s * 3.0).sin(),
                0.3 - 0.6 * s,
                2.0 * s,
            ];
            map.pose_raw(&q, 20.0 + 100.0 * s).unwrap()
        })
        .collect()
}

fn send_from(bus: &mut Bus<SerialTransport>, from: u64) -> Result<(), BusError> {
    for (i, raw) in plan().iter().enumerate().skip(from as usize) {
        bus.send_motion(i as u64, dofbot_protocol::Pose::new(*raw).unwrap(), 80)?;
    }
    Ok(())
}

#[test]
fn resume_after_disconnect_reaches_the_uninterrupted_final_pose() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let dir = common::tempdir();
    let cfg = BusConfig {
        frame_gap_ms: 20.0,
        ..BusConfig::default()
    };

    let whole = Mock::start(&py, &[]);
    let mut bus = Bus::connect(
        SerialTransport::open(&whole.path).unwrap(),
        cfg.clone(),
        Journal::none(),
    )
    .unwrap();
    send_from(&mut bus, 0).unwrap();
    bus.sleep(Duration::from_millis(800));
    drop(bus);
    let uninterrupted = whole.finish();

    // 6 pings at connect, then the link dies after the 7th motion frame arrives.
    let journal = dir.path().join("journal.jsonl");
    let broken = Mock::start(&py, &["--disconnect-after", "13"]);
    let mut bus = Bus::connect(
        SerialTransport::open(&broken.path).unwrap(),
        cfg.clone(),
        Journal::append(&journal).unwrap(),
    )
    .unwrap();
    let err = send_from(&mut bus, 0).unwrap_err();
    assert_eq!(err.code(), "port_lost", "{err}");
    drop(bus);
    std::thread::sleep(Duration::from_millis(300));
    let at_break = broken.finish();
    assert_eq!(at_break["disconnected"], true);

    let rp = ResumePoint::from_journal(&journal).unwrap();
    assert!(rp.last_sent.is_some() && rp.resume_from() < plan().len() as u64 - 1);
    assert_eq!(
        rp.last_error.as_ref().map(|e| e.0.as_str()),
        Some("port_lost")
    );

    // The arm stays where it stopped: the next mock starts from the broken one's positions.
    let initial = raw_array(&at_break["positions"])
        .map(|r| r.to_string())
        .join(",");
    let resumed = Mock::start(&py, &["--initial", &initial]);
    let mut bus = Bus::connect(
        SerialTransport::open(&resumed.path).unwrap(),
        cfg,
        Journal::append(&journal).unwrap(),
    )
    .unwrap();
    send_from(&mut bus, rp.resume_from()).unwrap();
    bus.sleep(Duration::from_millis(800));
    drop(bus);
    let after = resumed.finish();
    assert_eq!(
        raw_array(&after["positions"]),
        raw_array(&uninterrupted["positions"])
    );
    assert_eq!(raw_array(&after["positions"]), *plan().last().unwrap());
    let rp = ResumePoint::from_journal(&journal).unwrap();
    assert_eq!(rp.last_sent, Some(plan().len() as u64 - 1));
}

#[test]
fn sim_and_mock_agree_on_moves_and_reads() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let mock = Mock::start(&py, &[]);
    let mut real = Bus::connect(
        SerialTransport::open(&mock.path).unwrap(),
        BusConfig::default(),
        Journal::none(),
    )
    .unwrap();
    let cfg = BusConfig::default();
    // The mock reads back exactly what it was sent; the simulated arm's documented read-back
    // noise (one count by default) is switched off so the two can be compared byte for byte.
    let mut options = SimOptions::default();
    options.mechanics.read_noise_counts = 0;
    let arm = SimArm::new(&options, &cfg.servo_map).unwrap();
    let mut sim = Bus::connect(arm.transport(), cfg, Journal::none()).unwrap();
    assert_eq!(real.read_joints().unwrap(), sim.read_joints().unwrap());
    assert_eq!(real.version().unwrap(), sim.version().unwrap());
    for q in [Q, [-0.7, 0.4, -1.2, 1.5, -1.5], [0.0; 5]] {
        let a = real.move_joints(&q, 10.0, None).unwrap();
        let b = sim.move_joints(&q, 10.0, None).unwrap();
        assert_eq!(a, b);
    }
    assert_eq!(
        arm.positions(),
        mock.finish()["positions"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as u16)
            .collect::<Vec<_>>()
            .as_slice()
    );
}

#[test]
fn sim_faults_match_the_mock_error_kinds() {
    let cases: [(Faults, &str); 6] = [
        (
            Faults {
                corrupt_every: 1,
                ..Faults::default()
            },
            "bad_checksum",
        ),
        (
            Faults {
                drop_every: 1,
                ..Faults::default()
            },
            "timeout",
        ),
        (
            Faults {
                fail_read_servo: Some(3),
                ..Faults::default()
            },
            "read_failure",
        ),
        (
            Faults {
                disconnect_after: Some(9),
                ..Faults::default()
            },
            "port_lost",
        ),
        (
            Faults {
                stall_servo: Some(2),
                ..Faults::default()
            },
            "read_back_mismatch",
        ),
        (
            Faults {
                absent_servo: Some(4),
                ..Faults::default()
            },
            "not_answering",
        ),
    ];
    for (faults, code) in cases {
        let cfg = BusConfig::default();
        let arm = SimArm::new(
            &SimOptions {
                faults: faults.clone(),
                ..SimOptions::default()
            },
            &cfg.servo_map,
        )
        .unwrap();
        let err = Bus::connect(arm.transport(), cfg, Journal::none())
            .and_then(|mut b| b.move_joints(&Q, 90.0, None))
            .unwrap_err();
        assert_eq!(err.code(), code, "{faults:?}: {err}");
    }
}

#[test]
fn stop_flag_sends_no_further_motion() {
    let cfg = BusConfig::default();
    let arm = SimArm::new(&SimOptions::default(), &cfg.servo_map).unwrap();
    let dir = common::tempdir();
    let journal = dir.path().join("journal.jsonl");
    let mut bus = Bus::connect(arm.transport(), cfg, Journal::append(&journal).unwrap()).unwrap();
    let frames = plan();
    bus.send_motion(0, dofbot_protocol::Pose::new(frames[0]).unwrap(), 80)
        .unwrap();
    bus.stop_flag()
        .store(true, std::sync::atomic::Ordering::SeqCst);
    let err = bus
        .send_motion(1, dofbot_protocol::Pose::new(frames[1]).unwrap(), 80)
        .unwrap_err();
    assert_eq!(err, BusError::Stopped);
    let motions = arm.received().iter().filter(|f| f.func == 0x1D).count();
    assert_eq!(motions, 1);
    let rp = ResumePoint::from_journal(&journal).unwrap();
    assert_eq!((rp.last_sent, rp.resume_from()), (Some(0), 0));
    assert_eq!(rp.last_error.unwrap().0, "stopped");
}

/// A write that failed may still have reached the board (a pty write timing out on a loaded
/// machine after delivering its bytes): the resume re-sends that frame rather than driving the
/// arm back to the last one logged as written.
#[test]
fn a_resume_starts_at_the_frame_whose_write_failed() {
    let line = |seq: u64, kind: &str, motion: u64| {
        format!(r#"{{"seq":{seq},"t":0.0,"unix_ms":0,"kind":"{kind}","motion":{motion}}}"#)
    };
    let text = [
        line(0, "tx", 3),
        line(1, "tx", 4),
        line(2, "error", 5),
        String::new(),
    ]
    .join("\n");
    let rp = ResumePoint::parse(Path::new("j.jsonl"), text.as_bytes()).unwrap();
    assert_eq!((rp.last_sent, rp.last_failed_write), (Some(4), Some(5)));
    assert_eq!(rp.resume_from(), 5);
    let stopped = [line(0, "tx", 4), line(1, "stop", 5), String::new()].join("\n");
    let rp = ResumePoint::parse(Path::new("j.jsonl"), stopped.as_bytes()).unwrap();
    assert_eq!(rp.resume_from(), 4, "a stop sends nothing");
}

/// A plan over two setups (issue 51): the run of setup 1 ends at an operator stop naming
/// setup 2, so a resume starts setup 2 at its first frame (not at setup 1's frame 41); a run
/// of setup 2 cut short resumes where it stood, its frames counted apart from setup 1's.
#[test]
fn an_operator_stop_hands_the_resume_to_the_next_setup_from_its_first_frame() {
    let line = |seq: u64, kind: &str, extra: &str| {
        format!(r#"{{"seq":{seq},"t":0.0,"unix_ms":0,"kind":"{kind}"{extra}}}"#)
    };
    let mut lines = vec![
        line(0, "open", r#","plan_sha256":"ab""#),
        line(1, "tx", r#","motion":0"#),
        line(2, "tx", r#","motion":41"#),
        line(3, "operator_stop", r#","code":"refixture","setup":2"#),
    ];
    let parse = |lines: &[String]| {
        let text = lines.join("\n") + "\n";
        ResumePoint::parse(Path::new("j.jsonl"), text.as_bytes()).unwrap()
    };
    let rp = parse(&lines);
    assert_eq!(rp.operator_stop, Some(("refixture".to_string(), 2)));
    assert_eq!((rp.setup, rp.last_sent), (1, Some(41)));
    lines.extend([
        line(4, "open", r#","plan_sha256":"ab","setup":2"#),
        line(5, "tx", r#","motion":0"#),
        line(6, "tx", r#","motion":7"#),
        line(7, "error", r#","motion":8"#),
    ]);
    let rp = parse(&lines);
    assert_eq!(rp.operator_stop, None, "setup 2 has started");
    assert_eq!((rp.setup, rp.last_sent, rp.resume_from()), (2, Some(7), 8));
    assert_eq!(rp.plan_sha256, vec!["ab".to_string()]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Random joint targets, many outside the limits: whatever the public API accepts puts
    /// only in-range raws on the wire, and they decode to joints inside the limits.
    #[test]
    fn no_frame_outside_raw_ranges_or_joint_limits(
        q in prop::array::uniform5(-4.0f64..4.0),
        gripper in -20.0f64..200.0,
        time in prop::option::of(0.01f64..3.0),
    ) {
        let cfg = BusConfig { ping_at_connect: false, ..BusConfig::default() };
        let map = cfg.servo_map.clone();
        let arm = SimArm::new(&SimOptions::default(), &map).unwrap();
        let mut bus = Bus::connect(arm.transport(), cfg, Journal::none()).unwrap();
        let within = q.iter().zip(&map.joints).all(|(v, j)| *v >= j.lower_rad && *v <= j.upper_rad)
            && (0.0..=180.0).contains(&gripper);
        let result = bus.move_joints(&q, gripper, time.map(Duration::from_secs_f64));
        if !within {
            prop_assert!(matches!(result, Err(BusError::Refused(_))));
        }
        for f in arm.received().iter().filter(|f| f.func == 0x1D) {
            let frame = dofbot_protocol::Frame::new(f.func, &f.payload).unwrap();
            let Ok(dofbot_protocol::Command::MoveAll { pose, .. }) = dofbot_protocol::Command::parse(&frame) else {
                panic!("a 0x1D frame that does not parse");
            };
            let state = map.state_from_raw(pose.raw()).unwrap();
            for (i, j) in map.joints.iter().enumerate() {
                let half_count = (0.5 / j.servo_scale().unwrap().counts_per_deg()).to_radians();
                prop_assert!(state.joints[i] >= j.lower_rad - half_count && state.joints[i] <= j.upper_rad + half_count);
            }
            prop_assert!(within);
        }
    }
}

/// `arm` takes its servo map from servos.toml (as `run` and `calibrate` do): a calibrated zero
/// offset of servo 1 moves the raw target and is taken back out of the read.
#[test]
fn arm_commands_use_the_calibrated_servo_offsets() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let mock = Mock::start(&py, &[]);
    let dir = common::tempdir();
    let shipped = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration/servos.toml"),
    )
    .unwrap();
    let servos = dir.path().join("servos.toml");
    std::fs::write(
        &servos,
        shipped.replacen("zero_offset_deg = 90.0", "zero_offset_deg = 95.0", 1),
    )
    .unwrap();
    let config = dir.path().join("arm.toml");
    std::fs::write(
        &config,
        format!("[robot]\nservos = {:?}\n", servos.display().to_string()),
    )
    .unwrap();
    let arm = |args: &[&str], calibrated: bool| {
        let mut cmd = common::polishbot();
        cmd.arg("arm").args(args).args(["--port", &mock.path]);
        if calibrated {
            cmd.arg("--config").arg(&config);
        }
        let out = common::succeed(&mut cmd);
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap_or_default()
    };
    arm(&["move", "--joints", "0,0,0,0,0", "--time", "0.3"], true);
    // Servo 1 at 95 servo degrees: raw 900 + 2200 * 95 / 180.
    let calibrated = arm(&["read"], true);
    let raw = raw_array(&calibrated["raw"]);
    assert!(raw[0].abs_diff(2061) <= 1, "servo 1 raw {}", raw[0]);
    assert!(calibrated["joints"][0].as_f64().unwrap().abs() < 0.002);
    // The shipped map (zero at 90) sees the same servo 5 degrees round.
    let nominal = arm(&["read"], false);
    let q1 = nominal["joints"][0].as_f64().unwrap();
    assert!((q1 - 5f64.to_radians()).abs() < 0.002, "joint 1 {q1}");
}

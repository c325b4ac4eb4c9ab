//! The DOFBOT link as the real boards speak it. Serial, against the mock on a pseudo-terminal:
//! the arm commands on every kind of ping reply (none, status, id and status) with stale
//! echoes passed over, a servo that answers neither ping nor read, and Ctrl-C ending a wait.
//! I2C: every command the driver sends, performed on the in-process fake board, is
//! the transactions of Yahboom's smbus `Arm_Lib.py` byte for byte (written out here from that
//! library, not from dofbot-protocol); `arm` and `calibrate` run end to end over it from the
//! CLI (`POLISHBOT_TEST_FAKE_I2C`, test-only); without the device `--i2c` is one line naming
//! it. (`run` over I2C: tests/plan.rs, which has the planned inspection.)
mod common;

use std::path::Path;
use std::time::Duration;

use dofbot_protocol::i2c::Transaction as T;
use dofbot_protocol::{Pose, ServoId};
use polishbot::bus::EntryKind;
use polishbot::bus::{Bus, JOINT_COUNT};
use polishbot::bus::{BusConfig, I2cTransport, Journal, ServoMap};
use polishbot::robot::Servos;
use polishbot::sim::{FakeI2c, I2cRecord, SimArm, SimOptions};

use common::{raw_array, read_journal, Mock};

/// Joint angles of the serial moves, rad.
const Q: [f64; JOINT_COUNT] = [0.5, -0.3, 0.2, 0.1, 1.0];

const FAKE: &str = "POLISHBOT_TEST_FAKE_I2C";

fn byte(reg: u8, value: u8) -> T {
    T::WriteByte { reg, value }
}

/// The transactions recorded since `from` and the records themselves.
fn since(records: &[I2cRecord], from: usize) -> (Vec<T>, Vec<I2cRecord>) {
    let r = records[from..].to_vec();
    (r.iter().map(|x| x.op).collect(), r)
}

#[test]
fn every_command_on_the_fake_board_is_arm_libs_transactions() {
    let cfg = BusConfig {
        ping_at_connect: false,
        ..BusConfig::default()
    };
    let arm = SimArm::new(&SimOptions::default(), &cfg.servo_map).unwrap();
    let fake = FakeI2c::new(arm.clone(), 0x15);
    let records = fake.records();
    let mut bus = Bus::connect(I2cTransport::new(fake), cfg, Journal::none()).unwrap();
    let rec = || records.lock().unwrap().clone();

    // Arm_serial_servo_read(2): write_byte_data(0x15, 0x32, 0), sleep(0.003),
    // read_word_data(0x15, 0x32); the word is the board's big-endian value swapped.
    let n = rec().len();
    let raw = bus.read_raw(ServoId::new(2).unwrap()).unwrap();
    let (ops, r) = since(&rec(), n);
    assert_eq!(ops, [byte(0x32, 0), T::ReadWord { reg: 0x32 }]);
    assert!(r[1].t - r[0].t >= 0.003 - 1e-9, "no 3 ms wait: {r:?}");
    assert_eq!(r[1].value, Some(raw.swap_bytes()));
    assert_eq!(raw, arm.positions()[1]);

    // Arm_ping_servo(3): write_byte_data(0x15, 0x38, 3), sleep(.003), read_byte_data(0x15,
    // 0x38): 0xDA alive.
    let n = rec().len();
    assert_eq!(bus.ping(3).unwrap(), Some(0xDA));
    let (ops, r) = since(&rec(), n);
    assert_eq!(ops, [byte(0x38, 3), T::ReadByte { reg: 0x38 }]);
    assert!(r[1].t - r[0].t >= 0.003 - 1e-9);

    // Arm_serial_set_torque(0) and (1): write_byte_data(0x15, 0x1A, 0 | 1).
    let n = rec().len();
    bus.torque(false).unwrap();
    bus.torque(true).unwrap();
    assert_eq!(since(&rec(), n).0, [byte(0x1A, 0), byte(0x1A, 1)]);

    // Arm_serial_servo_write6(...): write_i2c_block_data(0x15, 0x1e, [tH, tL]), then
    // write_i2c_block_data(0x15, 0x1d, [p1H, p1L, .., p6H, p6L]).
    let target = [2100u16, 1900, 2200, 1800, 1600, 2500];
    let n = rec().len();
    bus.send_motion(0, Pose::new(target).unwrap(), 1500)
        .unwrap();
    let data: Vec<u8> = target.iter().flat_map(|r| r.to_be_bytes()).collect();
    assert_eq!(
        since(&rec(), n).0,
        [T::block(0x1E, &[0x05, 0xDC]), T::block(0x1D, &data)]
    );
    bus.sleep(Duration::from_millis(1600));
    assert_eq!(arm.positions(), target);
    assert_eq!(bus.verify(0, target).unwrap().raw, target);

    // Arm_serial_servo_write_offset_switch(4): write_byte_data(0x15, 0x1c, 4);
    // Arm_serial_servo_write_offset_state(): write_byte_data(0x15, 0x1b, 1), sleep(.001),
    // read_byte_data(0x15, 0x1b) (1 = ok).
    let n = rec().len();
    bus.store_mid_offset(ServoId::new(4).unwrap()).unwrap();
    let state = bus.offset_state().unwrap();
    assert_eq!(state, dofbot_protocol::OffsetState::Ok);
    let (ops, r) = since(&rec(), n);
    assert_eq!(
        ops,
        [byte(0x1C, 4), byte(0x1B, 1), T::ReadByte { reg: 0x1B }]
    );
    assert!(r[2].t - r[1].t >= 0.001 - 1e-9);

    // Arm_get_hardversion(): write_byte_data(0x15, 0x01, 1), sleep(.001), read_byte_data.
    let n = rec().len();
    assert_eq!(bus.version().unwrap(), 1);
    assert_eq!(
        since(&rec(), n).0,
        [byte(0x01, 1), T::ReadByte { reg: 0x01 }]
    );
}

/// Runs polishbot over the fake I2C board logging to `log`; returns its output.
fn over_i2c(log: &Path, args: &[&str]) -> std::process::Output {
    common::polishbot()
        .args(args)
        .args(["--i2c", "/dev/i2c-1"])
        .env(FAKE, log)
        .output()
        .unwrap()
}

fn log_lines(log: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(log)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn arm_ping_read_move_over_i2c_from_the_cli() {
    let dir = common::tempdir();
    let log = dir.path().join("i2c.jsonl");
    let out = over_i2c(&log, &["arm", "ping"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        v["evidence"],
        "ping replies and reads: all six servos answered both"
    );
    assert_eq!(v["port"], "i2c fake @ 0x15");
    // Per servo: Arm_ping_servo's write and read of 0x38, then Arm_serial_servo_read's of
    // 0x30+id.
    let ops: Vec<(String, u64)> = log_lines(&log)
        .iter()
        .map(|l| {
            (
                l["op"].as_str().unwrap().to_string(),
                l["reg"].as_u64().unwrap(),
            )
        })
        .collect();
    let mut want = Vec::new();
    for id in 1..=6u64 {
        want.push(("write_byte".to_string(), 0x38));
        want.push(("read_byte".to_string(), 0x38));
        want.push(("write_byte".to_string(), 0x30 + id));
        want.push(("read_word".to_string(), 0x30 + id));
    }
    assert_eq!(ops[..24], want[..]);

    let q = [0.3, -0.2, 0.4, 0.1, -0.5];
    let joints = q.map(|x: f64| x.to_string()).join(",");
    let out = over_i2c(
        &log,
        &[
            "arm",
            "move",
            "--joints",
            &joints,
            "--gripper",
            "40",
            "--time",
            "1.2",
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let want = ServoMap::default().pose_raw(&q, 40.0).unwrap();
    let got: Vec<u16> = v["raw"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_u64().unwrap() as u16)
        .collect();
    assert_eq!(got, want);
    // The motion went as Arm_serial_servo_write6 sends it: time to 0x1E, positions to 0x1D.
    let lines = log_lines(&log);
    let k = lines.iter().position(|l| l["reg"] == 0x1D).unwrap();
    assert_eq!(lines[k - 1]["reg"], 0x1E);
    assert_eq!(lines[k - 1]["data"], serde_json::json!([0x04, 0xB0]));
    let data: Vec<u8> = want.iter().flat_map(|r| r.to_be_bytes()).collect();
    assert_eq!(lines[k]["data"], serde_json::json!(data));
}

#[test]
fn calibrate_servos_over_i2c_recovers_the_hidden_offsets() {
    let dir = common::tempdir();
    let config = dir.path().join("cfg.toml");
    let offsets = [2.0, -3.0, 1.5, 4.0, -2.5];
    std::fs::write(
        &config,
        "[sim.mechanics]\nmount_offset_deg = [2.0, -3.0, 1.5, 4.0, -2.5, 0.0]\nstart_physical_deg = [90.0, 90.0, 90.0, 90.0, 90.0, 90.0]\n",
    )
    .unwrap();
    let log = dir.path().join("i2c.jsonl");
    let out = over_i2c(
        &log,
        &[
            "calibrate",
            "servos",
            "--assume-pose",
            "--config",
            config.to_str().unwrap(),
            "--out",
            dir.path().to_str().unwrap(),
        ],
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let servos = Servos::load(&dir.path().join("servos.toml")).unwrap();
    assert!(servos.servos.len() >= JOINT_COUNT);
    for (s, d) in servos.servos.iter().zip(offsets) {
        // Within one count (1/12.2 deg) of the planted offset.
        assert!((s.zero_offset_deg - 90.0 - d).abs() < 0.09, "{s:?}");
    }
    // Torque off went as Arm_serial_set_torque(0) does it.
    assert!(log_lines(&log).iter().any(|l| l["op"] == "write_byte"
        && l["reg"] == 0x1A
        && l["data"] == serde_json::json!([0])));
}

#[test]
fn i2c_without_the_device_is_one_line_naming_it() {
    let out = common::polishbot()
        .args(["arm", "read", "--i2c", "/dev/i2c-no-such-bus"])
        .env_remove(FAKE)
        .output()
        .unwrap();
    let stderr = common::one_line_failure(&out);
    assert!(
        stderr.starts_with("polishbot: ") && stderr.contains("/dev/i2c-no-such-bus"),
        "{stderr}"
    );
    let out = common::polishbot()
        .args([
            "arm",
            "read",
            "--i2c",
            "/dev/i2c-1",
            "--i2c-address",
            "0x99",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("0x03..0x77"),
        "{stderr}"
    );
}

/// `arm ping`, `arm move` (read back and verified) and `arm read` against each kind of board
/// (no ping reply, as the serial Arm_ping_servo expects; a 1-byte status; id and status), with
/// a stale reply (another servo's echo) before every third read that must be passed over.
#[test]
fn arm_commands_work_whatever_the_board_answers_to_pings() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let both = "ping replies and reads: all six servos answered both";
    let boards = [
        ("none", "no ping replies; all six servos answered reads"),
        ("status", both),
        ("id-status", both),
    ];
    let want = ServoMap::default().pose_raw(&Q, 30.0).unwrap();
    let joints = Q.map(|q| q.to_string()).join(",");
    for (ping, evidence) in boards {
        let mock = Mock::start(&py, &["--ping", ping, "--stale-echo-every", "3"]);
        let arm = |args: &[&str]| {
            let out = common::succeed(
                common::polishbot()
                    .arg("arm")
                    .args(args)
                    .args(["--port", &mock.path]),
            );
            serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
        };
        let v = arm(&["ping"]);
        assert_eq!(v["evidence"], evidence, "--ping {ping}: {v}");
        for s in v["servos"].as_array().unwrap() {
            let status = if ping == "none" {
                serde_json::Value::Null
            } else {
                0xDA.into()
            };
            assert_eq!(s["ping_status"], status, "--ping {ping}: {s}");
            assert!(s["raw"].as_u64().is_some(), "--ping {ping}: {s}");
        }
        let move_args = format!("move --joints {joints} --gripper 30 --time 1.2");
        let moved = arm(&move_args.split(' ').collect::<Vec<_>>());
        assert_eq!(raw_array(&moved["raw"]), want, "--ping {ping}");
        let read = arm(&["read"]);
        assert_eq!(raw_array(&read["raw"]), want, "--ping {ping}");
        let (state, logged) = mock.finish_logged();
        assert_eq!(raw_array(&state["positions"]), want);
        assert!(logged.iter().any(|l| l["cmd"] == "ping"));
    }
}

/// A board whose pings say a servo is absent and whose reads of it get no reply: `arm ping`
/// names it and fails; with no ping replies at all the read's timeout is the error.
#[test]
fn a_servo_that_answers_neither_ping_nor_read_is_an_error() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    for (ping, message) in [
        ("status", "servo 5 not answering"),
        ("none", "timeout: no reply to read_position (0x35)"),
    ] {
        let mock = Mock::start(&py, &["--ping", ping, "--absent-servo", "5"]);
        let out = common::polishbot()
            .args(["arm", "ping", "--port", &mock.path])
            .output()
            .unwrap();
        let stderr = common::one_line_failure(&out);
        assert!(stderr.contains(message), "--ping {ping}: {stderr}");
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["servos"][4]["raw"], serde_json::Value::Null);
    }
}

/// Ctrl-C during `arm move`'s wait for a 30 s move on the real-time simulator: the command
/// ends within 100 ms of the signal (250 ms allowed here for a loaded machine), fails with the
/// stop named, and the journal ends on a complete stop line.
#[test]
fn ctrl_c_ends_the_wait_of_a_move_at_once_with_the_journal_closed() {
    let dir = common::tempdir();
    let config = dir.path().join("cfg.toml");
    std::fs::write(&config, "[sim]\nrealtime = true\n").unwrap();
    let journal = dir.path().join("journal.jsonl");
    let child = common::polishbot()
        .args([
            "arm",
            "move",
            "--sim",
            "--joints",
            "0.2,0,0,0,0",
            "--time",
            "30",
        ])
        .arg("--config")
        .arg(&config)
        .arg("--journal")
        .arg(&journal)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until the motion frame is journalled, then interrupt.
    let t0 = std::time::Instant::now();
    while !std::fs::read_to_string(&journal).is_ok_and(|t| t.contains("move_all")) {
        assert!(t0.elapsed() < Duration::from_secs(20), "no motion frame");
        std::thread::sleep(Duration::from_millis(10));
    }
    let sent = std::time::Instant::now();
    std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    let out = child.wait_with_output().unwrap();
    let took = sent.elapsed();
    println!("Ctrl-C to exit: {} ms", took.as_millis());
    assert!(took < Duration::from_millis(250), "took {took:?}");
    let stderr = common::one_line_failure(&out);
    assert!(stderr.contains("stopped by the operator"), "{stderr}");
    let entries = read_journal(&journal);
    assert_eq!(entries.last().unwrap().kind, EntryKind::Stop);
}

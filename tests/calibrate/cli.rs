//! The Python mock, the CLI, the jog terminal over a PTY, and bad calibration files.
use super::*;

/// The mock with the hidden offsets, 1 count of read noise seeded `seed`, held at the zero pose.
fn hidden_mock(py: &Path, seed: u64) -> common::Mock {
    let off: Vec<String> = OFFSETS.iter().map(|v| v.to_string()).collect();
    let seed = seed.to_string();
    common::Mock::start(
        py,
        &[
            "--mount-offset-deg",
            &off.join(","),
            "--read-noise-counts",
            "1",
            "--noise-seed",
            &seed,
            "--start-physical-deg",
            "90,90,90,90,90,90",
        ],
    )
}

#[test]
fn sim_and_mock_agree_with_hidden_mechanics() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let _board = common::take_turns();
    let mock = hidden_mock(&py, 17);
    let cfg = BusConfig::default();
    let mut real = Bus::connect(
        polishbot::bus::SerialTransport::open(&mock.path).unwrap(),
        cfg.clone(),
        Journal::none(),
    )
    .unwrap();
    let options = SimOptions {
        mechanics: mechanics(1),
        ..SimOptions::default()
    };
    let arm = SimArm::new(&options, &cfg.servo_map).unwrap();
    let mut sim = Bus::connect(arm.transport(), cfg, Journal::none()).unwrap();
    let mut reads = Vec::new();
    for _ in 0..4 {
        let a = real.read_pose_raw().unwrap();
        assert_eq!(a, sim.read_pose_raw().unwrap());
        reads.push(a);
    }
    assert!(reads.windows(2).any(|w| w[0] != w[1]), "noise is on");
    real.torque(true).unwrap();
    sim.torque(true).unwrap();
    let q = [0.3, -0.2, 0.4, 0.1, 0.6];
    let a = real.move_joints(&q, 90.0, None).unwrap();
    let b = sim.move_joints(&q, 90.0, None).unwrap();
    assert_eq!(a, b);
    drop(real);
    let state = mock.finish();
    let phys: Vec<f64> = state["physical_deg"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for (m, s) in phys.iter().zip(arm.physical_deg()) {
        assert!((m - s).abs() < 1e-9, "{m} vs {s}");
    }
}

/// Runs `polishbot calibrate ARGS --port P --out DIR`; returns stdout.
fn cli(port: &str, out: &Path, args: &[&str]) -> String {
    let o = common::succeed(
        common::polishbot()
            .arg("calibrate")
            .args(args)
            .args(["--port", port, "--out"])
            .arg(out),
    );
    String::from_utf8(o.stdout).unwrap()
}

#[test]
fn mock_chain_through_the_cli_recovers_the_planted_truth() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let _board = common::take_turns();
    let mock = hidden_mock(&py, 3);
    let dir = common::tempdir();
    let out = dir.path().join("cell");
    let log = cli(&mock.path, &out, &["servos", "--assume-pose"]);
    assert!(log.contains("wrote"), "{log}");
    let servos = Servos::load(&out.join("servos.toml")).unwrap();
    for s in servos.servos.iter().filter(|s| s.joint.is_some()) {
        let err = s.zero_offset_deg - 90.0 - OFFSETS[s.id as usize - 1];
        assert!(err.abs() < 0.2, "servo {}: {err} deg", s.id);
    }

    let robot = robot_from(&shipped("tool.toml"), &out.join("servos.toml"));
    let map = frames::servo_map(&robot).unwrap();
    let pivot = dir.path().join("pivot.txt");
    std::fs::write(&pivot, targets_text(&pivot_targets(&map))).unwrap();
    let log = cli(
        &mock.path,
        &out,
        &["tool", "--targets", pivot.to_str().unwrap()],
    );
    assert!(log.contains("residual per touch"), "{log}");
    let tool = Tool::load(&out.join("tool.toml")).unwrap();
    let tip_err = (Vector3::from(tool.tip_offset) - Vector3::from(TRUE_TIP)).norm() * 1000.0;
    eprintln!("mock: tool tip error {tip_err:.3} mm");
    assert!(tip_err < 0.5, "{tip_err} mm");

    let fix = fixture();
    let fix_file = dir.path().join("fixture.toml");
    std::fs::write(&fix_file, fixture_toml(&fix)).unwrap();
    let fid = dir.path().join("fiducials.txt");
    std::fs::write(&fid, targets_text(&fiducial_targets(&map, &fix))).unwrap();
    let (fix_s, fid_s) = (fix_file.to_str().unwrap(), fid.to_str().unwrap());
    let log = cli(
        &mock.path,
        &out,
        &["workcell", "--fixture", fix_s, "--targets", fid_s],
    );
    assert!(log.contains("residual per fiducial"), "{log}");
    let w = Workcell::load(&out.join("workcell.toml")).unwrap();
    let t_err = translation_error_mm(&w.robot_from_reference, &true_workcell());
    let r_err = rotation_angle_deg(&w.robot_from_reference, &true_workcell());
    eprintln!("mock: workcell translation {t_err:.3} mm, rotation {r_err:.4} deg");
    assert!(t_err < 1.0 && r_err < 0.5, "{t_err} mm {r_err} deg");

    let log = cli(
        &mock.path,
        &out,
        &["verify", "--targets", fid_s, "--fixture", fix_s],
    );
    assert!(log.contains("worst tool tip"), "{log}");
    assert_eq!(log.matches("fiducial ").count(), 5, "{log}");
}

/// A child process on a new pseudo-terminal: keys in, screen text out.
struct Pty {
    master: std::fs::File,
    screen: Arc<Mutex<Vec<u8>>>,
    child: std::process::Child,
}

impl Pty {
    fn spawn(cmd: &mut std::process::Command) -> Pty {
        use std::os::fd::{FromRawFd, OwnedFd};
        let (mut m, mut s) = (0, 0);
        // SAFETY: openpty fills two new descriptors; each is owned exactly once below.
        let rc = unsafe {
            libc::openpty(
                &mut m,
                &mut s,
                std::ptr::null_mut(),
                std::ptr::null(),
                std::ptr::null(),
            )
        };
        assert_eq!(rc, 0, "openpty");
        let (master, slave) = unsafe { (OwnedFd::from_raw_fd(m), OwnedFd::from_raw_fd(s)) };
        let child = cmd
            .stdin(slave.try_clone().unwrap())
            .stdout(slave.try_clone().unwrap())
            .stderr(slave)
            .spawn()
            .unwrap();
        let master = std::fs::File::from(master);
        let screen = Arc::new(Mutex::new(Vec::new()));
        let (mut r, sink) = (master.try_clone().unwrap(), screen.clone());
        std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = r.read(&mut buf) {
                if n == 0 {
                    break;
                }
                sink.lock().unwrap().extend_from_slice(&buf[..n]);
            }
        });
        Pty {
            master,
            screen,
            child,
        }
    }

    fn text(&self) -> String {
        String::from_utf8_lossy(&self.screen.lock().unwrap()).to_string()
    }

    /// Waits until the screen holds `needle` `count` times.
    fn wait_for(&self, needle: &str, count: usize) -> String {
        let start = Instant::now();
        loop {
            let t = self.text();
            if t.matches(needle).count() >= count {
                return t;
            }
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "no {needle:?} x{count} on screen:\n{t}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn keys(&mut self, k: &str) {
        self.master.write_all(k.as_bytes()).unwrap();
    }
}

#[test]
fn jog_terminal_over_a_pty_steps_joints_shows_the_tip_and_records_touches() {
    let dir = common::tempdir();
    let mut pty = Pty::spawn(
        common::polishbot()
            .args(["calibrate", "tool", "--sim", "--out"])
            .arg(dir.path()),
    );
    pty.wait_for("jog: joint 1 | step 1.00 deg", 1);
    // Keys arrive one by one (raw mode): no newline is ever sent.
    pty.keys("2");
    pty.wait_for("jog: joint 2 | step 1.00 deg", 1);
    pty.keys("]");
    pty.wait_for("jog: joint 2 | step 2.00 deg", 1);
    pty.keys("+");
    let screen = pty.wait_for("| touches 0", 4);
    // Joint 2 read back at +2 deg within two counts (0.16 deg: the raw quantisation and the
    // simulated arm's documented read-back noise of one count), the tip moved towards -y and
    // down.
    let last = screen.lines().rfind(|l| l.contains("| touches 0")).unwrap();
    let field = |name: &str| -> Vec<f64> {
        let rest = last.split(name).nth(1).unwrap();
        let part = rest.split('|').next().unwrap();
        part.split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect()
    };
    let q = field("q [deg]");
    assert!((q[1] - 2.0).abs() < 0.2 && q[0].abs() < 0.2, "{last}");
    let tip = field("tip [mm]");
    assert!(tip[1] < -10.0 && tip[2] > 400.0, "{last}");
    pty.keys("t");
    pty.wait_for("touch 1 recorded (the pivot point (touch 1))", 1);
    pty.keys("5+++");
    pty.wait_for("jog: joint 5 | step 2.00 deg", 4);
    pty.keys(" ");
    let screen = pty.wait_for("touch 2 recorded", 1);
    // Keys are not echoed.
    assert!(!screen.contains("5+++"), "{screen}");
    pty.keys("q");
    let screen = pty.wait_for(
        "polishbot: calibrate tool: pivot: 2 touches, need at least 4",
        1,
    );
    let status = pty.child.wait().unwrap();
    assert!(!status.success(), "{screen}");
    assert!(!dir.path().join("tool.toml").exists());
}

#[test]
fn servos_waits_for_enter_on_a_terminal_then_writes_the_file() {
    let dir = common::tempdir();
    let config = dir.path().join("cfg.toml");
    std::fs::write(
        &config,
        "[sim.mechanics]\nmount_offset_deg = [2.0, -3.0, 1.5, 4.0, -2.5, 0.0]\nstart_physical_deg = [90.0, 90.0, 90.0, 90.0, 90.0, 90.0]\n",
    )
    .unwrap();
    let mut pty = Pty::spawn(
        common::polishbot()
            .args(["calibrate", "servos", "--sim", "--out"])
            .arg(dir.path())
            .arg("--config")
            .arg(&config),
    );
    pty.wait_for("[Enter to go on, Esc to abort]", 1);
    std::thread::sleep(Duration::from_millis(200));
    assert!(!dir.path().join("servos.toml").exists(), "waited for Enter");
    pty.keys("\r");
    pty.wait_for("calibrate servos: wrote", 1);
    assert!(pty.child.wait().unwrap().success());
    let servos = Servos::load(&dir.path().join("servos.toml")).unwrap();
    for (s, d) in servos.servos.iter().zip([2.0, -3.0, 1.5, 4.0, -2.5]) {
        assert!((s.zero_offset_deg - 90.0 - d).abs() < 0.1, "{s:?}");
    }
}

#[test]
fn bad_files_and_bad_fits_name_the_place() {
    let dir = common::tempdir();
    let t = dir.path().join("targets.txt");
    std::fs::write(&t, "# ok\n0.1, 0.2 0.3,0.4 0.5\n\n0.1 0.2 0.3\n").unwrap();
    let e = calibrate::load_targets(&t).unwrap_err().to_string();
    assert!(
        e.contains("targets.txt: line 4: need 5 joint angles (rad), got 3"),
        "{e}"
    );
    std::fs::write(&t, "0.1 0.2 x 0.4 0.5\n").unwrap();
    let e = calibrate::load_targets(&t).unwrap_err().to_string();
    assert!(e.contains("line 1: invalid float literal"), "{e}");

    // servos.toml without a zero_offset_deg line gets one after its id; an unknown id is named.
    let text = "period = 0.02\n[[servo]]\nid = 2 # shoulder\njoint = \"a\"\n";
    let out = files::patch_servos(text, &t, &[(2, 91.25)]).unwrap();
    assert!(
        out.contains("id = 2 # shoulder\nzero_offset_deg = 91.25\njoint"),
        "{out}"
    );
    let e = files::patch_servos(text, &t, &[(4, 90.0)]).unwrap_err();
    assert!(
        e.to_string().contains("no [[servo]] table with id = 4"),
        "{e}"
    );

    // A touch 6 mm off its fiducial: refused on the RMS, naming every fiducial's residual.
    let fix = fixture();
    let w = true_workcell();
    let touches: Vec<calibrate::Touch> = fix
        .fiducials
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let mut p = w.transform_point(&Point3::from(Vector3::from(f.position) * 1e-3));
            if k == 2 {
                p.z += 0.006;
            }
            calibrate::Touch {
                label: f.name.clone(),
                joints: [0.0; 5],
                tip: [p.x, p.y, p.z],
            }
        })
        .collect();
    let cfg = CalibrationConfig::default();
    let ok = calibrate::workcell::fit_workcell(&fix, touches[..].to_vec(), &cfg);
    let e = ok.unwrap_err().to_string();
    assert!(
        e.contains("RMS residual") && e.contains("C ") && e.contains("E "),
        "{e}"
    );

    // verify against a workcell that is 5 cm off: not ok.
    let far = Workcell {
        robot_from_reference: Matrix4::new_translation(&Vector3::new(0.05, 0.3, 0.1)),
    };
    cell_run(|bus, cell| {
        let r = calibrate::verify(
            bus,
            cell,
            &calibrate::verify::DEFAULT_CHECK_POSES,
            Some((&fix, &far)),
        )
        .unwrap();
        assert!(!r.ok && r.max_fiducial_error_mm.unwrap() > 10.0, "{r:?}");
    });
}

//! Grinding planner: plans from inspections of synthetic cases (truth from `synth`) checked
//! through the robot model, unreachable regions reported, bad input refused, plan.json, CLI.
mod common;

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use polishbot::motion::{plan_part, Inspection, Plan, PlanConfig, PlanError, SegmentKind};
use polishbot::robot::{Robot, Workcell};

fn calib(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration")
        .join(name)
}

fn dofbot() -> (Robot, Workcell) {
    let robot = Robot::load(
        &calib("dofbot.urdf"),
        &calib("tool.toml"),
        &calib("servos.toml"),
    )
    .expect("calibration");
    let wc = Workcell::load(&calib("workcell.toml")).expect("workcell");
    (robot, wc)
}

/// The inspection folder of synth case `seed` with `defects` defects (common::synthetic).
fn synthetic_inspection(dir: &Path, seed: u64, defects: usize) -> polishbot::synth::Truth {
    common::synthetic::inspection(dir, &common::femoral_synth(seed, defects))
}

/// Finite-difference velocity, acceleration and jerk of the samples against the joint limits.
fn worst_derivative_ratio(plan: &Plan, robot: &Robot) -> f64 {
    let h = plan.period;
    let mut worst: f64 = 0.0;
    for (j, spec) in robot.joints.iter().enumerate() {
        let q: Vec<f64> = plan.samples.iter().map(|s| s.q[j]).collect();
        for w in q.windows(4) {
            let v = (w[1] - w[0]) / h;
            let a = (w[2] - 2.0 * w[1] + w[0]) / (h * h);
            let jk = (w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]) / (h * h * h);
            worst = worst
                .max(v.abs() / spec.velocity)
                .max(a.abs() / spec.acceleration)
                .max(jk.abs() / spec.jerk);
        }
        for v in &q {
            assert!(
                *v >= spec.lower - 1e-9 && *v <= spec.upper + 1e-9,
                "{} out of limits",
                spec.name
            );
        }
    }
    worst
}

fn polyline_distance(p: &Vector3<f64>, line: &[Vector3<f64>]) -> f64 {
    polishbot::motion::check::polyline_distance(p, line)
}

#[test]
fn plan_from_a_synthetic_inspection_meets_every_acceptance_number() {
    let tmp = common::tempdir();
    let truth = synthetic_inspection(tmp.path(), 11, 6);
    let inspection = Inspection::load(tmp.path()).expect("load inspection");
    let (robot, wc) = dofbot();
    let cfg = PlanConfig::rigid();
    let p = plan_part(&inspection, &robot, &wc, &cfg).expect("plan");
    println!(
        "defects: {:?}",
        truth
            .defects
            .iter()
            .map(|d| (d.kind, d.height, d.width))
            .collect::<Vec<_>>()
    );
    println!("metrics: {:#?}", p.metrics);
    for r in &p.reachability.regions {
        println!("region {r:?}");
    }
    println!(
        "unreachable: {} (first: {:?})",
        p.reachability.unreachable.len(),
        p.reachability.unreachable.first()
    );
    assert!(!p.passes.is_empty(), "something must be ground");

    // limits by finite differences, within 1 %
    let worst = worst_derivative_ratio(&p, &robot);
    println!("worst derivative / limit: {worst:.4}");
    assert!(worst <= 1.01, "finite differences reach {worst} of a limit");

    // modelled tool tip against every planned path point and vice versa
    let tips: Vec<Vector3<f64>> = p.samples.iter().map(|s| robot.fk(&s.q).position).collect();
    let mut worst_path: f64 = 0.0;
    let mut feeds = Vec::new();
    for seg in p.segments.iter().filter(|s| s.kind == SegmentKind::Grind) {
        let pass = &p.passes[seg.pass.expect("grind segments name a pass")];
        let sampled = &tips[seg.first_sample..=seg.last_sample];
        for pt in &pass.points {
            let tip = Vector3::from(pt.tip_m);
            assert!(
                (robot.fk(&pt.q).position - tip).norm() < 1e-9,
                "IK of a path point"
            );
            worst_path = worst_path.max(polyline_distance(&tip, sampled));
        }
        let planned: Vec<Vector3<f64>> =
            pass.points.iter().map(|x| Vector3::from(x.tip_m)).collect();
        for t in sampled {
            worst_path = worst_path.max(polyline_distance(t, &planned));
        }
        // feed: tip speed over the middle of strokes long enough to cruise
        let n = sampled.len();
        if n > 40 {
            for w in sampled[n / 4..3 * n / 4].windows(2) {
                feeds.push((w[1] - w[0]).norm() / p.period * 1e3);
            }
        }
    }
    println!("worst path error {:.4} mm", worst_path * 1e3);
    assert!(worst_path * 1e3 <= 0.1);
    assert!(!feeds.is_empty());
    for f in &feeds {
        assert!(
            (f - cfg.feed_mm_s).abs() <= 0.1 * cfg.feed_mm_s,
            "feed {f} mm/s"
        );
    }

    // coverage of the reachable part of every planned region
    for r in p
        .reachability
        .regions
        .iter()
        .filter(|r| r.repairable && r.layers > 0)
    {
        if r.reachable_points > 0 {
            assert!(
                r.coverage_of_reachable >= 0.95,
                "region {} coverage {}",
                r.id,
                r.coverage_of_reachable
            );
        }
        assert!(
            (r.unreachable_share - (1.0 - r.reachable_points as f64 / r.points as f64)).abs()
                < 1e-12
        );
    }
    // every left-out point says why
    assert!(p
        .reachability
        .unreachable
        .iter()
        .all(|u| !u.reason.is_empty()));
}

/// A plan of a small case (one depth layer per region) for the streaming tests, saved.
fn small_plan(dir: &Path) -> (Plan, PathBuf) {
    let insp = dir.join("inspection");
    synthetic_inspection(&insp, 11, 6);
    let inspection = Inspection::load(&insp).expect("load inspection");
    let (robot, wc) = dofbot();
    let cfg = PlanConfig {
        depth_step_mm: 1.0,
        ..PlanConfig::rigid()
    };
    let p = plan_part(&inspection, &robot, &wc, &cfg).expect("plan");
    assert!(p.passes.len() > 2, "the case must have reachable passes");
    let path = dir.join("plan.json");
    p.save(&path).expect("save");
    (p, path)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn sim_run_receives_exactly_the_plan_frames_at_the_period() {
    use polishbot::bus::{Bus, BusConfig, Journal};
    use polishbot::sim::{SimArm, SimOptions};
    let tmp = common::tempdir();
    let (_, path) = small_plan(tmp.path());
    let (robot, _) = dofbot();
    let p = Plan::load(&path).expect("load");
    let checked = p.check(&robot, &Default::default()).expect("re-check");
    let cfg = BusConfig {
        servo_map: polishbot::motion::frames::servo_map(&robot).expect("map"),
        ..BusConfig::default()
    };
    let arm = SimArm::new(&SimOptions::default(), &cfg.servo_map).expect("sim");
    let journal = Journal::append(&tmp.path().join("journal.jsonl")).expect("journal");
    let mut bus = Bus::connect(arm.transport(), cfg, journal).expect("connect");
    let report = polishbot::cell::execute(&mut bus, &checked, p.period, 0, &Default::default())
        .expect("run");
    let moves: Vec<_> = arm
        .received()
        .into_iter()
        .filter(|f| f.func == 0x1D)
        .collect();
    assert_eq!(moves.len(), checked.frames.len());
    for (got, want) in moves.iter().zip(&checked.frames) {
        assert_eq!(got.payload, want[4..want.len() - 1], "payload differs");
    }
    let gaps: Vec<f64> = moves.windows(2).map(|w| w[1].t - w[0].t).collect();
    let m = median(gaps);
    assert!((m - p.period).abs() <= 0.002, "median gap {m}");
    assert_eq!(report.final_raw, *checked.raw.last().unwrap());
    assert_eq!(arm.positions(), *checked.raw.last().unwrap());
    println!(
        "sim: {} frames, median gap {m:.4} s, {} read-backs",
        moves.len(),
        report.readbacks
    );
}

/// `polishbot plan` of the inspection folder `insp` with 1 mm depth layers (a config file
/// in `dir`) and `extra` arguments, into `dir/plan.json`; its output and that path.
fn cli_plan(
    dir: &Path,
    insp: &Path,
    extra: &[&std::ffi::OsStr],
) -> (std::process::Output, PathBuf) {
    let cfg = dir.join("plan.toml");
    std::fs::write(&cfg, "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n").unwrap();
    let plan_path = dir.join("plan.json");
    let out = common::succeed(
        common::polishbot()
            .args(["plan", "--config"])
            .arg(&cfg)
            .arg("--inspection")
            .arg(insp)
            .arg("-o")
            .arg(&plan_path)
            .args(extra),
    );
    (out, plan_path)
}

#[test]
fn cli_plan_then_run_against_the_mock_board() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let tmp = common::tempdir();
    let insp = tmp.path().join("inspection");
    synthetic_inspection(&insp, 11, 6);
    let yaml = tmp.path().join("traj.yaml");
    let (out, plan_path) = cli_plan(tmp.path(), &insp, &["--export-ros".as_ref(), yaml.as_ref()]);
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let p = Plan::load(&plan_path).unwrap();
    let text = std::fs::read_to_string(&yaml).unwrap();
    assert!(text.contains("joint_names: [\"arm_joint1\", \"arm_joint2\", \"arm_joint3\", \"arm_joint4\", \"arm_joint5\"]"));
    assert_eq!(text.matches("  - positions:").count(), p.samples.len());

    let mock = common::Mock::start(&py, &[]);
    let journal = tmp.path().join("journal.jsonl");
    let out = common::succeed(
        common::polishbot()
            .args(["run", "--plan"])
            .arg(&plan_path)
            .args(["--port", &mock.path, "--journal"])
            .arg(&journal),
    );
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let (state, logged) = mock.finish_logged();
    let logged: Vec<serde_json::Value> =
        logged.into_iter().filter(|l| l["func"] == "0x1D").collect();
    let frames: Vec<&str> = logged
        .iter()
        .map(|l| l["frame"].as_str().unwrap())
        .collect();
    assert_eq!(frames.len(), p.frames.len());
    assert!(
        frames.iter().zip(&p.frames).all(|(a, b)| *a == b),
        "frames differ"
    );
    let gaps: Vec<f64> = logged
        .windows(2)
        .map(|w| w[1]["t"].as_f64().unwrap() - w[0]["t"].as_f64().unwrap())
        .collect();
    let m = median(gaps);
    println!("mock: {} frames, median gap {:.4} s", frames.len(), m);
    assert!((m - p.period).abs() <= 0.002, "median gap {m}");
    let (robot, _) = dofbot();
    let checked = p.check(&robot, &Default::default()).unwrap();
    let pos: Vec<u16> = state["positions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap() as u16)
        .collect();
    assert_eq!(pos, checked.raw.last().unwrap().to_vec(), "final pose");
}

/// A region whose peak regions.json marks as a lower bound (read by single point pairs) is
/// planned down to that peak, and `plan` says so: in plan.json's reachability and in a
/// warning line.
#[test]
fn a_lower_bound_peak_is_carried_into_the_plan_with_a_warning() {
    let tmp = common::tempdir();
    let insp = tmp.path().join("inspection");
    synthetic_inspection(&insp, 11, 6);
    let file = insp.join("regions.json");
    let mut regions: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let list = regions["regions"].as_array_mut().unwrap();
    let flagged = list
        .iter_mut()
        .find(|r| r["repairable"] == true)
        .expect("a repairable region");
    flagged["peak_lower_bound"] = true.into();
    let id = flagged["id"].as_u64().unwrap() as usize;
    std::fs::write(&file, regions.to_string()).unwrap();
    let (out, plan_path) = cli_plan(tmp.path(), &insp, &[]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let p = Plan::load(&plan_path).unwrap();
    for r in &p.reachability.regions {
        assert_eq!(r.peak_lower_bound, r.id == id, "region {}", r.id);
        let warned = stdout.contains(&format!("warning: region {}: its peak", r.id));
        assert_eq!(
            warned,
            r.id == id && r.layers > 0,
            "region {}: {stdout}",
            r.id
        );
    }
    assert!(
        p.reachability
            .regions
            .iter()
            .any(|r| r.id == id && r.layers > 0),
        "the flagged region was not planned: {stdout}"
    );
}

#[test]
fn run_refuses_a_tampered_plan_before_sending_anything() {
    let tmp = common::tempdir();
    let (p, path) = small_plan(tmp.path());
    let provenance = common::hostile::stamp(&path, &common::hostile::provenance_of(tmp.path()));
    let (robot, _) = dofbot();
    let refuse = |bad: &Plan, why: &str| {
        let f = tmp.path().join("bad.json");
        bad.save(&f).unwrap();
        common::hostile::stamp(&f, &provenance);
        let out = common::polishbot()
            .args(["run", "--sim", "--plan"])
            .arg(&f)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("refused"),
            "{why}: {err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(
            !tmp.path().join("journal.jsonl").exists(),
            "{why}: nothing may be sent"
        );
    };
    // a frame byte changed
    let mut bad = p.clone();
    let k = bad.frames.len() / 2;
    bad.frames[k] = bad.frames[k - 1].clone();
    refuse(&bad, "frame");
    // a sample moved so that its frame is consistent but the jerk is not
    let mut bad = p.clone();
    bad.samples[k].q[1] += 0.01;
    let qs: Vec<Vec<f64>> = bad.samples.iter().map(|s| s.q.clone()).collect();
    let map = polishbot::motion::frames::servo_map(&robot).unwrap();
    bad.frames = polishbot::motion::frames::encode(&qs, &map, 90.0, bad.period)
        .unwrap()
        .iter()
        .map(|f| polishbot::motion::frames::to_hex(f))
        .collect();
    assert!(matches!(
        bad.check(&robot, &Default::default()),
        Err(PlanError::Invalid(_))
    ));
    refuse(&bad, "jerk");
    // a joint beyond its limit
    let mut bad = p.clone();
    bad.samples[k].q[2] = 1.6;
    refuse(&bad, "limit");
    // the untouched plan passes, and a dry run sends nothing
    common::succeed(
        common::polishbot()
            .args(["run", "--sim", "--dry-run", "--plan"])
            .arg(&path),
    );
    assert!(!tmp.path().join("journal.jsonl").exists());
}

#[test]
fn unreachable_regions_are_reported_point_by_point() {
    let tmp = common::tempdir();
    synthetic_inspection(tmp.path(), 11, 6);
    let inspection = Inspection::load(tmp.path()).unwrap();
    let (robot, mut wc) = dofbot();
    wc.robot_from_reference[(1, 3)] += 1.0; // the part 1 m farther away
    let p = plan_part(&inspection, &robot, &wc, &PlanConfig::rigid()).unwrap();
    assert!(p.passes.is_empty());
    let total: usize = p.reachability.regions.iter().map(|r| r.path_points).sum();
    assert!(total > 0);
    assert_eq!(
        p.reachability.unreachable.len(),
        total,
        "every point listed"
    );
    assert!(p
        .reachability
        .unreachable
        .iter()
        .all(|u| u.reason.starts_with("out of reach")));
    for r in p.reachability.regions.iter().filter(|r| r.repairable) {
        assert_eq!(r.unreachable_share, 1.0);
        assert_eq!(r.coverage_of_all, 0.0);
    }
    let strict = PlanConfig {
        require_full_reach: true,
        ..PlanConfig::rigid()
    };
    let err = plan_part(&inspection, &robot, &wc, &strict).unwrap_err();
    assert!(matches!(err, PlanError::Unreachable(ref v) if v.len() == total));
    assert!(err.to_string().contains("out of reach"));
}

#[test]
fn bad_inspection_files_are_refused_with_file_and_place() {
    let tmp = common::tempdir();
    synthetic_inspection(tmp.path(), 11, 2);
    let csv = tmp.path().join("deviations.csv");
    let good = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = good.lines().map(String::from).collect();
    lines[5] = lines[5].replacen(',', ",x", 1);
    std::fs::write(&csv, lines.join("\n")).unwrap();
    let e = Inspection::load(tmp.path()).unwrap_err().to_string();
    assert!(e.contains("deviations.csv") && e.contains("line 6"), "{e}");
    std::fs::write(&csv, &good).unwrap();
    let regions = tmp.path().join("regions.json");
    let text = std::fs::read_to_string(&regions).unwrap();
    std::fs::write(&regions, text.replacen("\"points\"", "\"pts\"", 1)).unwrap();
    let e = Inspection::load(tmp.path()).unwrap_err().to_string();
    assert!(e.contains("regions.json") && e.contains("line 1"), "{e}");
    std::fs::write(&regions, text.replacen("\"points\":", "\"points\":1+", 1)).unwrap();
    assert!(Inspection::load(tmp.path()).is_err());
    let out = common::polishbot()
        .args(["plan", "--inspection"])
        .arg(tmp.path().join("missing"))
        .args(["-o", "/dev/null"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("regions.json"),
        "{err}"
    );
}

#[test]
fn plan_from_the_inspect_command_of_a_synth_case() {
    let tmp = common::tempdir();
    let case = tmp.path().join("case");
    let run = |args: &[&str]| {
        let out = common::polishbot().args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let mesh = s(&common::shared_data("femoral_dm.stl"));
    let contact = s(&common::shared_data("femoral_dm_contact.stl"));
    run(&[
        "synth",
        "--out",
        &s(&case),
        "--mesh",
        &mesh,
        "--surface",
        &contact,
        "--units",
        "m",
        "--seed",
        "11",
        "--reference-points",
        "100000",
        "--scan-points",
        "100000",
    ]);
    let insp = tmp.path().join("insp");
    run(&[
        "inspect",
        "--reference",
        &s(&case.join("reference.ply")),
        "--scan",
        &s(&case.join("scan.ply")),
        "--pose",
        &s(&case.join("truth.json")),
        "-o",
        &s(&insp),
    ]);
    let plan_path = tmp.path().join("plan.json");
    println!(
        "{}",
        run(&[
            "plan",
            "--mode",
            "rigid",
            "--inspection",
            &s(&insp),
            "-o",
            &s(&plan_path)
        ])
    );
    let p = Plan::load(&plan_path).unwrap();
    let (robot, _) = dofbot();
    p.check(&robot, &Default::default())
        .expect("the written plan passes the re-check");
    assert!(worst_derivative_ratio(&p, &robot) <= 1.01);
    let m = &p.metrics;
    assert!(m.sample_to_path_max_mm <= 0.1 && m.path_to_samples_max_mm <= 0.1);
    assert!(
        m.cruise_feed_min_mm_s >= 0.9 * m.feed_mm_s && m.cruise_feed_max_mm_s <= 1.1 * m.feed_mm_s,
        "{m:?}"
    );
    assert!(!p.passes.is_empty());
    for r in p
        .reachability
        .regions
        .iter()
        .filter(|r| r.layers > 0 && r.reachable_points > 0)
    {
        assert!(r.coverage_of_reachable >= 0.95, "{r:?}");
    }
}

/// `run` over the fake I2C board (tests/link.rs checks the rest of the I2C link): every frame
/// of the plan goes out as Arm_Lib's six-servo transactions (the time block to 0x1E, the
/// twelve position bytes to 0x1D), in order, ending on the plan's last frame; `--dry-run`
/// opens no device.
#[test]
fn cli_plan_then_run_over_the_fake_i2c_board() {
    let tmp = common::tempdir();
    let insp = tmp.path().join("inspection");
    synthetic_inspection(&insp, 12, 3);
    let (_, plan_path) = cli_plan(tmp.path(), &insp, &[]);
    let p = Plan::load(&plan_path).unwrap();
    let log = tmp.path().join("i2c.jsonl");
    let run = |extra: &[&str]| {
        common::succeed(
            common::polishbot()
                .args(["run", "--i2c", "/dev/i2c-1", "--plan"])
                .arg(&plan_path)
                .args(extra)
                .env("POLISHBOT_TEST_FAKE_I2C", &log),
        )
    };
    run(&["--dry-run"]);
    assert!(!log.exists(), "a dry run opened the device");
    run(&["--journal", tmp.path().join("j.jsonl").to_str().unwrap()]);
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let sent: Vec<Vec<u64>> = lines
        .windows(2)
        .filter(|w| w[1]["reg"] == 0x1D)
        .map(|w| {
            assert_eq!(w[0]["reg"], 0x1E, "0x1D block without its time block");
            let mut v: Vec<u64> = serde_json::from_value(w[1]["data"].clone()).unwrap();
            v.extend(serde_json::from_value::<Vec<u64>>(w[0]["data"].clone()).unwrap());
            v
        })
        .collect();
    let planned: Vec<Vec<u64>> = p
        .frames
        .iter()
        .map(|f| {
            let b: Vec<u64> = f
                .split(' ')
                .map(|h| u64::from_str_radix(h, 16).unwrap())
                .collect();
            b[4..b.len() - 1].to_vec()
        })
        .collect();
    assert_eq!(sent.len(), planned.len());
    assert!(sent == planned, "I2C blocks differ from the plan's frames");
}

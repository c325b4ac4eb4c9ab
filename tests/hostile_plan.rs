//! Hostile inputs against the built binary (issue 34, "checked inputs and settings"), the
//! settings, plan and run side: config files, arm move times, plan settings, an inspection
//! whose files contradict each other, journals, `calibrate verify`'s targets, `synth`'s
//! settings and where the calibration files come from. Every case must end in well under 20 s
//! with a non-zero exit and one line naming the file and the place (line, key), never a panic;
//! and the checks must not refuse the valid case they guard. The inspect side is in hostile.rs.
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::hostile::{arg, case, read_json, refused};
use common::{pair_args, polishbot, succeed};
use serde_json::Value;

/// Writes `text` as a config file and returns its path.
fn config(tmp: &Path, text: &str) -> PathBuf {
    let path = tmp.join("settings.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn config_errors_name_the_file_the_line_and_the_key() {
    let tmp = common::tempdir();
    let plan = case().path("plan.json");
    let cases: [(&str, &[&str], &[&str]); 7] = [
        (
            "[bus]\nframe_gap_ms = 10\nsettle_ms = 1e300\n",
            &["arm", "read", "--sim"],
            &["line 3", "`settle_ms`", "ms"],
        ),
        (
            "[sim.timing]\n\nbaud = 0.0\n",
            &["arm", "read", "--sim"],
            &["line 3", "`baud`"],
        ),
        (
            "[bus]\nattempts = -1\n",
            &["arm", "read", "--sim"],
            &["line 2"],
        ),
        (
            "[bus]\nsettle_ms = \"soon\"\n",
            &["arm", "read", "--sim"],
            &["line 2"],
        ),
        (
            "[bus\nsettle_ms = 3\n",
            &["arm", "read", "--sim"],
            &["line 1"],
        ),
        (
            "[run]\nsettle_ms = 1e300\n",
            &["run", "--dry-run", "--plan", arg(&plan)],
            &["line 2", "[run]", "`settle_ms`"],
        ),
        (
            "reference_points = 7\n[compare]\nmethd = \"classic\"\n",
            &pair_args("inspect"),
            &["line 3", "unknown key `compare.methd`"],
        ),
    ];
    for (text, args, needles) in cases {
        let file = config(tmp.path(), text);
        let mut cmd = polishbot();
        cmd.arg("--config").arg(&file).args(args);
        let mut needles = needles.to_vec();
        needles.push("settings.toml");
        refused(&mut cmd, &needles);
    }
}

#[test]
fn absurd_arm_move_times_are_refused_without_a_panic() {
    for t in ["1e300", "-1", "NaN"] {
        let time = format!("--time={t}");
        refused(
            polishbot().args(["arm", "move", "--sim", "--joints", "0,0,0,0,0", &time]),
            &["--time"],
        );
    }
}

/// `plan` of `insp` with the settings `text`, into a fresh plan file under `tmp`.
fn plan(tmp: &Path, insp: &Path, text: &str) -> Command {
    let cfg = config(tmp, text);
    let mut cmd = polishbot();
    cmd.arg("--config")
        .arg(cfg)
        .args(["plan", "--inspection", arg(insp), "-o"])
        .arg(tmp.join("plan.json"));
    cmd
}

#[test]
fn plan_settings_out_of_range_are_refused_at_their_line() {
    let insp = case().path("inspection");
    let tmp = common::tempdir();
    for (text, key) in [
        ("[plan]\n\nallowance_mm = -1\n", "`allowance_mm`"),
        ("[plan]\n\ndepth_step_mm = 1e-9\n", "`depth_step_mm`"),
        ("[plan]\n\nspacing_mm = 1e-9\n", "`spacing_mm`"),
    ] {
        refused(&mut plan(tmp.path(), &insp, text), &["line 3", key, "mm"]);
    }
}

/// A copy of the case's inspection folder with regions.json's first repairable region (and
/// deviations.csv's text) edited.
fn tampered(
    tmp: &Path,
    region: impl FnOnce(&mut Value),
    csv: impl FnOnce(String) -> String,
) -> PathBuf {
    let from = case().path("inspection");
    let dir = tmp.join("inspection");
    std::fs::create_dir_all(&dir).unwrap();
    let mut regions = read_json(&from.join("regions.json"));
    let list = regions["regions"].as_array_mut().unwrap();
    region(
        list.iter_mut()
            .find(|r| r["repairable"] == true)
            .expect("a repairable region"),
    );
    std::fs::write(dir.join("regions.json"), regions.to_string()).unwrap();
    let text = std::fs::read_to_string(from.join("deviations.csv")).unwrap();
    std::fs::write(dir.join("deviations.csv"), csv(text)).unwrap();
    dir
}

/// An edit of a region of regions.json.
type RegionEdit = Box<dyn FnOnce(&mut Value)>;
/// An edit of deviations.csv's text.
type CsvEdit = Box<dyn FnOnce(String) -> String>;

#[test]
fn an_inspection_whose_files_contradict_each_other_is_refused() {
    let keep = |t: String| t;
    let cases: Vec<(RegionEdit, CsvEdit, &str)> = vec![
        (
            Box::new(|r| r["peak"] = 1e6.into()),
            Box::new(keep),
            "layers",
        ),
        (
            Box::new(|r| r["peak"] = (-r["peak"].as_f64().unwrap()).into()),
            Box::new(keep),
            "repairable",
        ),
        (
            Box::new(|r| {
                r["peak"] = (-r["peak"].as_f64().unwrap()).into();
                r["repairable"] = false.into();
            }),
            Box::new(keep),
            "differ in sign",
        ),
        (Box::new(|r| r["area"] = 1e9.into()), Box::new(keep), "area"),
        (
            Box::new(|_| {}),
            Box::new(|t: String| {
                let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
                let last = lines.last_mut().unwrap();
                let cut = last.rfind(',').unwrap();
                last.replace_range(cut.., ",77");
                lines.join("\n") + "\n"
            }),
            "region 77",
        ),
    ];
    for (region, csv, needle) in cases {
        let tmp = common::tempdir();
        let insp = tampered(tmp.path(), region, csv);
        refused(
            &mut plan(
                tmp.path(),
                &insp,
                "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n",
            ),
            &["inspection", needle],
        );
    }
}

#[test]
fn a_core_point_far_away_in_a_region_is_refused_at_once() {
    let tmp = common::tempdir();
    let mut id = 0;
    let insp = tampered(tmp.path(), |r| id = r["id"].as_i64().unwrap(), |t| t);
    // Move one row of that region 5 m away: regions.json no longer describes it.
    let csv = insp.join("deviations.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut done = false;
    let edited: Vec<String> = text
        .lines()
        .map(|l| match !done && l.ends_with(&format!(",{id}")) {
            true => {
                done = true;
                let rest = l.split_once(',').unwrap().1;
                format!("5000,{rest}")
            }
            false => l.to_string(),
        })
        .collect();
    assert!(done);
    std::fs::write(&csv, edited.join("\n") + "\n").unwrap();
    refused(
        &mut plan(
            tmp.path(),
            &insp,
            "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n",
        ),
        &["regions.json", "regions["],
    );
}

/// `run --dry-run` of the case's plan with `extra` arguments.
fn dry_run(extra: &[&str]) -> Command {
    let mut cmd = polishbot();
    cmd.args([
        "run",
        "--dry-run",
        "--sim",
        "--plan",
        arg(&case().path("plan.json")),
    ])
    .args(extra);
    cmd
}

#[test]
fn a_journal_is_tied_to_its_plan_and_a_garbage_journal_is_an_error() {
    let c = case();
    let tmp = common::tempdir();
    let journal = tmp.path().join("journal.jsonl");
    let out = succeed(polishbot().args([
        "run",
        "--sim",
        "--plan",
        arg(&c.path("plan.json")),
        "--journal",
        arg(&journal),
    ]));
    assert!(out.status.success());
    let text = std::fs::read_to_string(&journal).unwrap();
    let open: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    let sha = open["plan_sha256"]
        .as_str()
        .expect("plan_sha256 on the open line");
    assert_eq!(sha.len(), 64);
    // The same plan resumes (from its last frame); a plan differing by one byte does not.
    succeed(&mut dry_run(&["--resume", arg(&journal)]));
    let other = tmp.path().join("other.json");
    let plan_text = std::fs::read_to_string(c.path("plan.json")).unwrap();
    std::fs::write(&other, format!("{plan_text}\n")).unwrap();
    refused(
        polishbot().args([
            "run",
            "--dry-run",
            "--sim",
            "--plan",
            arg(&other),
            "--resume",
            arg(&journal),
        ]),
        &["journal.jsonl", "another plan"],
    );
    // A journal claiming a frame beyond the plan.
    let far = tmp.path().join("far.jsonl");
    let tx = format!(
        "{}\n{{\"seq\":1,\"t\":0.1,\"unix_ms\":0,\"kind\":\"tx\",\"motion\":999999}}\n",
        text.lines().next().unwrap()
    );
    std::fs::write(&far, tx).unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&far)]),
        &["far.jsonl", "frame 999999"],
    );
    // Garbage, a journal without a plan hash, and a cut line in the middle.
    let garbage = tmp.path().join("garbage.jsonl");
    std::fs::write(&garbage, "this is not a journal\n").unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&garbage)]),
        &["garbage.jsonl", "line 1"],
    );
    let old = tmp.path().join("old.jsonl");
    std::fs::write(
        &old,
        text.replace(&format!(",\"plan_sha256\":\"{sha}\""), ""),
    )
    .unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&old)]),
        &["old.jsonl", "no plan SHA-256"],
    );
    let cut = tmp.path().join("cut.jsonl");
    let lines: Vec<&str> = text.lines().collect();
    std::fs::write(
        &cut,
        format!("{}\n{{\"seq\":1,\"t\n{}\n", lines[0], lines[1]),
    )
    .unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&cut)]),
        &["cut.jsonl", "line 2"],
    );
}

#[test]
fn calibrate_verify_with_no_targets_is_an_error() {
    let tmp = common::tempdir();
    let targets = tmp.path().join("targets.txt");
    std::fs::write(&targets, "# no poses\n\n").unwrap();
    refused(
        polishbot()
            .args([
                "calibrate",
                "verify",
                "--sim",
                "--targets",
                arg(&targets),
                "--out",
            ])
            .arg(tmp.path()),
        &["targets.txt", "no joint targets"],
    );
}

#[test]
fn synth_refuses_nan_and_absurd_settings_up_front() {
    let tmp = common::tempdir();
    let out = tmp.path().join("case");
    for (flag, value, key) in [
        ("--noise", "NaN", "`noise`"),
        ("--reference-points", "100000000000", "`reference_points`"),
        ("--max-translation", "1e300", "`max_translation`"),
    ] {
        refused(
            polishbot().args(["synth", "--out", arg(&out), flag, value]),
            &[key],
        );
        assert!(
            !out.join("reference.ply").exists(),
            "{flag} {value} wrote files"
        );
    }
    let cfg = config(tmp.path(), "[shape]\nwidth = 64\ngroove_sigma = nan\n");
    refused(
        polishbot()
            .arg("--config")
            .arg(&cfg)
            .args(["synth", "--out", arg(&out)]),
        &["settings.toml", "line 3", "`groove_sigma`"],
    );
}

#[test]
fn calibration_files_come_from_the_working_directory_not_the_source_tree() {
    let tmp = common::tempdir();
    let out = polishbot()
        .current_dir(tmp.path())
        .args(["arm", "read", "--sim"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "ran without ./calibration/: {err}");
    assert!(err.contains("calibration/"), "{err}");
    assert!(!err.contains(env!("CARGO_MANIFEST_DIR")), "{err}");
}

/// A URDF joint's `<limit velocity>` is read: NaN, 0 or negative is refused naming the file
/// and the joint (it was ignored), and a URDF limit below servos.toml `velocity` is the one the
/// planner keeps (the intersection, as for the position limits).
#[test]
fn a_urdf_velocity_limit_is_checked_and_bounds_the_planner() {
    use polishbot::robot::{FileText, Robot, Tool};
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration");
    let read = |f: &str| FileText::read(&shipped.join(f)).unwrap();
    let (urdf, servos) = (read("dofbot.urdf"), read("servos.toml"));
    let with_velocity = |v: &str| {
        let text = urdf
            .text
            .replacen("velocity=\"1.0\"", &format!("velocity=\"{v}\""), 1);
        let urdf = FileText {
            path: urdf.path.clone(),
            text,
        };
        let tool = Tool::load(&shipped.join("tool.toml")).unwrap();
        Robot::from_texts(&urdf, tool, &servos)
    };
    for bad in ["nan", "0", "-1", "inf"] {
        let Err(e) = with_velocity(bad) else {
            panic!("velocity {bad} accepted")
        };
        let e = e.to_string();
        assert!(
            e.contains("dofbot.urdf") && e.contains("arm_joint1") && e.contains("velocity"),
            "{bad}: {e}"
        );
        assert_eq!(e.lines().count(), 1, "{e}");
    }
    let robot = with_velocity("0.5").unwrap();
    assert_eq!(robot.joints[0].velocity, 0.5);
    // a URDF limit above servos.toml's leaves the servos' (1.0 rad/s)
    assert_eq!(with_velocity("4.0").unwrap().joints[0].velocity, 1.0);
}

/// A negative synth setting given as a flag (`--noise -1` was taken by clap for a flag and
/// ended in its usage text, exit 2) and a defect range out of bounds or reversed are refused
/// in one line naming the flag and the range; the documented edges still pass the check.
#[test]
fn synth_flags_out_of_range_name_the_flag_and_the_range() {
    let tmp = common::tempdir();
    let out = tmp.path().join("case");
    for (flag, value, says) in [
        ("--noise", "-1", "0..=5 mm"),
        ("--noise", "inf", "0..=5 mm"),
        ("--outliers", "-0.1", "0..=0.49"),
        ("--width-range", "0.01,3", "0.05..=100 mm"),
        ("--width-range", "3,1", "min <= max"),
        ("--height-range", "-1,0.5", "0..=10 mm"),
    ] {
        let line = refused(
            polishbot().args(["synth", "--out", arg(&out), flag, value]),
            &[&format!("polishbot: {flag}: "), says],
        );
        assert_eq!(line.lines().count(), 1);
        assert!(
            !out.join("reference.ply").exists(),
            "{flag} {value} wrote files"
        );
    }
    let mut cfg = polishbot::synth::SynthConfig {
        width_range: [0.05, 100.0],
        height_range: [0.0, 10.0],
        noise: 0.0,
        ..Default::default()
    };
    assert_eq!(cfg.check(), Ok(()));
    cfg.width_range = [2.0, 2.0];
    assert_eq!(cfg.check(), Ok(()));
}

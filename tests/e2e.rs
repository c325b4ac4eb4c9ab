//! The whole chain as a user runs it, through the CLI and over a pseudo-terminal against the
//! Python mock board: synth -> inspect -> plan -> run. The regions are scored against the
//! planted truth, the mock's received frames and final servo state against the plan; then the
//! same run with reply faults injected, and a run whose link dies mid-way, resumed from its
//! journal on a fresh mock that starts where the first one stopped.
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use common::{polishbot, succeed, Mock};
use serde_json::Value;

/// The case every test here shares: made once per test binary run.
struct Case {
    dir: PathBuf,
    plan: PathBuf,
    /// The plan's 0x1D frames, hex as the mock logs them.
    frames: Vec<String>,
    /// Raw servo targets of the plan's last frame (servos 1..6).
    final_raw: Vec<u64>,
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Raw targets of a 0x1D frame `FF FC 11 1D r1hi r1lo ... r6hi r6lo thi tlo CHK`.
fn frame_targets(hex: &str) -> Vec<u64> {
    let b: Vec<u64> = hex
        .split(' ')
        .map(|t| u64::from_str_radix(t, 16).unwrap())
        .collect();
    assert_eq!(
        &b[..4],
        &[0xFF, 0xFC, 0x11, 0x1D],
        "not a move_all frame: {hex}"
    );
    (0..6).map(|i| (b[4 + 2 * i] << 8) | b[5 + 2 * i]).collect()
}

fn path_arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// synth -> inspect -> plan through the CLI, in the target's scratch folder.
fn case() -> &'static Case {
    static CASE: OnceLock<Case> = OnceLock::new();
    CASE.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("e2e");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let d = |f: &str| dir.join(f);
        // Small but real: the parametric part at half the default density (lower, the ICP
        // residual that enters the level of detection hides 0.2 mm defects), three defects,
        // a seed whose regions the arm partly reaches, one depth layer per region.
        succeed(polishbot().args([
            "synth",
            "--out",
            path_arg(&dir),
            "--seed",
            "9",
            "--defects",
            "3",
            "--reference-points",
            "200000",
            "--scan-points",
            "150000",
            "--height-range",
            "0.15,0.35",
            "--width-range",
            "2,3",
        ]));
        let out = succeed(polishbot().args([
            "inspect",
            "--reference",
            path_arg(&d("reference.ply")),
            "--scan",
            path_arg(&d("scan.ply")),
            "-o",
            path_arg(&d("inspection")),
        ]));
        println!("{}", String::from_utf8_lossy(&out.stdout));
        std::fs::write(
            d("plan.toml"),
            "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n",
        )
        .unwrap();
        let out = succeed(polishbot().args([
            "plan",
            "--config",
            path_arg(&d("plan.toml")),
            "--inspection",
            path_arg(&d("inspection")),
            "-o",
            path_arg(&d("plan.json")),
        ]));
        println!("{}", String::from_utf8_lossy(&out.stdout));
        let plan = read_json(&d("plan.json"));
        let frames: Vec<String> = plan["frames"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f.as_str().unwrap().to_string())
            .collect();
        assert!(
            plan["passes"]
                .as_array()
                .unwrap()
                .iter()
                .any(|p| p["kind"] == "pass"),
            "the plan grinds nothing"
        );
        let final_raw = frame_targets(frames.last().unwrap());
        Case {
            plan: d("plan.json"),
            dir,
            frames,
            final_raw,
        }
    })
}

/// Stops the mock; its final state and the move_all frames it received, in order.
fn finish(mock: Mock) -> (Value, Vec<String>) {
    let (state, logged) = mock.finish_logged();
    let frames = logged
        .into_iter()
        .filter(|l| l["func"] == "0x1D")
        .map(|l| l["frame"].as_str().unwrap().to_string())
        .collect();
    (state, frames)
}

fn raw_list(v: &Value) -> Vec<u64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|r| r.as_u64().unwrap())
        .collect()
}

/// `polishbot run --plan P --port DEV` plus `extra` (journal or resume).
fn run_on(mock: &Mock, extra: &[&str]) -> Command {
    let mut cmd = polishbot();
    cmd.args([
        "run",
        "--plan",
        path_arg(&case().plan),
        "--port",
        &mock.path,
    ])
    .args(extra);
    cmd
}

fn journal_codes(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter_map(|e| e["code"].as_str().map(str::to_string))
        .collect()
}

#[test]
fn regions_match_the_planted_defects_and_registration_the_true_pose() {
    let c = case();
    let truth = read_json(&c.dir.join("truth.json"));
    let regions = read_json(&c.dir.join("inspection/regions.json"));
    let tolerance = regions["tolerance"].as_f64().unwrap();
    let regions = regions["regions"].as_array().unwrap();
    let defects = truth["defects"].as_array().unwrap();
    let f = |v: &Value| v.as_f64().unwrap();
    let dist = |a: &Value, b: &Value| {
        (0..3)
            .map(|i| (f(&a[i]) - f(&b[i])).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    // A region belongs to a defect when its centroid lies within the defect's reach and its
    // peak has the defect's sign.
    let belongs = |r: &Value, d: &Value| {
        let reach = f(&d["width"]) + f(&d["length"]) / 2.0 + 1.0;
        dist(&r["centroid"], &d["centre"]) <= reach
            && f(&r["peak"]).signum() == f(&d["height"]).signum()
    };
    let mut repairable = 0;
    for d in defects {
        if d["kind"] != "pit" && f(&d["height"]) > tolerance {
            repairable += 1;
            assert!(
                regions
                    .iter()
                    .any(|r| belongs(r, d) && r["repairable"] == true),
                "planted defect not found: {d}"
            );
        }
    }
    assert!(
        repairable >= 2,
        "the case plants {repairable} repairable defects"
    );
    for r in regions {
        assert!(
            defects.iter().any(|d| belongs(r, d)),
            "region invented where nothing was planted: {r}"
        );
        assert_eq!(r["repairable"] == true, f(&r["peak"]) > 0.0, "{r}");
    }
    // Registration: every scan point lands within 0.05 mm of where the true pose puts it.
    let reg = read_json(&c.dir.join("inspection/registration.json"));
    let (a, b) = (&reg["scan_to_reference"], &truth["scan_to_reference"]);
    for p in [
        [0.0, 0.0, 0.0],
        [40.0, 0.0, 0.0],
        [0.0, 40.0, 0.0],
        [0.0, 0.0, 40.0],
    ] {
        let map = |m: &Value| -> Vec<f64> {
            (0..3)
                .map(|i| (0..3).map(|j| f(&m[i][j]) * p[j]).sum::<f64>() + f(&m[i][3]))
                .collect()
        };
        let (pa, pb) = (map(a), map(b));
        let e = (0..3).map(|i| (pa[i] - pb[i]).powi(2)).sum::<f64>().sqrt();
        assert!(e < 0.05, "registration off by {e} mm at {p:?}");
    }
}

/// The mock ended where the plan ends: every servo there and commanded there.
fn assert_at_final_pose(state: &Value, c: &Case) {
    assert_eq!(raw_list(&state["positions"])[..6], c.final_raw[..]);
    assert_eq!(raw_list(&state["targets"])[..6], c.final_raw[..]);
}

/// A whole run against a mock started with `flags`: it must succeed, the mock must receive
/// exactly the plan's frames and end at its final pose. Returns the journal's error codes.
fn whole_run(py: &Path, flags: &[&str]) -> Vec<String> {
    let c = case();
    let _board = common::take_turns();
    let tmp = common::tempdir();
    let journal = tmp.path().join("journal.jsonl");
    let mock = Mock::start(py, flags);
    let out = succeed(&mut run_on(&mock, &["--journal", path_arg(&journal)]));
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let (state, frames) = finish(mock);
    assert_eq!(
        frames, c.frames,
        "{flags:?}: frames received differ from the plan's"
    );
    assert_at_final_pose(&state, c);
    journal_codes(&journal)
}

#[test]
fn the_mock_receives_every_planned_frame_and_ends_at_the_final_pose() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    whole_run(&py, &[]);
}

#[test]
fn dropped_and_corrupt_replies_are_retried_and_the_run_completes() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let codes = whole_run(&py, &["--drop-every", "7", "--corrupt-every", "5"]);
    for code in ["timeout", "bad_checksum"] {
        assert!(
            codes.iter().any(|k| k == code),
            "no {code} in the journal: {codes:?}"
        );
    }
}

#[test]
fn a_run_cut_off_mid_way_resumes_from_its_journal_to_the_same_final_pose() {
    let Some(py) = common::oracle_python() else {
        return;
    };
    let c = case();
    let _board = common::take_turns();
    let tmp = common::tempdir();
    let journal = tmp.path().join("journal.jsonl");
    // The board counts every frame (pings and reads too): cut the link about half-way.
    let cut = (c.frames.len() / 2).to_string();
    let broken = Mock::start(&py, &["--disconnect-after", &cut]);
    let out = run_on(&broken, &["--journal", path_arg(&journal)])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the cut-off run succeeded");
    assert!(
        err.contains("stopped") && err.contains("--resume"),
        "stderr: {err}"
    );
    let (at_break, before) = finish(broken);
    assert_eq!(at_break["disconnected"], true);
    assert!(
        !before.is_empty() && before.len() < c.frames.len(),
        "{} of {} frames before the cut",
        before.len(),
        c.frames.len()
    );
    assert_eq!(before[..], c.frames[..before.len()], "a prefix of the plan");

    // The arm stays where it stopped: the fresh board starts at the broken one's positions.
    let initial: Vec<String> = raw_list(&at_break["positions"])
        .iter()
        .map(u64::to_string)
        .collect();
    let resumed = Mock::start(&py, &["--initial", &initial.join(",")]);
    let dry = succeed(
        polishbot()
            .args(["run", "--dry-run", "--plan", path_arg(&c.plan), "--resume"])
            .arg(&journal),
    );
    println!("{}", String::from_utf8_lossy(&dry.stdout));
    let out = succeed(&mut run_on(&resumed, &["--resume", path_arg(&journal)]));
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let (resumed_state, after) = finish(resumed);
    let from = c.frames.len() - after.len();
    assert_eq!(
        after[..],
        c.frames[from..],
        "the resumed run sends the plan's tail"
    );
    assert!(
        from <= before.len() && from + 1 >= before.len(),
        "resumed at frame {from}; {} frames had arrived",
        before.len()
    );
    assert!(
        String::from_utf8_lossy(&dry.stdout).contains(&format!("from frame {from}")),
        "the dry run names the resume frame"
    );
    assert_at_final_pose(&resumed_state, c);
}

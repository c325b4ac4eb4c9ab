//! The closed scan-grind-rescan loop (issue 29, `polishbot cycle`): its settings, a plan that
//! fails, and the loop end to end on a synthetic part whose defects the arm reaches, scored
//! against the simulator's own truth (`after_truth.ply`: the removal per point) and the planted
//! defects (synth's truth). The stop rule and the prediction read: tests/cycle_rule.rs.
mod common;

use std::io::Write;
use std::path::Path;
use std::process::Stdio;

use nalgebra::Point3;
use polishbot::cycle::{CycleConfig, Outcome};
use polishbot::synth::DefectKind;

use common::accept::{
    acceptance, accepted, cycle, footprint, truth_scores, untouched_drift, TOLERANCE_MM,
};
use common::polishbot;

#[test]
fn an_unknown_table_in_the_cycle_settings_is_refused_naming_file_and_line() {
    let dir = common::tempdir();
    let cfg = dir.path().join("cycle.toml");
    std::fs::write(&cfg, "[plan.plan]\ndepth_step_mm = 1.0\n[plann]\nx = 1\n").unwrap();
    let out = polishbot()
        .args(["cycle", "--sim", "--reference", "r.ply", "--scan", "s.ply"])
        .arg("--config")
        .arg(&cfg)
        .arg("-o")
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    let line = common::one_line_failure(&out);
    assert!(
        line.contains("cycle.toml: line 3: unknown table `plann`"),
        "{line}"
    );
}

/// An arm that grinds nothing (the rescan is the scan it was given) and, before its rescan
/// comes back, makes the next iteration's plan.json a folder: grind 2's plan then fails to
/// be written, a failure of the plan stage as a failed path check is.
struct Blocked;

impl polishbot::cycle::Executor for Blocked {
    fn grind(
        &mut self,
        job: &polishbot::cycle::GrindJob,
    ) -> anyhow::Result<polishbot::cycle::Rescan> {
        let next = job.dir.parent().unwrap().join("iter-2/plan.json");
        std::fs::create_dir_all(next)?;
        Ok(polishbot::cycle::Rescan {
            scan: job.part.clone(),
            more_scans: Vec::new(),
            part: None,
        })
    }
}

#[test]
fn a_later_plan_that_fails_ends_the_loop_recorded_with_its_reason() {
    let dir = common::scratch("plan-failed");
    common::case(3, &dir);
    let mut plan = polishbot::cycle::PlanFileConfig::default();
    plan.robot.use_cell(&common::calib(""));
    let cfg = CycleConfig {
        // the arm grinds nothing: no progress must not end the loop before grind 2's plan
        min_progress: 0.0,
        // and the planner reads the part at the tool's footprint (footprint.csv, below)
        footprint_radius_mm: Some(polishbot::cycle::FINE_RADIUS_MM),
        plan,
        ..CycleConfig::default()
    };
    let out = dir.join("cycle");
    let inputs = common::loop_inputs(&dir, &out);
    let ended = polishbot::cycle::run_cycle(&cfg, inputs, &mut Blocked)
        .expect("a later plan's failure is an outcome, not an error");
    assert_eq!(ended.outcome, Outcome::PlanFailed);
    assert_eq!(ended.records.len(), 2, "{:?}", ended.records);
    let why = ended.records[1]
        .stopped
        .as_deref()
        .expect("the reason recorded");
    assert!(why.starts_with("grind 2's plan failed: "), "{why}");
    assert!(why.contains("plan.json"), "{why}");
    // cycle.json and cycle.html are written, with the verdict of the part as last measured
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("cycle.json")).unwrap()).unwrap();
    assert_eq!(json["outcome"], "plan_failed");
    assert_eq!(json["records"][1]["stopped"].as_str(), Some(why));
    assert_eq!(
        json["records"][1]["measured"]["verdict"],
        serde_json::to_value(ended.records[1].measured.verdict).unwrap()
    );
    let html = std::fs::read_to_string(&ended.html).unwrap();
    assert!(html.contains("Stopped because grind 2"), "{html}");
    // each inspection wrote its footprint reading, which the folder's plan input reads back:
    // a number on most rows (44858 of 50250: the 0.6 mm cylinders hold too few scan points at
    // the scan's borders and sparse spots), and the adaptive distances (deviations.csv) replaced
    let read = polishbot::repair::Inspection::load(&out.join("iter-1").join("inspection")).unwrap();
    let rows = read.points.len();
    let numbers = read.fine.iter().filter(|f| f.is_finite()).count();
    assert!(
        read.fine.len() == rows && numbers as f64 >= 0.85 * rows as f64,
        "{numbers} of {rows}"
    );
    assert!(read
        .points
        .iter()
        .zip(&read.fine)
        .all(|(p, f)| !f.is_finite() || p.distance == *f));
    let csv = std::fs::read_to_string(out.join("iter-1/inspection/deviations.csv")).unwrap();
    let adaptive: Vec<f64> = (csv.lines().skip(1))
        .map(|l| l.split(',').nth(6).unwrap().parse().unwrap())
        .collect();
    let moved = adaptive
        .iter()
        .zip(&read.points)
        .filter(|(a, p)| **a != p.distance)
        .count();
    assert!(
        moved as f64 > 0.5 * rows as f64,
        "{moved} of {rows} read differently"
    );
    assert!(out.join("iter-2/inspection/footprint.csv").exists());
}

/// Least drop of a planted bump's true peak (p90) in the first grind, mm: the rigid layers
/// at k 1.3 x nominal take 0.04-0.1 mm off (42 % of the demo's excess volume in its first
/// pass), so 0.01 mm (two thirds of the scan noise) tells a ground defect from a missed one.
const FIRST_DROP_MM: f64 = 0.01;
/// Noise margin when comparing a peak across two rescans (different points), mm: the p90 of a
/// few hundred points with 0.015 mm scanner noise moves by about this much between rescans.
const RESCAN_MARGIN_MM: f64 = 0.01;

#[test]
fn the_loop_grinds_the_reachable_defects_down_over_iterations_and_leaves_the_pits() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cycle");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let truth = common::case(3, &dir);
    // the rigid loop as this test was written for it: depth layers ground by a stiff burr
    // (20 N/mm, the simulator's former default mount) whose true k is 1.3 x 1e-4 mm^2/N, a
    // 10 MPa abrasive at 5000 rpm (the simulator's former default tool), on an ideal arm (a
    // 20 N/mm mount turns the documented arm's 1 mm tip errors into 20 N); the removal loop
    // (now the default mode) is the two-case test below. The cell's compliance table is this
    // arm's own, as on a real cell: `calibrate compliance` measured on the simulated ideal arm
    // (the shipped table was learned on the documented arm; planning this arm with it bent the
    // commands against a sag the arm does not have and cut to -0.393 mm, and `calibrate
    // verify` refuses it on this arm: tests/compliance.rs); the compensation stays on, as by
    // default. The burr gives along the normal as the former mount did.
    let cfg = rigid_loop_settings(&dir);
    let out = cycle(&dir, "cycle")
        .args([
            "--sim",
            "--mode",
            "rigid",
            "--max-iterations",
            "2",
            "--config",
        ])
        .arg(&cfg)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    let code = out.status.code();
    assert!(
        code == Some(0) || code == Some(4),
        "{code:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    the_folders_and_the_table(&dir, code, &stdout);

    // against the simulator's truth: every bump's peak fell in the first grind and did not
    // rise in the second; the pits were never touched
    let (first, pits1) = truth_scores(&dir, &truth, 1);
    println!("iteration 1 p90 before/after per bump: {first:.4?}");
    for (b, a) in &first {
        assert!(
            a < &(b - FIRST_DROP_MM),
            "a bump was not ground: {b} -> {a}"
        );
    }
    let mut pits = pits1;
    if dir.join("cycle/iter-2/after_truth.ply").is_file() {
        let (second, pits2) = truth_scores(&dir, &truth, 2);
        println!("iteration 2 p90 before/after per bump: {second:.4?}");
        for ((_, a1), (_, a2)) in first.iter().zip(&second) {
            assert!(*a2 <= a1 + RESCAN_MARGIN_MM, "a peak rose: {a1} -> {a2}");
        }
        pits = pits.max(pits2);
    }
    assert_eq!(pits, 0.0, "a pit was ground");
    // no core point is more than the tolerance below nominal after the first grind, away
    // from the planted pits. NOT asserted after the second: there the rigid layers over-grind
    // (measured on this case, seed 4: -0.103 mm, twice the tolerance, at the flank of the
    // 0.44 mm bump 0.9 mm from its centre, a new pit region in iter-3): issue 29's acceptance
    // needs the removal planner (branch wire), reported to the lead
    let worst = lowest_away_from_pits(&dir, &truth);
    println!("lowest core point away from pits: {worst:.4} mm");
    assert!(worst >= -0.05, "over-ground: {worst} mm (tolerance 0.05)");

    // a real arm: the next scan's path comes on stdin (here the fake I2C board of the
    // link tests, and the sim's rescan as "the next scan")
    a_real_arm_takes_the_next_scan_on_stdin(&dir);
}

/// The rigid loop's settings in `dir` (cycle.toml; see the loop's test): the simulated ideal
/// arm's own compliance table, fitted by `calibrate compliance --sim` into `own-cell`, for plan
/// and run, and the stiff burr of true k 1.3 x 1e-4 mm^2/N on the ideal arm.
fn rigid_loop_settings(dir: &Path) -> std::path::PathBuf {
    let own = dir.join("own-cell");
    std::fs::create_dir_all(&own).unwrap();
    let arm = dir.join("ideal-arm.toml");
    std::fs::write(&arm, "[sim.grinding]\nideal_arm = true\n").unwrap();
    let fit = common::polishbot()
        .args(["calibrate", "compliance", "--sim", "--cell"])
        .arg(common::calib(""))
        .arg("--out")
        .arg(&own)
        .arg("--config")
        .arg(&arm)
        .output()
        .unwrap();
    println!("{}", String::from_utf8_lossy(&fit.stdout));
    assert!(
        fit.status.success(),
        "{}",
        String::from_utf8_lossy(&fit.stderr)
    );
    let servos = own.join("servos.toml");
    let cfg = dir.join("cycle.toml");
    std::fs::write(
        &cfg,
        format!(
            "[plan.robot]\nservos = {servos:?}\n[run.robot]\nservos = {servos:?}\n\
             [run.sim.grinding]\npreston_k = 1e-4\nk_factor = 1.3\nspring_rate_n_mm = 20.0\n\
             modulus_mpa = 10.0\nspindle_rpm = 5000.0\nideal_arm = true\n\
             compliance_direction = \"surface_normal\"\n"
        ),
    )
    .unwrap();
    cfg
}

/// The loop's folders in `dir` (each grind's inspection, plan, journal and rescan), its table in
/// cycle.html (a row per inspection, no script) and on stdout, and the outcome `code` as the
/// page says it.
fn the_folders_and_the_table(dir: &Path, code: Option<i32>, stdout: &str) {
    for f in [
        "inspection/regions.json",
        "plan.json",
        "journal.jsonl",
        "after.ply",
    ] {
        assert!(dir.join("cycle/iter-1").join(f).is_file(), "iter-1/{f}");
    }
    assert!(dir.join("cycle/iter-2/inspection/deviations.csv").is_file());
    let html = std::fs::read_to_string(dir.join("cycle/cycle.html")).unwrap();
    let rows = html.matches("<tr><td>").count();
    let iterations = (1..=3)
        .filter(|k| dir.join(format!("cycle/iter-{k}/inspection")).is_dir())
        .count();
    assert_eq!(rows, iterations, "{html}");
    assert!(!html.contains("<script"));
    assert!(
        stdout.contains("residual pred/achieved mm"),
        "no table on stdout"
    );
    assert_eq!(code == Some(0), html.contains("Outcome: within tolerance."));
}

/// The lowest core point of the second inspection (iter-2's deviations.csv) away from the
/// planted pits of `truth`, mm.
fn lowest_away_from_pits(dir: &Path, truth: &polishbot::synth::Truth) -> f64 {
    let last = dir.join("cycle/iter-2/inspection/deviations.csv");
    let text = std::fs::read_to_string(last).unwrap();
    let head: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = head.iter().position(|h| *h == "distance").unwrap();
    let near_pit = |p: &Point3<f64>| {
        truth.defects.iter().any(|d| {
            d.kind == DefectKind::Pit
                && (Point3::from(d.centre) - p).norm() < footprint(d.width, d.length) + 1.0
        })
    };
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse::<f64>()).collect::<Vec<_>>())
        .filter_map(|v| {
            let p = Point3::new(
                *v[0].as_ref().ok()?,
                *v[1].as_ref().ok()?,
                *v[2].as_ref().ok()?,
            );
            let d = *v[col].as_ref().ok()?;
            (!near_pit(&p) && d.is_finite()).then_some(d)
        })
        .fold(f64::INFINITY, f64::min)
}

/// A real arm (the fake I2C board of the link tests, the sim's rescan as "the next scan"): the
/// loop asks for the next scan's path on stdin, tells the operator which setups and table
/// angles see the ground area, and inspects the file it is given.
fn a_real_arm_takes_the_next_scan_on_stdin(dir: &Path) {
    let mut child = cycle(dir, "real")
        .args(["--i2c", "/dev/i2c-fake", "--max-iterations", "1"])
        .env("POLISHBOT_TEST_FAKE_I2C", dir.join("i2c.log"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let next = dir.join("cycle/iter-1/after.ply");
    writeln!(child.stdin.take().unwrap(), "{}", next.display()).unwrap();
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(
        stdout.contains("enter each scan file's path"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // the operator is told which setups and table angles see the ground area (issue 53)
    assert!(
        stdout.contains("cycle: rescan the ground area: "),
        "{stdout}"
    );
    assert!(stdout.contains(&format!("inspect {}", next.display())));
    assert!(dir.join("real/iter-2/inspection/regions.json").is_file());
    assert!(!dir.join("real/iter-1/after.ply").exists());
}

/// The first two of the ten cases in the suite, with the parts of the issue's acceptance that
/// hold today: k is refitted after the first grind, the first grind removes at least
/// `min_progress` of the repairable excess volume, no core point where the cell ground is
/// measured more than the tolerance below nominal on any re-inspection (10 of the ten: the
/// lowest -0.008..-0.018 mm), the pits are never ground, the first pass is re-predicted at the
/// fitted k in cycle.json. NOT asserted (measured, reported to the lead): every repairable
/// region's reachable area within tolerance after 3 grinds (3 of the 10 cases; 4-67 points
/// above it in the others), the re-prediction within 0.01 mm RMS (0.015-0.036 mm).
/// Asserted: what the second grind did not touch kept its place (one virtual part).
#[test]
fn two_acceptance_cases_refit_k_grind_down_and_leave_the_pits() {
    for seed in [1, 21] {
        // the cell's default, documented arm (issue 50's acceptance), which the shipped
        // servos.toml's `[compliance]` table the planner compensates with was learned on. On
        // the ideal arm that table bends the commands against a sag the arm does not have:
        // seed 21's first grind landed 0.7-1.4 mm off (depth scale up to 1.96) and cut a
        // 6-point pit to -0.079 mm (with compensation off there: -0.010 mm)
        let a = acceptance(seed);
        let (first, second) = (a.inspections[0], a.inspections[1]);
        assert!(a.k_ratio.is_some(), "seed {seed}: k not refitted");
        // the first pass re-predicted at the fitted k, compared with what it achieved
        let [plan_k, fitted_k, achieved, _] = a.agreement.expect("no agreement in cycle.json");
        assert!(
            plan_k > 0.0 && fitted_k > 0.0 && achieved > 0.0,
            "{:?}",
            a.agreement
        );
        assert!(
            second.volume < first.volume * (1.0 - polishbot::cycle::DEFAULT_MIN_PROGRESS),
            "seed {seed}: volume {} -> {}",
            first.volume,
            second.volume
        );
        assert_eq!(a.on_pits, 0.0, "seed {seed}: a pit was ground");
        let over: Vec<f64> = a.inspections.iter().map(|i| i.lowest_ground).collect();
        assert!(
            over.iter().all(|&low| low >= -TOLERANCE_MM),
            "seed {seed}: ground below the tolerance, lowest per inspection {over:?}"
        );
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("accept-{seed}"));
        let (n, drift) = untouched_drift(&dir, 2);
        assert!(
            n > 1000 && drift < 1e-9,
            "seed {seed}: {n} untouched, drift {drift} mm"
        );
        println!("seed {seed}: issue acceptance met: {}", accepted(&a));
    }
}

/// All ten cases of the issue (seeds 1, 21, .., 181: each `case` tries 20 seeds from its
/// own); slow, run by hand: `cargo test --release --test cycle -- --ignored ten`; a subset
/// with `POLISHBOT_ACCEPT_SEEDS=61,81` (seed 41's second plan ran over 20 min, issue 29);
/// `POLISHBOT_ACCEPT_GRINDS=4` allows that many grinds instead of the cycle's default 3;
/// `POLISHBOT_ACCEPT_FOOTPRINT=0.6` passes `--footprint-radius 0.6` (the surveys too);
/// `POLISHBOT_ACCEPT_SIM="pressure_exponent = 1.0; k_noise = 0.0"` adds `[sim.grinding]` keys
/// (docs/ALGORITHMS.md, "The acceptance cases": what each part of the truth costs).
#[test]
#[ignore]
fn ten_acceptance_cases_with_the_removal_planner() {
    let seeds: Vec<u64> = match std::env::var("POLISHBOT_ACCEPT_SEEDS") {
        Ok(list) => list.split(',').map(|s| s.trim().parse().unwrap()).collect(),
        Err(_) => (0..10).map(|c| 1 + 20 * c).collect(),
    };
    let results: Vec<(u64, bool)> = seeds
        .into_iter()
        .map(|s| {
            let a = acceptance(s);
            println!("seed {s}: k after each grind / true k: {:.3?}", a.k_ratios);
            (s, accepted(&a))
        })
        .collect();
    println!("accepted: {results:?}");
}

/// Issue 50's acceptance table: the ten cases x three cell seeds (`[sim.grinding] seed` 29,
/// the simulator's default, 30 and 31: the cell's k variation field and its rescans), on the
/// cell's documented arm and then on the ideal arm (`common::survey::IDEAL`), two runs at a
/// time, each row scored against the noise-free truth and appended to the table file as it
/// ends. Slow (about an hour per arm), run by hand, one command:
/// `nice cargo test --release --test cycle -- --ignored thirty --nocapture`
/// The table goes to `POLISHBOT_SURVEY_OUT` (default target/tmp/survey.md); `POLISHBOT_SURVEY_ARMS`
/// = `documented`, `ideal` or both (default `documented,ideal`); `POLISHBOT_SURVEY_JOBS` runs
/// at a time (default 2); `POLISHBOT_SURVEY_CELLS` and `POLISHBOT_ACCEPT_SEEDS` other cell
/// seeds and cases; `POLISHBOT_SURVEY_KEEP=1` keeps each run's folder
/// (target/tmp/survey-ARM-CASE-CELL), `POLISHBOT_ACCEPT_GOUGED=1` writes its gouged true
/// points there (`gouged.csv`). Fails unless the issue's acceptance holds on the
/// documented arm: at least 27 of 30 runs with 99 % of the area within tolerance, and in every
/// run no true ground point below -tolerance, no pit ground and k within 10 %.
#[test]
#[ignore]
fn thirty_acceptance_runs_on_the_documented_and_the_ideal_arm() {
    use common::survey::{survey, DOCUMENTED, IDEAL};
    let list = |key: &str, default: Vec<u64>| match std::env::var(key) {
        Ok(list) => list.split(',').map(|s| s.trim().parse().unwrap()).collect(),
        Err(_) => default,
    };
    let cases = list(
        "POLISHBOT_ACCEPT_SEEDS",
        (0..10).map(|c| 1 + 20 * c).collect(),
    );
    let cells = list("POLISHBOT_SURVEY_CELLS", vec![29, 30, 31]);
    let jobs = std::env::var("POLISHBOT_SURVEY_JOBS").map_or(2, |j| j.parse().unwrap());
    let out = std::env::var_os("POLISHBOT_SURVEY_OUT").map_or_else(
        || Path::new(env!("CARGO_TARGET_TMPDIR")).join("survey.md"),
        std::path::PathBuf::from,
    );
    let arms = std::env::var("POLISHBOT_SURVEY_ARMS").unwrap_or("documented,ideal".into());
    let mut documented = None;
    for arm in [DOCUMENTED, IDEAL] {
        if arms.split(',').any(|a| a.trim() == arm.name) {
            let runs = survey(arm, &cases, &cells, jobs, &out);
            println!("{} arm: {}", arm.name, common::survey::summary(&runs));
            if arm.name == DOCUMENTED.name {
                documented = Some(runs);
            }
        }
    }
    println!("table: {}", out.display());
    if let Some(runs) = documented {
        assert!(
            common::survey::issue_met(&runs),
            "issue 50's acceptance not met on the documented arm: {} ({})",
            common::survey::summary(&runs),
            out.display()
        );
    }
}

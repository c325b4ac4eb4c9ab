//! The closed scan-grind-rescan loop (issue 29, `polishbot cycle`): its stop rule on
//! hand-made records, plan.json's optional prediction read, and the loop end to end on a
//! synthetic part whose defects the arm reaches, scored against the simulator's own truth
//! (`after_truth.ply`: the removal per point) and the planted defects (synth's truth).
mod common;

use std::io::Write;
use std::path::Path;
use std::process::Stdio;

use nalgebra::Point3;
use polishbot::cell::cycle::{
    decide, decide_plan, CycleConfig, IterationRecord, Measured, Outcome, PlanSummary,
};
use polishbot::regions::Verdict;
use polishbot::spatial::Neighbours;
use polishbot::synth::{synth_at, DefectKind, SynthConfig, Truth};

use common::polishbot;

fn measured(verdict: Verdict, repairable: usize, pits: usize, volume: f64) -> Measured {
    Measured {
        verdict,
        repairable,
        pits,
        peak_mm: (repairable > 0).then_some(0.2),
        rms_mm: (repairable > 0).then_some(0.1),
        volume_mm3: volume,
    }
}

/// A record that was ground: planned `planned` mm^3, the next inspection found `progress`
/// of it removed.
fn ground(k: usize, volume: f64, planned: f64, progress: f64) -> IterationRecord {
    let mut r = IterationRecord::new(k, measured(Verdict::Repairable, 2, 0, volume));
    r.planned_volume_mm3 = Some(planned);
    r.progress = Some(progress);
    r
}

#[test]
fn the_stop_rule_ends_within_tolerance_on_no_progress_and_after_the_last_iteration() {
    let cfg = CycleConfig {
        max_iterations: 2,
        min_progress: 0.05,
    };
    let fresh = |v| IterationRecord::new(9, measured(Verdict::Repairable, 2, 0, v));
    // a first inspection with excess: grind
    assert_eq!(decide(&[fresh(1.0)], &cfg), Outcome::Continue);
    // within tolerance wins over everything, even with no progress and iterations used up
    let done = IterationRecord::new(3, measured(Verdict::WithinTolerance, 0, 0, 0.0));
    let recs = [ground(1, 1.0, 1.0, 0.9), ground(2, 0.1, 0.1, 0.0), done];
    assert_eq!(decide(&recs, &cfg), Outcome::WithinTolerance);
    // 4 % of the planned volume removed, under 5 %: no progress
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 0.04), fresh(0.96)], &cfg),
        Outcome::NoProgress
    );
    // 6 % removed goes on; after 2 grinds the iterations are used up
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 0.06), fresh(0.94)], &cfg),
        Outcome::Continue
    );
    let two = [
        ground(1, 1.0, 1.0, 0.5),
        ground(2, 0.5, 0.5, 0.5),
        fresh(0.25),
    ];
    assert_eq!(decide(&two, &cfg), Outcome::MaxIterations);
    // only pits left: nothing to grind
    let pits = IterationRecord::new(2, measured(Verdict::Reject, 0, 1, 0.0));
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 1.0), pits], &cfg),
        Outcome::NothingToGrind
    );
    // a plan that grinds none of the excess
    let mut unreachable = fresh(1.0);
    unreachable.planned_volume_mm3 = Some(0.0);
    assert_eq!(decide_plan(&unreachable), Outcome::NothingPlanned);
    assert_eq!(decide_plan(&ground(1, 1.0, 1.0, 0.5)), Outcome::Continue);
    assert!(CycleConfig {
        max_iterations: 0,
        ..cfg
    }
    .check()
    .is_err());
    assert!(CycleConfig {
        min_progress: 1.5,
        ..cfg
    }
    .check()
    .is_err());
}

#[test]
fn a_rigid_plan_has_no_prediction_and_a_removal_plan_predicts_the_weighted_rms() {
    let rigid: PlanSummary = serde_json::from_str(
        r#"{"frames": [], "reachability": {"regions": [
            {"id": 0, "layers": 2}, {"id": 1, "layers": 0}, {"id": 2, "layers": 1}]}}"#,
    )
    .unwrap();
    assert_eq!(rigid.planned(), vec![0, 2]);
    assert_eq!(rigid.predicted_rms(), None);
    // removal mode (issue 28's plan.json): rms over 1 + 3 points of 0.02 and 0.04 mm is
    // sqrt((0.02^2 + 3 x 0.04^2) / 4) = sqrt(0.0013)
    let removal: PlanSummary = serde_json::from_str(
        r#"{"reachability": {"regions": [{"id": 0}, {"id": 1}]},
            "removal": {"force_n": 2.0, "regions": [
              {"region": 0, "core_points": 1, "after": {"rms_mm": 0.02, "peak_mm": 0.1}},
              {"region": 1, "core_points": 3, "after": {"rms_mm": 0.04, "peak_mm": 0.1}}]}}"#,
    )
    .unwrap();
    assert_eq!(removal.planned(), vec![0, 1]);
    let p = removal.predicted_rms().unwrap();
    assert!((p - 0.0013f64.sqrt()).abs() < 1e-12, "{p}");
}

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

/// Seeds tried from the one given until synth places all 5 defects (some seeds place only 4
/// clear of the edges and of each other where the arm reaches).
const SEED_TRIES: u64 = 20;

/// The issue's case: 5 defects (0.08-0.5 mm) where the arm reaches, a fifth of them pits;
/// the first seed from `seed` on that places all five.
fn case(seed: u64, dir: &Path) -> Truth {
    let reachable = polishbot::cell::reachable_sites().unwrap();
    let make = |seed| SynthConfig {
        seed,
        defects: 5,
        height_range: [0.08, 0.5],
        width_range: [2.0, 4.0],
        pit_share: 0.2,
        reference_points: 200_000,
        scan_points: 150_000,
        ..SynthConfig::default()
    };
    let case = (seed..seed + SEED_TRIES)
        .find_map(|s| synth_at(&make(s), &reachable).ok())
        .expect("a seed that places 5 defects");
    println!("synth seed {}", case.truth.seed);
    case.write(dir).unwrap();
    case.truth
}

/// The planted defect's footprint radius on the surface, mm (as demo's summary matches).
fn footprint(width: f64, length: f64) -> f64 {
    width + length / 2.0
}

/// Signed distance of each point to the reference cloud (nearest point's normal), mm.
fn true_deviation(reference: &polishbot::cloud::PointCloud, points: &[Point3<f64>]) -> Vec<f64> {
    let index = Neighbours::new(&reference.points);
    let normals = reference.normals.as_ref().unwrap();
    points
        .iter()
        .map(|p| {
            let nb = index.nearest(p).unwrap();
            normals[nb.index].dot(&(p - reference.points[nb.index]))
        })
        .collect()
}

/// 90th percentile of `v` (None when empty).
fn p90(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[(v.len() - 1) * 9 / 10])
}

/// Per planted bump or ridge: the 90th percentile of the true deviation over the points of
/// its central part (half its footprint) before and after one iteration's grind, from that
/// iteration's truth file (the removal per point); and the largest removal on any pit.
fn truth_scores(dir: &Path, truth: &Truth, iter: usize) -> (Vec<(f64, f64)>, f64) {
    let reference = polishbot::cloud::load_cloud(&dir.join("reference.ply"), None, None).unwrap();
    let file = dir.join(format!("cycle/iter-{iter}/after_truth.ply"));
    let ground = polishbot::cloud::load_cloud(&file, None, None).unwrap();
    let removal = ground.field("removal").unwrap();
    let dev = true_deviation(&reference, &ground.points);
    let mut peaks = Vec::new();
    let mut on_pits: f64 = 0.0;
    for d in &truth.defects {
        let c = Point3::from(d.centre);
        let r = footprint(d.width, d.length);
        let inside: Vec<usize> = (0..ground.len())
            .filter(|&i| (ground.points[i] - c).norm() < r)
            .collect();
        if d.kind == DefectKind::Pit {
            on_pits = inside.iter().map(|&i| removal[i]).fold(on_pits, f64::max);
            continue;
        }
        let centre: Vec<usize> = (0..ground.len())
            .filter(|&i| (ground.points[i] - c).norm() < r / 2.0)
            .collect();
        let after = p90(centre.iter().map(|&i| dev[i]).collect()).unwrap();
        let before = p90(centre.iter().map(|&i| dev[i] + removal[i]).collect()).unwrap();
        peaks.push((before, after));
    }
    (peaks, on_pits)
}

/// Least drop of a planted bump's true peak (p90) in the first grind, mm: the rigid layers
/// at k 1.3 x nominal take 0.04-0.1 mm off (42 % of the demo's excess volume in its first
/// pass), so 0.01 mm (two thirds of the scan noise) tells a ground defect from a missed one.
const FIRST_DROP_MM: f64 = 0.01;
/// Noise margin when comparing a peak across two rescans (different points), mm: the p90 of a
/// few hundred points with 0.015 mm scanner noise moves by about this much between rescans.
const RESCAN_MARGIN_MM: f64 = 0.01;

/// `cycle` on the case in `dir` (reference.ply, scan.ply) into `dir/out`.
fn cycle(dir: &Path, out: &str) -> std::process::Command {
    let mut cmd = polishbot();
    cmd.arg("cycle")
        .arg("--reference")
        .arg(dir.join("reference.ply"))
        .arg("--scan")
        .arg(dir.join("scan.ply"))
        .arg("-o")
        .arg(dir.join(out));
    cmd
}

#[test]
fn the_loop_grinds_the_reachable_defects_down_over_iterations_and_leaves_the_pits() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cycle");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let truth = case(3, &dir);
    // the simulator's true k 1.3 x the planner's (issue 29's "30 % off")
    let cfg = dir.join("cycle.toml");
    std::fs::write(&cfg, "[run.sim.grinding]\nk_factor = 1.3\n").unwrap();
    let out = cycle(&dir, "cycle")
        .args(["--sim", "--max-iterations", "2", "--config"])
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
    // the folders and the table
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
    let worst = text
        .lines()
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
        .fold(f64::INFINITY, f64::min);
    println!("lowest core point away from pits: {worst:.4} mm");
    assert!(worst >= -0.05, "over-ground: {worst} mm (tolerance 0.05)");

    // a real arm: the next scan's path comes on stdin (here the fake I2C board of the
    // link tests, and the sim's rescan as "the next scan")
    let mut child = cycle(&dir, "real")
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
        stdout.contains("enter the scan file's path"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains(&format!("inspect {}", next.display())));
    assert!(dir.join("real/iter-2/inspection/regions.json").is_file());
    assert!(!dir.join("real/iter-1/after.ply").exists());
}

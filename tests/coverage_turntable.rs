//! Turntable scans and setups: views merged by the table's axis and centre are measured where
//! they were seen, and two setups inspected together measure the articular surface (issues 36
//! and 53).
mod common;

use std::path::Path;

use nalgebra::Point3;
use polishbot::cloud::{self, PointCloud};
use polishbot::regions::{Regions, Verdict, SMALLEST_DEFECT_MM};
use polishbot::synth::Truth;

/// Scores of one turntable case: on the measured given core points IoU, the largest error
/// against truth on all measured core points, and per defect taller than the tolerance
/// whether a region found it, or a region near it touches an unmeasured area, or its centre
/// is unmeasured.
#[derive(Debug)]
struct TurntableScore {
    iou: f64,
    worst: f64,
    /// The largest error outside the support of defects narrower than the smallest defect
    /// the verdict must see (`SMALLEST_DEFECT_MM`, 2 mm): the error judged at the
    /// resolution the inspection promises (a 0.52 mm wide pit is averaged by any cylinder
    /// of the smallest radius, about 0.6 mm: it reads under a third of its depth).
    worst_resolved: f64,
    /// Defects narrower than that and taller than the tolerance, and how many of them a
    /// region found.
    narrow: usize,
    narrow_found: usize,
    coverage: f64,
    found: usize,
    touching: usize,
    unseen: usize,
    missed: usize,
}

/// `synth --views 12` of the parametric part with noise along the line of sight, merged by
/// `merge` with the table's axis and centre, then `inspect` (with its own registration).
fn turntable_case(seed: u64) -> TurntableScore {
    let dir = common::tempdir();
    let d = dir.path();
    let cfg = d.join("synth.toml");
    std::fs::write(&cfg, "[turntable]\nline_of_sight_noise = true\n").unwrap();
    let seed_arg = seed.to_string();
    common::succeed(
        common::polishbot()
            .arg("--config")
            .arg(&cfg)
            .args(["synth", "--out"])
            .arg(d)
            .args(["--views", "12", "--seed", &seed_arg]),
    );
    let views: Vec<String> = (0..12)
        .map(|i| d.join(format!("view_{i:03}.ply")).display().to_string())
        .collect();
    let merged = d.join("merged.ply");
    common::succeed(
        common::polishbot()
            .arg("merge")
            .args(&views)
            .args([
                "--step", "30", "--axis", "0,0,1", "--centre", "4,-3,0", "-o",
            ])
            .arg(&merged),
    );
    let insp = d.join("inspection");
    let out = common::inspect_cmd(&d.join("reference.ply"), &merged, None, &insp)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        matches!(out.status.code(), Some(0) | Some(3)),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth = Truth::load(&d.join("truth.json")).unwrap();
    let dev = cloud::load_cloud(&insp.join("deviations.ply"), None, None).unwrap();
    let regions: Regions =
        serde_json::from_str(&std::fs::read_to_string(insp.join("regions.json")).unwrap()).unwrap();
    score_turntable(&dev, &regions, &truth, &stdout)
}

fn score_turntable(
    dev: &PointCloud,
    regions: &Regions,
    truth: &Truth,
    stdout: &str,
) -> TurntableScore {
    let tol = regions.tolerance;
    let col = |name: &str| dev.field(name).expect(name).to_vec();
    let (distance, lod, region) = (col("distance"), col("uncertainty"), col("region"));
    let normals = dev.normals.as_ref().expect("normals");
    let truth_at: Vec<f64> = (0..dev.len())
        .map(|i| truth.deviation_at(&dev.points[i], &normals[i]))
        .collect();
    // The given core points are the first rows: the summary line counts those added.
    let added: usize = stdout
        .split(" added around defects")
        .next()
        .and_then(|s| s.rsplit('(').next())
        .and_then(|s| s.trim().parse().ok())
        .expect("added count");
    let given = dev.len() - added;
    let measured = |i: usize| distance[i].is_finite();
    let (mut both, mut either) = (0, 0);
    for i in (0..given).filter(|&i| measured(i)) {
        let t = truth_at[i].abs() > tol;
        let found = distance[i].abs() > lod[i] && distance[i].abs() > tol;
        both += usize::from(t && found);
        either += usize::from(t || found);
    }
    let worst = (0..dev.len())
        .filter(|&i| measured(i))
        .map(|i| (distance[i] - truth_at[i]).abs())
        .fold(0.0, f64::max);
    let narrow: Vec<_> = (truth.defects.iter())
        .filter(|d| d.width < SMALLEST_DEFECT_MM)
        .collect();
    let outside_narrow = |i: usize| {
        (narrow.iter()).all(|d| (dev.points[i] - Point3::from(d.centre)).norm() > d.support())
    };
    let worst_resolved = (0..dev.len())
        .filter(|&i| measured(i) && outside_narrow(i))
        .map(|i| (distance[i] - truth_at[i]).abs())
        .fold(0.0, f64::max);
    let mut score = TurntableScore {
        iou: both as f64 / either.max(1) as f64,
        worst,
        worst_resolved,
        narrow: 0,
        narrow_found: 0,
        coverage: regions.coverage,
        found: 0,
        touching: 0,
        unseen: 0,
        missed: 0,
    };
    for defect in truth.defects.iter().filter(|d| d.height.abs() > tol) {
        let c = Point3::from(defect.centre);
        let near = |i: &usize| (dev.points[*i] - c).norm() < defect.support();
        let ids: Vec<usize> = (0..dev.len())
            .filter(near)
            .filter(|&i| region[i] >= 0.0)
            .collect();
        let nearest = (0..dev.len())
            .min_by(|&a, &b| {
                (dev.points[a] - c)
                    .norm()
                    .total_cmp(&(dev.points[b] - c).norm())
            })
            .unwrap();
        if defect.width < SMALLEST_DEFECT_MM {
            score.narrow += 1;
            score.narrow_found += usize::from(!ids.is_empty());
        }
        if ids
            .iter()
            .any(|&i| !regions.regions[region[i] as usize].touches_unmeasured)
        {
            score.found += 1;
        } else if !ids.is_empty() {
            score.touching += 1;
        } else if !measured(nearest) {
            score.unseen += 1;
        } else {
            score.missed += 1;
        }
    }
    score
}

/// The acceptance case of issue 36 (seeds: POLISHBOT_TURNTABLE_SEEDS, comma-separated;
/// default seeds 1 and 4: seed 4 failed before the peak models read the noise of a merged
/// scan's tail, IoU 0.838 → 0.971): on measured core points IoU >= 0.96 and no error above
/// 0.2 mm; every defect taller than the tolerance found, or its region marked as touching an
/// unmeasured area, or lying in one.
#[test]
fn turntable_views_are_measured_where_seen() {
    let seeds: Vec<u64> = std::env::var("POLISHBOT_TURNTABLE_SEEDS")
        .map(|s| {
            s.split(',')
                .map(|t| t.trim().parse().expect("seed"))
                .collect()
        })
        .unwrap_or_else(|_| vec![1, 4]);
    for seed in seeds {
        let s = turntable_case(seed);
        eprintln!("seed {seed}: coverage {:.3}, {s:?}", s.coverage);
        assert!(s.iou >= 0.96, "seed {seed}: {s:?}");
        assert!(s.worst <= 0.2, "seed {seed}: {s:?}");
        assert_eq!(s.missed, 0, "seed {seed}: {s:?}");
    }
}

/// Runs `cmd`, asserting it succeeds (or, with `incomplete`, ends "incomplete", exit 3), and
/// returns its stdout.
fn run_ok(cmd: &mut std::process::Command, incomplete: bool) -> String {
    let out = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let want = if incomplete { 3 } else { 0 };
    assert_eq!(
        out.status.code(),
        Some(want),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// `synth --views 12 --setups 2 --elevation 35` into `d`, each setup's views merged on its own
/// (`merged.ply`, `setup2_merged.ply`) and both setups' joined by `merge --setups`
/// (`joined.ply`); returns the two merged scans and the joined one.
fn two_setups_merged(d: &Path) -> (Vec<std::path::PathBuf>, std::path::PathBuf) {
    let cfg = d.join("synth.toml");
    std::fs::write(&cfg, "[turntable]\nline_of_sight_noise = true\n").unwrap();
    run_ok(
        common::polishbot()
            .arg("--config")
            .arg(&cfg)
            .args(["synth", "--out"])
            .arg(d)
            .args(["--views", "12", "--setups", "2", "--elevation", "35"])
            .args(["--view-points", "30000", "--reference-points", "200000"])
            .args(["--scan-points", "1000", "--seed", "1"]),
        false,
    );
    let table = ["--axis", "0,0,1", "--centre", "4,-3,0"];
    let views = |prefix: &str| -> Vec<_> {
        (0..12)
            .map(|i| d.join(format!("{prefix}view_{i:03}.ply")))
            .collect()
    };
    let merged: Vec<_> = ["", "setup2_"]
        .iter()
        .map(|prefix| {
            let out = d.join(format!("{prefix}merged.ply"));
            run_ok(
                common::polishbot()
                    .arg("merge")
                    .args(views(prefix))
                    .args(["--step", "30"])
                    .args(table)
                    .arg("-o")
                    .arg(&out),
                false,
            );
            out
        })
        .collect();
    let joined = d.join("joined.ply");
    let stdout = run_ok(
        common::polishbot()
            .arg("merge")
            .args(views(""))
            .args(views("setup2_"))
            .arg("--setups")
            .arg(d.join("turntable.json"))
            .arg("--reference")
            .arg(d.join("reference.ply"))
            .args(table)
            .arg("-o")
            .arg(&joined),
        false,
    );
    assert!(stdout.contains("merge: 2 setups"), "{stdout}");
    (merged, joined)
}

/// Issue 53's case in the suite: `synth --views 12 --setups 2 --elevation 35` (the scanner
/// 35 degrees above the table; setup 2 the part turned over), small views (30,000 points).
/// One setup alone (merged) measures 58-80 % of synth's articular surface (articular.ply),
/// as the held-out femoral views of the issue do, is incomplete, its report pictures the
/// unmeasured area, and the suggested views ask for a second setup for all but under 5 % of
/// the area to inspect. Then, judged at the resolution the inspection promises (errors
/// outside defects narrower than 2 mm; those must be found):
/// - one setup plus the suggested views (the second setup, merged on its own;
///   `inspect --scan A --scan B`);
/// - both setups' 24 views joined by `merge --setups turntable.json --reference` (each setup
///   merged, joined through its registration onto the reference), inspected as one scan;
///
/// each measures at least 95 % of the area, with IoU >= 0.96 on measured core points, no
/// error above 0.2 mm, and a verdict; deviations.ply says that both scans supported core
/// points.
#[test]
fn two_setups_inspected_together_measure_the_articular_surface() {
    let dir = common::tempdir();
    let d = dir.path();
    let (merged, joined) = two_setups_merged(d);
    let inspect = |scans: &[std::path::PathBuf], out: &Path, incomplete: bool| {
        let mut cmd = common::polishbot();
        cmd.arg("inspect")
            .arg("--reference")
            .arg(d.join("reference.ply"));
        for s in scans {
            cmd.arg("--scan").arg(s);
        }
        cmd.arg("--inspect-area").arg(d.join("articular.ply"));
        run_ok(cmd.arg("-o").arg(out), incomplete)
    };
    let truth = Truth::load(&d.join("truth.json")).unwrap();
    let score = |insp: &Path, stdout: &str| {
        let dev = cloud::load_cloud(&insp.join("deviations.ply"), None, None).unwrap();
        let text = std::fs::read_to_string(insp.join("regions.json")).unwrap();
        let regions: Regions = serde_json::from_str(&text).unwrap();
        (
            score_turntable(&dev, &regions, &truth, stdout),
            regions,
            dev,
        )
    };
    // One setup: 58-80 % measured; the suggestion asks for a second setup for all but under
    // 5 % of the area, and the report shows where.
    let one = inspect(&merged[..1], &d.join("one"), true);
    let (s, _, _) = score(&d.join("one"), &one);
    eprintln!("one setup: {s:?}");
    assert!((0.58..=0.80).contains(&s.coverage), "{s:?}");
    let number_before = |text: &str, tail: &str| -> f64 {
        let head = text.split(tail).next().expect(tail);
        head.rsplit(' ').next().unwrap().parse().expect(tail)
    };
    let line = one
        .lines()
        .find(|l| l.starts_with("suggested views: "))
        .expect("suggested views");
    let unmeasured = number_before(line, " % of the area to inspect not measured");
    let other_setup = number_before(line, " % faces no table angle of this setup");
    assert!(unmeasured - other_setup < 5.0, "{line}");
    let html = std::fs::read_to_string(d.join("one/report.html")).unwrap();
    assert!(d.join("one/unmeasured.png").is_file() && html.contains("unmeasured.png"));
    assert!(html.contains("scan it in a second setup"));
    // One setup plus the suggested second setup, and both setups joined by merge.
    for (name, scans) in [("both", merged.clone()), ("joined", vec![joined.clone()])] {
        let insp = d.join(name);
        let stdout = inspect(&scans, &insp, false);
        let (s, regions, dev) = score(&insp, &stdout);
        eprintln!("{name}: {s:?}");
        assert!(s.coverage >= 0.95, "{name}: {s:?}");
        assert!(s.iou >= 0.96, "{name}: {s:?}");
        assert!(s.worst_resolved <= 0.2, "{name}: {s:?}");
        assert_eq!(s.narrow_found, s.narrow, "{name}: {s:?}");
        assert_ne!(regions.verdict, Verdict::Incomplete);
        assert!(!insp.join("unmeasured.png").exists());
        if name == "joined" {
            continue;
        }
        let support = dev.field("scans").expect("scans field");
        let measured = dev.field("measured").unwrap();
        for bit in [1.0, 2.0] {
            assert!(support.contains(&bit), "no core point of scan {bit} alone");
        }
        assert!(support
            .iter()
            .zip(measured)
            .all(|(&m, &v)| (m > 0.0) == (v == 1.0)));
    }
}

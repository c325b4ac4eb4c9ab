//! Acquisition: `polishbot merge` against the synthetic turntable truth and the real bunny.
mod common;

use std::path::Path;

use nalgebra::{
    Isometry3, Matrix3, Point3, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3,
};
use polishbot::cloud::transform::{isometry_from_rows, pose_difference};
use polishbot::cloud::Units;
use polishbot::preprocess::{estimate_normals, NormalConfig};
use serde_json::Value;

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).expect("json")).expect("parse")
}

fn rows(v: &Value) -> [[f64; 4]; 4] {
    serde_json::from_value(v.clone()).expect("4x4 rows")
}

fn merge(args: &[&str]) -> std::process::Output {
    common::polishbot()
        .arg("merge")
        .args(args)
        .output()
        .expect("run polishbot")
}

/// Runs `merge` with `args`, asserts it succeeded and returns its stdout.
fn merge_ok(args: &[&str]) -> String {
    let out = merge(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

#[test]
fn synthetic_turntable_12_views_match_truth() {
    synthetic_turntable(12, "30", "7", None);
}

#[test]
fn synthetic_turntable_36_views_match_truth() {
    synthetic_turntable(36, "10", "3", None);
}

/// The table axis tilted 20 degrees from +z towards the scanner (and no --axis given): merge
/// finds it itself.
#[test]
fn synthetic_turntable_tilted_axis_is_estimated() {
    let a = 20f64.to_radians();
    synthetic_turntable(12, "30", "5", Some([0.0, -a.sin(), a.cos()]));
}

/// `synth --views n --view-points 30000 --angle-error 3 --seed seed` into `d` (table `axis`,
/// default +z): the truth (`turntable.json`) and the view files.
fn synth_views(d: &Path, n: usize, seed: &str, axis: Option<[f64; 3]>) -> (Value, Vec<String>) {
    let views_arg = n.to_string();
    let mut synth = common::polishbot();
    if let Some(a) = axis {
        let cfg = d.join("synth.toml");
        std::fs::write(&cfg, format!("[turntable]\naxis = {a:?}\n")).unwrap();
        synth.arg("--config").arg(cfg);
    }
    let out = synth
        .args(["synth", "--out"])
        .arg(d)
        .args([
            "--views",
            &views_arg,
            "--view-points",
            "30000",
            "--angle-error",
            "3",
            "--seed",
            seed,
        ])
        .output()
        .expect("synth");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let truth = read_json(&d.join("turntable.json"));
    let files = truth["views"]
        .as_array()
        .expect("views")
        .iter()
        .map(|v| {
            d.join(v["file"].as_str().expect("file"))
                .display()
                .to_string()
        })
        .collect();
    (truth, files)
}

/// The angle tolerance is the table's accuracy a (every true angle within a of nominal, the
/// first view's too), checked on the synth truth (angles within 3 degrees): with a = 3 every
/// view is placed, none held or rejected, although corrections from the first view exceed 3.
/// Given view 11 four degrees short of its nominal angle, its own correction stays within 2a
/// but no set of true angles within a explains all corrections (they span over 2a): its
/// match is rejected and the view held.
#[test]
fn angle_tolerance_is_the_tables_accuracy() {
    let dir = common::tempdir();
    let d = dir.path();
    let (truth, files) = synth_views(d, 12, "3", None);
    let true_deg: Vec<f64> = truth["views"]
        .as_array()
        .expect("views")
        .iter()
        .map(|v| v["true_deg"].as_f64().expect("true_deg"))
        .collect();
    let correction = |i: usize, nominal: f64| true_deg[i] - true_deg[0] - nominal;
    let span = |c: &[f64]| {
        c.iter().fold(f64::MIN, |a, &b| a.max(b)) - c.iter().fold(f64::MAX, |a, &b| a.min(b))
    };
    let honest: Vec<f64> = (0..12).map(|i| correction(i, 30.0 * i as f64)).collect();
    let mut short = honest.clone();
    short[11] = correction(11, 326.0);
    // The case tests what it claims: corrections over a, within 2a, spanning over 2a.
    let largest = honest.iter().fold(0.0f64, |a, c| a.max(c.abs()));
    assert!(
        largest > 3.0 && largest <= 6.0 && span(&honest) <= 6.0,
        "{honest:?}"
    );
    assert!(short[11].abs() <= 6.0 && span(&short) > 6.0, "{short:?}");
    let out = d.join("m.ply").display().to_string();
    let mut args: Vec<&str> = files.iter().map(String::as_str).collect();
    args.extend(["--angle-tolerance", "3", "-o", &out]);
    let honest_angles = "0,30,60,90,120,150,180,210,240,270,300,330";
    let short_angles = "0,30,60,90,120,150,180,210,240,270,300,326";
    for (angles, held) in [(honest_angles, None), (short_angles, Some(11))] {
        let stdout = merge_ok(&[&args[..], &["--angles", angles]].concat());
        let report = read_json(&d.join("m.json"));
        for (i, v) in report["views"]
            .as_array()
            .expect("views")
            .iter()
            .enumerate()
        {
            let rejected = v["rejected"].as_array().expect("rejected");
            if Some(i) == held {
                assert_eq!(v["placement"], "held", "{v}");
                assert!(!rejected.is_empty(), "{v}");
                for r in rejected {
                    let c = r["correction_deg"].as_f64().unwrap();
                    let s = r["span_deg"].as_f64().unwrap();
                    assert!(c <= 6.0 && s > 6.0, "{angles}: {r}");
                }
                assert!(stdout.contains("view_011.ply: rejected"), "{stdout}");
            } else {
                assert!(
                    v["placement"] != "held" && rejected.is_empty(),
                    "{angles}: {v}"
                );
            }
        }
    }
}

/// Synth `views` views `step` degrees apart (true angles off by up to 3 degrees) about the
/// table `axis` (default +z), merge them without an axis and compare poses, axis and merged
/// surface with the synth truth.
fn synthetic_turntable(n: usize, step: &str, seed: &str, axis: Option<[f64; 3]>) {
    let dir = common::tempdir();
    let d = dir.path();
    let (truth, files) = synth_views(d, n, seed, axis);
    let tviews = truth["views"].as_array().expect("views");
    let merged = d.join("merged.ply");
    let mut args: Vec<&str> = files.iter().map(String::as_str).collect();
    let m = merged.display().to_string();
    // Each true angle is off by up to 3 degrees: the table's accuracy.
    args.extend(["--step", step, "--angle-tolerance", "3", "-o", &m]);
    let stdout = merge_ok(&args);
    assert!(
        stdout.contains("loop closure") && stdout.contains("axis ("),
        "{stdout}"
    );
    let report = read_json(&d.join("merged.json"));
    assert!(report["loop_closure"]["rotation_deg"].is_number());
    let views = report["views"].as_array().expect("views");
    assert_eq!(views.len(), n);
    for (t, v) in tviews.iter().zip(views) {
        let a = isometry_from_rows(&rows(&t["view_to_first"])).expect("truth pose");
        let b = isometry_from_rows(&rows(&v["view_to_first"])).expect("merged pose");
        let (dr, dt) = pose_difference(&a, &b);
        assert!(dr < 0.02 && dt < 0.02, "{}: {dr} deg {dt} mm", t["file"]);
    }
    global_partners_are_near_in_turn(&report, step.parse().expect("step"));
    // Axis: same direction as the truth, and the estimated centre lies on the true axis.
    let ta = Vector3::from(serde_json::from_value::<[f64; 3]>(truth["axis"].clone()).unwrap());
    let tc = Vector3::from(serde_json::from_value::<[f64; 3]>(truth["centre"].clone()).unwrap());
    let ea = Vector3::from(serde_json::from_value::<[f64; 3]>(report["axis"].clone()).unwrap());
    let ec = Vector3::from(serde_json::from_value::<[f64; 3]>(report["centre"].clone()).unwrap());
    assert!(ea.angle(&ta).to_degrees() < 0.02, "axis {ea} vs {ta}");
    if let Some(a) = axis {
        assert!(
            ta.angle(&Vector3::from(a)).to_degrees() < 1e-9,
            "synth axis {ta}"
        );
    }
    // The start axis from one pair (no --axis given) is near the truth too.
    let sa = serde_json::from_value::<[f64; 3]>(report["axis_seed"]["axis"].clone()).unwrap();
    let sa = Vector3::from(sa);
    assert!(sa.angle(&ta).to_degrees() < 0.5, "start axis {sa} vs {ta}");
    let off = ec - tc;
    assert!(
        (off - ta * off.dot(&ta)).norm() < 0.05,
        "centre {ec} off the axis"
    );
    // The merged cloud lies on the true surface: median point-to-plane distance to the
    // reference (moved into the first view's frame by the synth truth).
    let reference = polishbot::cloud::load_cloud(&d.join("reference.ply"), None, None).unwrap();
    let first = isometry_from_rows(&rows(&truth["first_from_reference"])).expect("pose");
    let ref_pts: Vec<_> = reference.points.iter().map(|p| first * p).collect();
    let ref_nrm = reference.normals.as_ref().expect("reference normals");
    let tree = polishbot::spatial::Neighbours::new(&ref_pts);
    let cloud = polishbot::cloud::load_cloud(&merged, None, None).unwrap();
    let mut dist: Vec<f64> = cloud
        .points
        .iter()
        .step_by(10)
        .map(|p| {
            let nb = tree.nearest(p).expect("neighbour");
            (first * ref_nrm[nb.index])
                .dot(&(p - ref_pts[nb.index]))
                .abs()
        })
        .collect();
    dist.sort_by(f64::total_cmp);
    let median = dist[dist.len() / 2];
    assert!(median < 0.02, "merged cloud median distance {median} mm");
    // A saved axis is accepted back (the report is a calibration file).
    let out = merge(&[
        &files[0],
        &files[1],
        "--step",
        step,
        "--calibration",
        &d.join("merged.json").display().to_string(),
        "-o",
        &d.join("pair.ply").display().to_string(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The global step seeks each view's partners among the 12 views nearest to it in turn: on a
/// turn of more views every partner is at most 7 steps away (6 steps each way, the table's
/// errors of up to 3 degrees per view may swap the 6th and the 7th); the steps' wall times
/// are reported and add up to at most the total.
fn global_partners_are_near_in_turn(report: &Value, step: f64) {
    let views = report["views"].as_array().expect("views");
    let nominal = |name: &str| {
        let v = views.iter().find(|v| v["name"] == name).expect("partner");
        v["nominal_deg"].as_f64().expect("nominal")
    };
    for v in views {
        let a = v["nominal_deg"].as_f64().expect("nominal");
        for p in v["partners"].as_array().expect("partners") {
            let d = (nominal(p.as_str().unwrap()) - a).rem_euclid(360.0);
            let gap = d.min(360.0 - d);
            assert!(
                views.len() <= 13 || gap <= 7.0 * step + 1e-9,
                "{}: partner {p} {gap} deg away",
                v["name"]
            );
        }
    }
    let t = &report["times"];
    let parts: f64 = [
        "prepare",
        "axis",
        "place",
        "loop_closure",
        "global_pairs",
        "global_solve",
        "join",
    ]
    .iter()
    .map(|k| t[k].as_f64().unwrap_or_else(|| panic!("times.{k}: {t}")))
    .sum();
    assert!(parts <= t["total"].as_f64().expect("total") + 1e-6, "{t}");
}

/// bun.conf: `bmesh FILE tx ty tz qi qj qk qr`, applied as p' = p R + t (metres).
fn bunny_truth(name: &str) -> Isometry3<f64> {
    let conf = std::fs::read_to_string(common::shared_data("bunny/bun.conf")).expect("bun.conf");
    let line = conf
        .lines()
        .find(|l| l.starts_with("bmesh") && l.contains(name))
        .expect("bmesh line");
    let v: Vec<f64> = line
        .split_whitespace()
        .skip(2)
        .map(|s| s.parse().unwrap())
        .collect();
    let q = UnitQuaternion::from_quaternion(Quaternion::new(v[6], v[3], v[4], v[5]));
    let r: Matrix3<f64> = q.to_rotation_matrix().into_inner().transpose();
    Isometry3::from_parts(
        Translation3::new(v[0] * 1e3, v[1] * 1e3, v[2] * 1e3),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}

#[test]
fn bunny_045_onto_000() {
    let dir = common::tempdir();
    let b0 = common::shared_data("bunny/bun000.ply")
        .display()
        .to_string();
    let b45 = common::shared_data("bunny/bun045.ply")
        .display()
        .to_string();
    let out_ply = dir.path().join("bun.ply").display().to_string();
    // With the nominal axis, and without (the axis then comes from the pair itself). The
    // table turned 34.3 degrees for a nominal 45: a table accuracy of 6 degrees (turns from
    // the first view within 12) admits it.
    for axis in [&["--axis", "0,-1,0"][..], &[]] {
        let rest = [
            "--angles",
            "0,45",
            "--units",
            "m",
            "--angle-tolerance",
            "6",
            "-o",
            &out_ply,
        ];
        let out = merge(&[&[b0.as_str(), b45.as_str()][..], axis, &rest].concat());
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let report = read_json(&dir.path().join("bun.json"));
        let got = isometry_from_rows(&rows(&report["views"][1]["view_to_first"])).expect("pose");
        let (dr, dt) = pose_difference(&bunny_truth("bun045.ply"), &got);
        assert!(dr < 1.0 && dt < 1.0, "bun045 {axis:?}: {dr} deg {dt} mm");
    }
}

#[test]
fn a_view_that_cannot_be_aligned_is_named_or_skipped() {
    let dir = common::tempdir();
    let b0 = common::shared_data("bunny/bun000.ply")
        .display()
        .to_string();
    let b45 = common::shared_data("bunny/bun045.ply")
        .display()
        .to_string();
    // A plane far from the bunny: nothing of it overlaps.
    let bad = dir.path().join("bad.xyz");
    let mut text = String::new();
    for i in 0..40 {
        for j in 0..40 {
            text += &format!("{} {} 5.0\n", i as f64 * 0.002, j as f64 * 0.002);
        }
    }
    std::fs::write(&bad, text).unwrap();
    let bad = bad.display().to_string();
    let out_ply = dir.path().join("m.ply").display().to_string();
    let args = [
        &b0,
        &bad,
        &b45,
        "--angles",
        "0,20,45",
        "--axis",
        "0,-1,0",
        "--units",
        "m",
        "-o",
        &out_ply,
        "--angle-tolerance",
        "12",
    ];
    let out = merge(&args);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.xyz") && err.trim().lines().count() == 1,
        "{err}"
    );
    let mut skip = args.to_vec();
    skip.push("--skip-bad");
    let out = merge(&skip);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("skipped"));
    let report = read_json(&dir.path().join("m.json"));
    assert_eq!(report["skipped"].as_array().unwrap().len(), 1);
    let got = isometry_from_rows(&rows(&report["views"][1]["view_to_first"])).expect("pose");
    let (dr, dt) = pose_difference(&bunny_truth("bun045.ply"), &got);
    assert!(
        dr < 1.0 && dt < 1.0,
        "bun045 after a skipped view: {dr} deg {dt} mm"
    );
}

/// The bunny views `names` (in `bunny/`, metres) moved by their bun.conf poses into bun000's
/// frame, with outward-free PCA normals: the true surface the merges are measured against.
fn bunny_true_surface(names: &[&str]) -> (Vec<Point3<f64>>, Vec<Vector3<f64>>) {
    let mut pts = Vec::new();
    for n in names {
        let path = common::shared_data(&format!("bunny/{n}"));
        let cloud = polishbot::cloud::load_cloud(&path, None, Some(Units::M)).expect("view");
        let pose = bunny_truth(n);
        pts.extend(cloud.points.iter().map(|p| pose * p));
    }
    let cloud = polishbot::cloud::PointCloud::from_points(pts.clone());
    let normals = estimate_normals(&cloud, &NormalConfig::default())
        .expect("normals")
        .normals;
    (pts, normals)
}

/// Median and 90th percentile of the point-to-plane distances of every 3rd point of `cloud`
/// to the true surface (nearest true point's tangent plane), mm.
fn distance_to_truth(
    cloud: &[Point3<f64>],
    truth: &(Vec<Point3<f64>>, Vec<Vector3<f64>>),
) -> [f64; 2] {
    let tree = polishbot::spatial::Neighbours::new(&truth.0);
    let mut d: Vec<f64> = cloud
        .iter()
        .step_by(3)
        .map(|p| {
            let nb = tree.nearest(p).expect("neighbour");
            truth.1[nb.index].dot(&(p - truth.0[nb.index])).abs()
        })
        .collect();
    d.sort_by(f64::total_cmp);
    [d[d.len() / 2], d[d.len() * 9 / 10]]
}

/// Merges the bunny views `names` at nominal `angles` about -y (extra arguments `extra`) and
/// returns the report and the merged points.
fn merge_bunny(names: &[&str], angles: &str, extra: &[&str]) -> (Value, Vec<Point3<f64>>, String) {
    let (dir, out) = merge_bunny_output(names, angles, extra);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out_ply = dir.path().join("bun.ply");
    let report = read_json(&dir.path().join("bun.json"));
    let cloud = polishbot::cloud::load_cloud(&out_ply, None, None).unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    (report, cloud.points, stdout)
}

/// Runs `merge` on the Stanford bunny views `names` at `angles` (about -y, metres) with `extra`
/// flags into a fresh folder (bun.ply, bun.json); returns the folder and the run's output.
fn merge_bunny_output(
    names: &[&str],
    angles: &str,
    extra: &[&str],
) -> (tempfile::TempDir, std::process::Output) {
    let dir = common::tempdir();
    let files: Vec<String> = names
        .iter()
        .map(|n| {
            common::shared_data(&format!("bunny/{n}"))
                .display()
                .to_string()
        })
        .collect();
    let out_ply = dir.path().join("bun.ply").display().to_string();
    let mut args: Vec<&str> = files.iter().map(String::as_str).collect();
    args.extend([
        "--angles", angles, "--axis", "0,-1,0", "--units", "m", "-o", &out_ply,
    ]);
    args.extend(extra);
    let out = merge(&args);
    (dir, out)
}

/// Every accepted (not held) view's correction is within the report's tolerance, and the
/// largest pose error against bun.conf over the views in `check` (degrees, mm).
fn bunny_pose_errors(report: &Value, check: &[&str]) -> [f64; 2] {
    let tol = report["angle_tolerance"].as_f64().expect("tolerance");
    let mut worst = [0.0f64; 2];
    for v in report["views"].as_array().expect("views") {
        let name = v["name"].as_str().unwrap();
        if v["placement"] != "held" {
            let c = v["correction_deg"].as_f64().unwrap();
            assert!(
                c <= tol,
                "{name} accepted with a correction of {c} deg > {tol}"
            );
        }
        if let Some(n) = check.iter().find(|n| name.ends_with(*n)) {
            let got = isometry_from_rows(&rows(&v["view_to_first"])).expect("pose");
            let (dr, dt) = pose_difference(&bunny_truth(n), &got);
            worst = [worst[0].max(dr), worst[1].max(dt)];
        }
    }
    worst
}

/// Issue 32 on the four real bunny views: 0/45/90/180 (bun045's table turned 34.3 degrees, so
/// the tolerance is 12) and 0/90/180 (45 missing: 90 degree gaps, default tolerance): every
/// pose near the Stanford registration (bun.conf) and the merged cloud within median 0.15 mm
/// and 90th percentile 0.30 mm of the truly posed views.
#[test]
fn bunny_views_with_small_and_large_gaps_match_bun_conf() {
    let four = ["bun000.ply", "bun045.ply", "bun090.ply", "bun180.ply"];
    let three = ["bun000.ply", "bun090.ply", "bun180.ply"];
    for (names, angles, extra) in [
        (&four[..], "0,45,90,180", &["--angle-tolerance", "12"][..]),
        (&three[..], "0,90,180", &[][..]),
    ] {
        let (report, cloud, stdout) = merge_bunny(names, angles, extra);
        let [dr, dt] = bunny_pose_errors(&report, names);
        let [median, p90] = distance_to_truth(&cloud, &bunny_true_surface(names));
        eprintln!("{angles}: worst pose {dr:.3} deg {dt:.3} mm; to truth median {median:.3} p90 {p90:.3} mm\n{stdout}");
        assert!(
            dr < 0.5 && dt < 1.0,
            "{angles}: worst pose {dr} deg {dt} mm"
        );
        assert!(
            median <= 0.15 && p90 <= 0.30,
            "{angles}: median {median} p90 {p90} mm"
        );
        assert!(
            report["global"]["pairs"].as_u64().unwrap() >= 2,
            "{angles}: no global step"
        );
        for v in report["views"].as_array().unwrap().iter().skip(1) {
            assert!(v["residual_mm"].as_f64().is_some(), "{angles}: {v}");
        }
    }
}

/// With the default 5 degree tolerance bun045 (true turn 34.3 degrees against 45) cannot be
/// accepted: no match lies within the bound, and at its predicted pose only a fifth of it fits,
/// so merge refuses it, naming the view and the numbers, rather than merging it in 10 degrees
/// off (issue 52); with --skip-bad it is left out and listed, and the others still match
/// bun.conf.
#[test]
fn bunny_view_beyond_the_tolerance_is_refused_or_left_out() {
    let names = ["bun000.ply", "bun045.ply", "bun090.ply", "bun180.ply"];
    let (_, out) = merge_bunny_output(&names, "0,45,90,180", &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("bun045.ply: no match within the angle tolerance (5 deg)")
            && stderr.contains("of its points fit (min_fitness 0.3)")
            && stderr.contains("--skip-bad")
            && stderr.lines().count() == 1,
        "{stderr}"
    );
    let (report, _, stdout) = merge_bunny(&names, "0,45,90,180", &["--skip-bad"]);
    let skipped = report["skipped"].as_array().expect("skipped");
    assert!(
        skipped.len() == 1 && skipped[0].as_str().unwrap().ends_with("bun045.ply"),
        "{report}"
    );
    assert!(stdout.contains("bun045.ply"), "{stdout}");
    let [dr, dt] = bunny_pose_errors(&report, &["bun090.ply", "bun180.ply"]);
    assert!(dr < 0.5 && dt < 1.0, "worst pose {dr} deg {dt} mm");
}

//! Hostile inputs against the built binary (issue 34, "checked inputs and settings"), the
//! inspect side: every case must end in well under 20 s with a non-zero exit and one line
//! naming the file and the place (line, key, point index), never a panic; and the checks must
//! not refuse the valid case they guard. The settings, plan and run inputs are in
//! hostile_plan.rs.
mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::hostile::{arg, case, read_json, refused};
use common::{polishbot, succeed};
use polishbot::cloud::{self, PlyPrecision, PointCloud};

/// `inspect` of the case's scan against `reference` with `extra` arguments, into `out`.
fn inspect(reference: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = polishbot();
    cmd.args(["inspect", "--reference", arg(reference), "--scan"])
        .arg(case().path("scan.ply"))
        .args(["-o", arg(out)])
        .args(extra);
    cmd
}

/// The case's reference cloud with `edit` applied, written to `name` in a fresh folder.
fn edited_reference(tmp: &Path, name: &str, edit: impl FnOnce(&mut PointCloud)) -> PathBuf {
    let mut c = cloud::load_cloud(&case().path("reference.ply"), None, None).unwrap();
    edit(&mut c);
    let path = tmp.join(name);
    cloud::write_ply(&path, &c, None, PlyPrecision::F64).unwrap();
    path
}

/// Region peaks of an inspection folder, in file order.
fn peaks(dir: &Path) -> Vec<f64> {
    read_json(&dir.join("regions.json"))["regions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["peak"].as_f64().unwrap())
        .collect()
}

#[test]
fn a_pose_from_a_failed_registration_is_refused() {
    let tmp = common::tempdir();
    let pose = tmp.path().join("registration.json");
    let mut truth = read_json(&case().path("truth.json"));
    truth["status"] = "failed".into();
    truth["reason"] = "too few correspondences".into();
    std::fs::write(&pose, truth.to_string()).unwrap();
    let out = tmp.path().join("out");
    refused(
        &mut inspect(&case().path("reference.ply"), &out, &["--pose", arg(&pose)]),
        &["registration.json", "--pose", "\"failed\""],
    );
}

#[test]
fn a_reference_in_metres_read_as_millimetres_against_a_millimetre_scan_names_units() {
    let tmp = common::tempdir();
    let metres = edited_reference(tmp.path(), "reference_m.ply", |c| {
        c.points.iter_mut().for_each(|p| *p *= 1e-3);
    });
    // --units m makes the reference right and the millimetre scan 1000 times too large.
    let out = tmp.path().join("out");
    refused(
        &mut inspect(&metres, &out, &["--units", "m"]),
        &["scan.ply", "--units", "ratio"],
    );
}

#[test]
fn inward_reference_normals_are_turned_round_and_mixed_ones_refused() {
    let c = case();
    let tmp = common::tempdir();
    let truth = c.path("truth.json");
    let pose = ["--pose", arg(&truth)];
    let straight = tmp.path().join("straight");
    succeed(&mut inspect(&c.path("reference.ply"), &straight, &pose));
    let inward = edited_reference(tmp.path(), "inward.ply", |c| {
        c.normals
            .as_mut()
            .unwrap()
            .iter_mut()
            .for_each(|n| *n = -*n);
    });
    let turned = tmp.path().join("turned");
    let out = succeed(&mut inspect(&inward, &turned, &pose));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("inward.ply") && err.contains("turned round"),
        "{err}"
    );
    // A bump stays a bump: the same regions with the same signed peaks as the straight run.
    assert_eq!(peaks(&turned), peaks(&straight));
    assert!(peaks(&straight).iter().any(|p| *p > 0.0));
    // Half the part (x above its median) inward, half outward.
    let mixed = edited_reference(tmp.path(), "mixed.ply", |c| {
        let mut xs: Vec<f64> = c.points.iter().map(|p| p.x).collect();
        let mid = xs.len() / 2;
        let median = *xs.select_nth_unstable_by(mid, f64::total_cmp).1;
        let n = c.normals.as_mut().unwrap();
        for (p, n) in c.points.iter().zip(n.iter_mut()) {
            if p.x > median {
                *n = -*n;
            }
        }
    });
    refused(
        &mut inspect(&mixed, &tmp.path().join("mixed"), &pose),
        &["mixed.ply", "not consistently oriented"],
    );
}

#[test]
fn a_reference_without_normals_gets_estimated_ones_as_the_help_says() {
    let help = succeed(polishbot().args(["inspect", "--help"]));
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("without normals gets PCA normals"), "{help}");
    let tmp = common::tempdir();
    let bare = edited_reference(tmp.path(), "bare.ply", |c| c.normals = None);
    let truth = case().path("truth.json");
    let pose = ["--pose", arg(&truth)];
    let out = succeed(&mut inspect(&bare, &tmp.path().join("out"), &pose));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bare.ply") && err.contains("has no normals: estimated"),
        "{err}"
    );
    // The same part with its own (correct) normals measures at least as well (issue 52: a
    // reference with normals must inspect as accurately as without): each of its regions
    // (the three bumps) is one of the estimated run's, its peak within 0.02 mm (a tenth of
    // the smallest bump), and no more regions (the estimated normals add 0.06-0.09 mm ones).
    let own = tmp.path().join("own");
    succeed(&mut inspect(&case().path("reference.ply"), &own, &pose));
    let (a, b) = (peaks(&own), peaks(&tmp.path().join("out")));
    assert!(a.len() == 3 && a.len() <= b.len(), "{a:?} {b:?}");
    assert!(
        a.iter().all(|x| b.iter().any(|y| (x - y).abs() < 0.02)),
        "{a:?} {b:?}"
    );
}

#[test]
fn a_bad_normal_names_the_file_and_the_point_and_the_core_file_is_not_the_reference() {
    let tmp = common::tempdir();
    let bad = edited_reference(tmp.path(), "bad_normal.ply", |c| {
        c.normals.as_mut().unwrap()[0] *= 2.0;
    });
    let truth = case().path("truth.json");
    let pose = ["--pose", arg(&truth)];
    refused(
        &mut inspect(&bad, &tmp.path().join("a"), &pose),
        &["bad_normal.ply", "reference point 0", "not a unit vector"],
    );
    let core = edited_reference(tmp.path(), "core.ply", |c| {
        c.points.truncate(50);
        let n = c.normals.as_mut().unwrap();
        n.truncate(50);
        n[7] *= 0.5;
    });
    let extra = [pose[0], pose[1], "--core", arg(&core)];
    let line = refused(
        &mut inspect(&case().path("reference.ply"), &tmp.path().join("b"), &extra),
        &["core.ply", "--core file point 7", "not a unit vector"],
    );
    assert!(!line.contains("the reference"), "{line}");
}

/// The femoral component of `femoral_dm.stl` (shared data, metres) sampled with `n` points
/// and its facet normals (outward: the mesh is closed and oriented by its volume).
fn femoral_dm(file: &str, n: usize, seed: u64) -> PointCloud {
    let path = common::shared_data(file);
    let cloud::Geometry::Mesh { mut mesh, .. } = cloud::load(&path, None, Some(cloud::Units::M))
        .unwrap()
        .geometry
    else {
        panic!("{file} is a mesh")
    };
    if file == "femoral_dm.stl" {
        mesh.orient_outward();
    }
    cloud::sample_mesh(&mesh, n, seed).unwrap().cloud
}

/// `orient_outward` on a copy of `c`: Ok(true) when kept as it is, Ok(false) when turned
/// round, Err(message) when refused.
fn orientation(c: &PointCloud) -> Result<bool, String> {
    let mut c2 = c.clone();
    match polishbot::inspect::checks::orient_outward(Path::new("thin.ply"), &mut c2) {
        Ok(None) => {
            assert_eq!(c2.normals, c.normals, "changed without a note");
            Ok(true)
        }
        Ok(Some(note)) => {
            assert!(
                note.contains("thin.ply") && note.contains("turned round"),
                "{note}"
            );
            Ok(false)
        }
        Err(e) => Err(e.to_string()),
    }
}

fn flipped(c: &PointCloud, which: impl Fn(usize, &nalgebra::Point3<f64>) -> bool) -> PointCloud {
    let mut f = c.clone();
    for (i, (p, n)) in c.points.iter().zip(f.normals.as_mut().unwrap()).enumerate() {
        if which(i, p) {
            *n = -*n;
        }
    }
    f
}

/// The thin-walled reference: the femoral component's outer (articular) surface and
/// its inner box cuts, a 3-6 mm wall apart, sampled with correct outward normals as CAD
/// sampling tools export them (issue 52: refused at 20k points, "65 % agree"). Kept as it is
/// at any density; turned round when every normal points in; refused when the box cuts alone
/// point in. The same with two parallel sheets (the articular surface and a copy 6 mm / 3 mm
/// behind it, facing away from the material between them): kept, and refused with one whole
/// sheet or one patch turned in.
#[test]
fn a_thin_walled_reference_with_correct_normals_is_kept_and_a_flipped_sheet_refused() {
    let contact = femoral_dm("femoral_dm_contact.stl", 50_000, 9);
    let on_contact = polishbot::spatial::Neighbours::new(&contact.points);
    for (n, seed) in [(4_000, 1), (20_000, 2), (100_000, 3)] {
        let c = femoral_dm("femoral_dm.stl", n, seed);
        assert_eq!(orientation(&c), Ok(true), "{n} points");
        assert_eq!(orientation(&flipped(&c, |_, _| true)), Ok(false), "{n}");
        // The box cuts (points over 1 mm from the articular surface) turned in.
        let cuts = flipped(&c, |_, p| on_contact.nearest(p).unwrap().dist2 > 1.0);
        let err = orientation(&cuts).unwrap_err();
        assert!(err.contains("thin.ply: reference normals"), "{n}: {err}");
    }
    for (wall_mm, n, seed) in [(6.0, 20_000, 4), (3.0, 40_000, 5)] {
        let mut c = femoral_dm("femoral_dm_contact.stl", n / 2, seed);
        let normals = c.normals.clone().unwrap();
        for (p, m) in c.points.clone().iter().zip(&normals) {
            c.points.push(p - wall_mm * m);
            c.normals.as_mut().unwrap().push(-m);
        }
        let half = c.len() / 2;
        assert_eq!(orientation(&c), Ok(true), "{wall_mm} mm, {n} points");
        assert_eq!(orientation(&flipped(&c, |_, _| true)), Ok(false));
        let inner = orientation(&flipped(&c, |i, _| i >= half)).unwrap_err();
        assert!(
            inner.contains("point into the material on one sheet"),
            "{inner}"
        );
        let patch = orientation(&flipped(&c, |i, p| i < half && p.x > 10.0)).unwrap_err();
        assert!(patch.contains("not consistently oriented"), "{patch}");
    }
}

/// The hang list, inspect side: `--tolerance 0` is refused at its floor; the floor
/// itself (0.01 mm: regions all over the part's noise) gets an answer from inspect and from
/// plan over all its regions (issue 52: 19 s, then plan past 200 s); a 100-point scan with
/// `--pose` is refused as too sparse by both methods (was 65 s, classic past 45 s); `--units
/// m` on millimetre files names the scan's spacing, not a 309-digit `depth_step_mm`.
#[test]
fn tolerance_at_its_floor_sparse_scans_and_a_unit_slip_answer() {
    let c = case();
    let tmp = common::tempdir();
    let truth = c.path("truth.json");
    let pose = ["--pose", arg(&truth)];
    refused(
        &mut inspect(
            &c.path("reference.ply"),
            &tmp.path().join("t0"),
            &["--tolerance", "0"],
        ),
        &[
            "--tolerance",
            "`tolerance` = 0.0 mm is outside 0.01..=10.0 mm",
        ],
    );
    let floor = tmp.path().join("floor");
    let mut cmd = inspect(
        &c.path("reference.ply"),
        &floor,
        &[&pose[..], &["--tolerance", "0.01"]].concat(),
    );
    let out = cmd.output().unwrap();
    assert!(matches!(out.status.code(), Some(0 | 3)), "{out:?}");
    let regions = read_json(&floor.join("regions.json"))["regions"]
        .as_array()
        .unwrap()
        .len();
    assert!(regions > 20, "{regions} regions at 0.01 mm");
    let plan = tmp.path().join("plan.json");
    let mut cmd = polishbot();
    cmd.arg("--config").arg(c.path("plan.toml"));
    succeed(cmd.args(["plan", "--inspection", arg(&floor), "-o", arg(&plan)]));
    // Every 1,500th point of the scan: 100 points.
    let sparse = {
        let mut s = cloud::load_cloud(&c.path("scan.ply"), None, None).unwrap();
        s.points = s.points.iter().step_by(s.len() / 100).copied().collect();
        s.normals = None;
        s.fields.clear();
        let path = tmp.path().join("s100.ply");
        cloud::write_ply(&path, &s, None, PlyPrecision::F64).unwrap();
        path
    };
    for method in [&[][..], &["--method", "classic"][..]] {
        let mut cmd = polishbot();
        cmd.args([
            "inspect",
            "--reference",
            arg(&c.path("reference.ply")),
            "--scan",
        ])
        .arg(&sparse)
        .args(["-o", arg(&tmp.path().join("sparse"))])
        .args(pose)
        .args(method);
        refused(&mut cmd, &["s100.ply", "too sparse"]);
    }
    let line = refused(
        &mut inspect(
            &c.path("reference.ply"),
            &tmp.path().join("m"),
            &["--units", "m"],
        ),
        &["scan.ply"],
    );
    assert!(
        !line.contains("config") && !line.contains("depth_step_mm"),
        "{line}"
    );
    assert!(
        line.split(|ch: char| !ch.is_ascii_digit())
            .all(|d| d.len() <= 12),
        "{line}"
    );
}

//! Preprocessing against peers and truth: Open3D's statistical outlier removal (exact kept
//! set), a direct computation of the paper's eqs. 1-4, outlier recall on part scans, normals
//! against Open3D, and curvature-aware sampling on the femoral part.
mod common;

use std::path::Path;

use nalgebra::{Point3, Vector3};
use polishbot::cloud::{self, Geometry, Mesh, PlyPrecision, PointCloud, Units};
use polishbot::preprocess::{
    curvature_sample, estimate_normals, statistical_outlier_filter, CurvatureSampleConfig,
    NormalConfig, Orientation, SorConfig,
};
use polishbot::spatial::Neighbours;
use polishbot::synth::{synth, SynthCase, SynthConfig};
use rand::{Rng, SeedableRng};

fn femoral_mesh() -> Mesh {
    match cloud::load(&common::shared_data("femoral_dm.stl"), None, Some(Units::M))
        .unwrap()
        .geometry
    {
        Geometry::Mesh { mesh, .. } => mesh,
        Geometry::Cloud(_) => panic!("femoral_dm.stl has no faces"),
    }
}

fn bunny() -> PointCloud {
    cloud::load_cloud(
        &common::shared_data("bunny/bun000.ply"),
        None,
        Some(Units::M),
    )
    .unwrap()
}

/// The femoral part sampled at `n` points with 0.02 mm noise, then `outliers` points scattered
/// uniformly in its box (appended last).
fn part_with_scatter(n: usize, outliers: usize, seed: u64) -> PointCloud {
    let mut points = cloud::sample_mesh(&femoral_mesh(), n, seed)
        .unwrap()
        .cloud
        .points;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed + 100);
    for p in points.iter_mut() {
        *p += Vector3::new(rng.gen(), rng.gen(), rng.gen()).map(|v: f64| (v - 0.5) * 0.04);
    }
    let bbox = cloud::Aabb::of(&points).unwrap();
    for _ in 0..outliers {
        let t = Vector3::new(rng.gen(), rng.gen(), rng.gen());
        points.push(bbox.min + bbox.extent().component_mul(&t));
    }
    PointCloud::from_points(points)
}

/// `polishbot synth`'s default case (seed 1) with a small reference (only the scan is used).
fn synth_case() -> SynthCase {
    synth(&SynthConfig {
        reference_points: 20_000,
        ..SynthConfig::default()
    })
    .unwrap()
}

fn synth_scan() -> PointCloud {
    synth_case().scan
}

const OPEN3D_SOR: &str = r#"
import json, sys
import open3d as o3d
pcd = o3d.io.read_point_cloud(sys.argv[1])
_, kept = pcd.remove_statistical_outlier(nb_neighbors=int(sys.argv[2]), std_ratio=float(sys.argv[3]))
print(json.dumps({"n": len(pcd.points), "kept": list(kept)}))
"#;

/// Open3D's kept indices for `cloud` (written as a float64 PLY so both read the same numbers).
fn open3d_kept(python: &Path, cloud: &PointCloud, k: usize, ratio: f64) -> Vec<usize> {
    let dir = common::tempdir();
    let path = dir.path().join("in.ply");
    cloud::write_ply(&path, cloud, None, PlyPrecision::F64).unwrap();
    let out = common::run_python(
        python,
        OPEN3D_SOR,
        &[path.to_str().unwrap(), &k.to_string(), &ratio.to_string()],
    );
    let v: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!(v["n"].as_u64().unwrap() as usize, cloud.len());
    v["kept"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i.as_u64().unwrap() as usize)
        .collect()
}

fn check_against_open3d(python: &Path, name: &str, cloud: &PointCloud, k: usize, ratio: f64) {
    let ours = statistical_outlier_filter(
        cloud,
        &SorConfig {
            k,
            std_ratio: ratio,
            count_self: true,
        },
    )
    .unwrap();
    let theirs = open3d_kept(python, cloud, k, ratio);
    eprintln!(
        "{name}: {} points, k {k}, ratio {ratio}: Open3D keeps {}, we keep {}",
        cloud.len(),
        theirs.len(),
        ours.kept.len()
    );
    assert_eq!(ours.kept, theirs, "{name}: kept sets differ");
    assert!(
        ours.removed > 0,
        "{name}: the comparison should remove something"
    );
}

#[test]
fn count_self_matches_open3d_exactly() {
    let Some(python) = common::oracle_python() else {
        return;
    };
    let scan = synth_scan();
    check_against_open3d(&python, "synth scan", &scan, 20, 2.0);
    check_against_open3d(&python, "synth scan", &scan, 8, 1.0);
    let bunny = bunny();
    check_against_open3d(&python, "bunny bun000", &bunny, 20, 2.0);
    check_against_open3d(&python, "bunny bun000", &bunny, 30, 0.5);
}

/// Eqs. 1-4 computed directly: brute-force distances to every other point, the k smallest,
/// their mean, population mean and standard deviation, keep d <= mean + lambda std.
fn direct_eqs_1_to_4(points: &[Point3<f64>], k: usize, lambda: f64) -> Vec<usize> {
    let d: Vec<f64> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut all: Vec<f64> = points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (p - q).norm())
                .collect();
            all.sort_by(f64::total_cmp);
            all[..k].iter().sum::<f64>() / k as f64
        })
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let std = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    (0..d.len())
        .filter(|&i| d[i] <= mean + lambda * std)
        .collect()
}

#[test]
fn paper_convention_matches_a_direct_computation() {
    let part = part_with_scatter(3_000, 60, 5);
    for (k, lambda) in [(20, 2.0), (5, 1.0), (1, 0.0)] {
        let ours = statistical_outlier_filter(
            &part,
            &SorConfig {
                k,
                std_ratio: lambda,
                count_self: false,
            },
        )
        .unwrap();
        assert_eq!(
            ours.kept,
            direct_eqs_1_to_4(&part.points, k, lambda),
            "k {k} lambda {lambda}"
        );
    }
}

/// Share of `indices` that `kept` (ascending) does not contain.
fn removed_share(kept: &[usize], indices: &[usize]) -> f64 {
    let gone = indices
        .iter()
        .filter(|i| kept.binary_search(i).is_err())
        .count();
    gone as f64 / indices.len() as f64
}

/// Synth's scattered outliers are thrown 2-15 mm from a seed point along a jittered normal;
/// some land back near another part of the surface (75 of 1515 within 1 mm for seed 1),
/// where no statistical filter can tell them from surface points. The recall target is
/// therefore scored on those that really are at least 2 mm from every surface point; the raw
/// share over all of them is printed as well, with the clustered ("reflection") outliers.
#[test]
fn synth_scan_outliers_are_removed_and_the_surface_kept() {
    let case = synth_case();
    let truth = &case.truth.outliers;
    let scan = &case.scan;
    let is_outlier = |i: &usize| truth.scattered.contains(i) || truth.clustered.contains(i);
    let surface: Vec<usize> = (0..scan.len()).filter(|i| !is_outlier(i)).collect();
    let surface_index =
        Neighbours::new(&surface.iter().map(|&i| scan.points[i]).collect::<Vec<_>>());
    let off_surface = |i: &&usize| surface_index.nearest(&scan.points[**i]).unwrap().dist2 >= 4.0;
    let far: Vec<usize> = truth
        .scattered
        .iter()
        .filter(off_surface)
        .copied()
        .collect();
    for (lambda, assert) in [(2.0, true), (1.0, false)] {
        let cfg = SorConfig {
            std_ratio: lambda,
            ..SorConfig::default()
        };
        let r = statistical_outlier_filter(scan, &cfg).unwrap();
        let far_removed = removed_share(&r.kept, &far);
        let surface_kept = 1.0 - removed_share(&r.kept, &surface);
        eprintln!(
            "synth seed 1, {} points, k 20, ratio {lambda}: removed {:.2} % of the {} scattered \
             outliers >= 2 mm off the surface ({:.2} % of all {}), {:.2} % of {} clustered \
             ones ({} clusters); kept {:.3} % of {} surface points",
            scan.len(),
            100.0 * far_removed,
            far.len(),
            100.0 * removed_share(&r.kept, &truth.scattered),
            truth.scattered.len(),
            100.0 * removed_share(&r.kept, &truth.clustered),
            truth.clustered.len(),
            truth.clusters,
            100.0 * surface_kept,
            surface.len()
        );
        if assert {
            assert!(
                far_removed >= 0.95,
                "scattered outliers removed: {far_removed}"
            );
            assert!(surface_kept >= 0.995, "surface points kept: {surface_kept}");
        }
    }
}

#[test]
fn curvature_sampling_favours_the_feature_region_of_the_femoral_part() {
    let cloud = cloud::sample_mesh(&femoral_mesh(), 100_000, 9)
        .unwrap()
        .cloud;
    let cfg = CurvatureSampleConfig {
        target: 10_000,
        ..CurvatureSampleConfig::default()
    };
    let s = curvature_sample(&cloud, &cfg).unwrap();
    let input_share = s.feature_points as f64 / cloud.len() as f64;
    let kept_feature = s.indices.iter().filter(|&&i| s.feature[i]).count();
    let kept_share = kept_feature as f64 / s.indices.len() as f64;
    let mut angles = s.mean_angle_deg.clone();
    angles.sort_by(f64::total_cmp);
    let pct = |q: f64| angles[((angles.len() - 1) as f64 * q) as usize];
    eprintln!(
        "femoral_dm, 100k samples -> {} (J {}, threshold {} deg): feature region {:.1} % of \
         the input, {:.1} % of the sample; mean normal angle p50 {:.2} p90 {:.2} p99 {:.2} deg",
        s.indices.len(),
        cfg.uniform_ratio,
        cfg.feature_angle_deg,
        100.0 * input_share,
        100.0 * kept_share,
        pct(0.5),
        pct(0.9),
        pct(0.99)
    );
    assert_eq!(s.indices.len(), 10_000);
    assert_eq!(kept_feature, s.kept_feature);
    assert!(kept_share > input_share, "{kept_share} <= {input_share}");
}

const OPEN3D_NORMALS: &str = r#"
import sys
import numpy as np
import open3d as o3d
pcd = o3d.io.read_point_cloud(sys.argv[1])
pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=int(sys.argv[2])))
np.savetxt(sys.stdout, np.asarray(pcd.normals), fmt="%.17g")
"#;

#[test]
fn pca_normals_match_open3d_up_to_sign() {
    let Some(python) = common::oracle_python() else {
        return;
    };
    let mut cloud = part_with_scatter(20_000, 0, 21);
    cloud.normals = None;
    let dir = common::tempdir();
    let path = dir.path().join("in.ply");
    cloud::write_ply(&path, &cloud, None, PlyPrecision::F64).unwrap();
    let out = common::run_python(&python, OPEN3D_NORMALS, &[path.to_str().unwrap(), "20"]);
    let theirs: Vec<Vector3<f64>> = out
        .lines()
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().unwrap()).collect();
            Vector3::new(v[0], v[1], v[2])
        })
        .collect();
    let cfg = NormalConfig {
        k: 20,
        orientation: Orientation::Unoriented,
        ..NormalConfig::default()
    };
    let ours = estimate_normals(&cloud, &cfg).unwrap();
    let worst = ours
        .normals
        .iter()
        .zip(&theirs)
        .map(|(a, b)| a.dot(b).abs())
        .fold(1.0, f64::min);
    eprintln!(
        "normals vs Open3D on {} points: smallest |cos| {worst}",
        cloud.len()
    );
    assert_eq!(theirs.len(), cloud.len());
    assert!(worst > 1.0 - 1e-9, "smallest |cos| {worst}");
}

#[test]
fn filter_command_writes_the_cloud_and_one_summary_line() {
    let dir = common::tempdir();
    let input = dir.path().join("scan.ply");
    let output = dir.path().join("clean.ply");
    let scan = part_with_scatter(20_000, 400, 4);
    cloud::write_ply(&input, &scan, None, PlyPrecision::F64).unwrap();
    let run = |extra: &[&str]| {
        let mut cmd = common::polishbot();
        cmd.arg("filter")
            .arg(&input)
            .arg("-o")
            .arg(&output)
            .args(extra);
        cmd.output().unwrap()
    };
    let out = run(&["--k", "20", "--std-ratio", "2.0"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = String::from_utf8(out.stdout).unwrap();
    let expected = statistical_outlier_filter(&scan, &SorConfig::default()).unwrap();
    assert_eq!(line.lines().count(), 1);
    assert!(
        line.contains(&format!("removed {}", expected.removed)),
        "{line}"
    );
    let written = cloud::load_cloud(&output, None, Some(Units::Mm)).unwrap();
    assert_eq!(written.points, expected.apply(&scan).points);

    let out = run(&[
        "--voxel",
        "1",
        "--curvature-sample",
        "2000",
        "--feature-angle",
        "5",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        cloud::load_cloud(&output, None, Some(Units::Mm))
            .unwrap()
            .len(),
        2000
    );

    for (args, says) in [
        (&["--k", "0"][..], "k must be at least 1"),
        (&["--k", "20400"][..], "needs more points"),
        (&["--std-ratio", "-1"][..], "std ratio must be"),
        (&["--voxel", "0"][..], "voxel must be"),
        (
            &["--curvature-sample", "100", "--uniform-ratio", "2"][..],
            "uniform ratio",
        ),
    ] {
        let out = run(args);
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(
            !out.status.success() && err.lines().count() == 1 && err.contains(says),
            "{args:?}: {err}"
        );
    }
}

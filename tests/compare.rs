//! compare + regions + inspect: py4dgeo oracle, accuracy against synth truth, the CLI files.
mod common;

use std::path::Path;

use nalgebra::{Point3, Vector3};
use polishbot::cloud::{PointCloud, Units};
use polishbot::compare::{compare, CompareConfig, Method};
use polishbot::synth::{synth, SynthCase, SynthConfig};

/// A femoral_dm case with the scan moved back into the reference frame by the true pose.
fn aligned_case(seed: u64, reference_points: usize, scan_points: usize) -> SynthCase {
    let cfg = SynthConfig {
        seed,
        mesh: Some(common::shared_data("femoral_dm.stl")),
        surface: Some(common::shared_data("femoral_dm_contact.stl")),
        units: Some(Units::M),
        reference_points,
        scan_points,
        ..SynthConfig::default()
    };
    let mut case = synth(&cfg).expect("synth case");
    let pose = case.truth.pose().expect("pose");
    case.scan.transform(&pose);
    case
}

fn write_f64(path: &Path, rows: impl Iterator<Item = [f64; 3]>) {
    let bytes: Vec<u8> = rows.flatten().flat_map(f64::to_le_bytes).collect();
    std::fs::write(path, bytes).unwrap();
}

fn read_f64(path: &Path) -> Vec<f64> {
    std::fs::read(path)
        .unwrap()
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

const PY4DGEO: &str = r#"
import sys, numpy as np, py4dgeo
d = sys.argv[1]
r, L, reg = map(float, sys.argv[2:5])
load = lambda n: np.fromfile(d + '/' + n, dtype='<f8').reshape(-1, 3)
ref, scan, core, nrm = load('ref'), load('scan'), load('core'), load('normals')
m = py4dgeo.M3C2(epochs=(py4dgeo.Epoch(ref), py4dgeo.Epoch(scan)), corepoints=core,
                 cyl_radius=r, normal_radii=[r], max_distance=L, registration_error=reg,
                 corepoint_normals=nrm)
dist, unc = m.run()
out = np.stack([dist, unc['lodetection'], unc['num_samples1'], unc['num_samples2']], 1)
out.astype('<f8').tofile(d + '/out')
"#;

#[test]
fn classic_equals_py4dgeo() {
    let Some(python) = common::oracle_python() else {
        return;
    };
    let case = aligned_case(5, 60_000, 45_000);
    // Holes in the scan give empty and one-point cylinders: NaN distances and NaN LoD.
    let holes: Vec<Point3<f64>> = case.reference.points.iter().step_by(9_000).copied().collect();
    let scan = PointCloud::from_points(
        case.scan
            .points
            .iter()
            .filter(|p| holes.iter().all(|h| (*p - h).norm() > 0.8))
            .copied()
            .collect(),
    );
    let idx: Vec<usize> = (0..case.reference.len()).step_by(12).collect();
    let mut core = case.reference.select(&idx);
    // Core points off the surface as well (along and against the normal).
    let normals = core.normals.clone().unwrap();
    for (i, p) in core.points.iter_mut().enumerate().step_by(50) {
        *p += normals[i] * if i % 100 == 0 { 0.7 } else { -2.5 };
    }
    let dir = common::tempdir();
    write_f64(&dir.path().join("ref"), case.reference.points.iter().map(|p| [p.x, p.y, p.z]));
    write_f64(&dir.path().join("scan"), scan.points.iter().map(|p| [p.x, p.y, p.z]));
    write_f64(&dir.path().join("core"), core.points.iter().map(|p| [p.x, p.y, p.z]));
    write_f64(&dir.path().join("normals"), normals.iter().map(|n| [n.x, n.y, n.z]));
    for (radius, max_distance, reg) in [(0.5, 1.0, 0.01), (0.3, 0.2, 0.0), (0.25, 1.3, 0.003)] {
        let cfg = CompareConfig {
            method: Method::Classic,
            radius: Some(radius),
            max_distance,
            registration_error: reg,
            min_points: 1,
            ..CompareConfig::default()
        };
        let ours = compare(&core, &case.reference, &scan, &cfg).unwrap();
        let d = dir.path().to_str().unwrap();
        let args = [d, &radius.to_string(), &max_distance.to_string(), &reg.to_string()];
        common::run_python(&python, PY4DGEO, &args);
        let theirs = read_f64(&dir.path().join("out"));
        assert_eq!(theirs.len(), 4 * core.len());
        let (mut nan_d, mut nan_lod) = (0, 0);
        for (i, (v, t)) in ours.values.iter().zip(theirs.chunks(4)).enumerate() {
            let ctx = format!("core {i} (r {radius}, L {max_distance}): ours {v:?}, py4dgeo {t:?}");
            assert_eq!(v.n_ref as f64, t[2], "{ctx}");
            assert_eq!(v.n_scan as f64, t[3], "{ctx}");
            assert_eq!(v.distance.is_nan(), t[0].is_nan(), "{ctx}");
            assert_eq!(v.uncertainty.is_nan(), t[1].is_nan(), "{ctx}");
            nan_d += t[0].is_nan() as usize;
            nan_lod += t[1].is_nan() as usize;
            if !t[0].is_nan() {
                assert!((v.distance - t[0]).abs() <= 1e-6, "{ctx}");
            }
            if !t[1].is_nan() {
                assert!((v.uncertainty - t[1]).abs() <= 1e-6, "{ctx}");
            }
        }
        eprintln!("r {radius} L {max_distance}: {} core points, {nan_d} NaN distances, {nan_lod} NaN LoD", core.len());
        assert!(nan_d > 0 && nan_lod > nan_d, "the case must exercise the NaN paths");
    }
}

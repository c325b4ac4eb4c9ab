//! compare + regions + inspect: py4dgeo oracle, accuracy against synth truth, the CLI files.
mod common;

#[path = "compare/cli.rs"]
mod cli;
#[path = "compare/peaks.rs"]
mod peaks;
use std::path::Path;

use nalgebra::Point3;
use polishbot::cloud::{PointCloud, Units};
use polishbot::compare::{
    compare, core_points, Aggregate, CompareConfig, CoreConfig, Deviations, Method,
};
use polishbot::regions::{find_regions, Region, RegionConfig, Regions};
use polishbot::synth::{synth, Defect, SynthCase, SynthConfig};

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
r, L, reg, robust = map(float, sys.argv[2:6])
load = lambda n: np.fromfile(d + '/' + n, dtype='<f8').reshape(-1, 3)
ref, scan, core, nrm = load('ref'), load('scan'), load('core'), load('normals')
m = py4dgeo.M3C2(epochs=(py4dgeo.Epoch(ref), py4dgeo.Epoch(scan)), corepoints=core,
                 cyl_radius=r, normal_radii=[r], max_distance=L, registration_error=reg,
                 corepoint_normals=nrm, robust_aggr=bool(robust))
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
    let holes: Vec<Point3<f64>> = case
        .reference
        .points
        .iter()
        .step_by(9_000)
        .copied()
        .collect();
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
    write_f64(
        &dir.path().join("ref"),
        case.reference.points.iter().map(|p| [p.x, p.y, p.z]),
    );
    write_f64(
        &dir.path().join("scan"),
        scan.points.iter().map(|p| [p.x, p.y, p.z]),
    );
    write_f64(
        &dir.path().join("core"),
        core.points.iter().map(|p| [p.x, p.y, p.z]),
    );
    write_f64(
        &dir.path().join("normals"),
        normals.iter().map(|n| [n.x, n.y, n.z]),
    );
    for (radius, max_distance, reg, aggregate) in [
        (0.5, 1.0, 0.01, Aggregate::Mean),
        (0.3, 0.2, 0.0, Aggregate::Mean),
        (0.25, 1.3, 0.003, Aggregate::Mean),
        (0.5, 1.0, 0.01, Aggregate::Median),
        (0.25, 1.3, 0.003, Aggregate::Median),
    ] {
        let cfg = CompareConfig {
            method: Method::Classic,
            radius: Some(radius),
            max_distance,
            registration_error: reg,
            aggregate,
            min_points: 1,
            ..CompareConfig::default()
        };
        let ours = compare(&core, &case.reference, &scan, &cfg).unwrap();
        let d = dir.path().to_str().unwrap();
        let args = [
            d,
            &radius.to_string(),
            &max_distance.to_string(),
            &reg.to_string(),
            if aggregate == Aggregate::Median {
                "1"
            } else {
                "0"
            },
        ];
        common::run_python(&python, PY4DGEO, &args);
        let theirs = read_f64(&dir.path().join("out"));
        assert_eq!(theirs.len(), 4 * core.len());
        let (mut nan_d, mut nan_lod) = (0, 0);
        for (i, (v, t)) in ours.values.iter().zip(theirs.chunks(4)).enumerate() {
            let ctx = format!(
                "core {i} (r {radius}, L {max_distance}, {aggregate:?}): ours {v:?}, py4dgeo {t:?}"
            );
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
        eprintln!(
            "r {radius} L {max_distance} {aggregate:?}: {} core points, {nan_d} NaN distances, \
             {nan_lod} NaN LoD",
            core.len()
        );
        // A one-point cylinder has a NaN standard deviation but an IQR of 0.
        let one_point_nan = aggregate == Aggregate::Mean;
        assert!(
            nan_d > 0 && (nan_lod > nan_d) == one_point_nan,
            "the case must exercise the NaN paths"
        );
    }
}

/// Scores of one method on one case against truth.
#[derive(Debug)]
struct Score {
    iou: f64,
    rms: f64,
    /// (defect height, region peak) for every defect taller than the tolerance.
    peaks: Vec<(f64, Option<f64>)>,
    /// IoU of the members of regions (what the report shows as defects: error points in
    /// groups of at least `min_points`) instead of every error point.
    region_iou: f64,
    false_regions: usize,
    regions: usize,
    /// Core points added by densification.
    densified: usize,
    /// Per defect taller than the tolerance: [true volume, regions' volume, true area,
    /// regions' area] ([`sizes`]).
    sizes: Vec<[f64; 4]>,
}

/// `truth_sizes`: [`true_sizes`] of `case`.
fn score(
    seed: u64,
    case: &SynthCase,
    truth_sizes: &[[f64; 2]],
    dev: &Deviations,
    regions: &Regions,
    tol: f64,
) -> Score {
    let truth: Vec<f64> = dev
        .points
        .iter()
        .zip(&dev.normals)
        .map(|(p, n)| case.truth.deviation_at(p, n))
        .collect();
    if let Some(dump) = std::env::var_os("POLISHBOT_DUMP") {
        let mut cloud = polishbot::compare::to_cloud(dev, &regions.labels);
        cloud.set_field("truth", truth.clone());
        let col = |f: &dyn Fn(&polishbot::compare::Deviation) -> f64| {
            dev.values.iter().map(f).collect::<Vec<f64>>()
        };
        cloud.set_field("peak", col(&|d| d.peak));
        cloud.set_field("peak_fitted", col(&|d| d.peak_fitted as u8 as f64));
        cloud.set_field("reason", col(&|d| d.reason as u8 as f64));
        let given = (0..dev.values.len()).map(|i| f64::from(u8::from(i < dev.given)));
        cloud.set_field("given", given.collect());
        let dump = dump.to_string_lossy();
        let path = format!("{dump}-{seed}-{:?}.csv", dev.method);
        polishbot::cloud::write_csv(Path::new(&path), &cloud).unwrap();
        case.truth
            .save(Path::new(&format!("{dump}-{seed}-truth.json")))
            .unwrap();
    }
    let is_true: Vec<bool> = truth.iter().map(|t| t.abs() > tol).collect();
    let detected: Vec<bool> = dev
        .values
        .iter()
        .map(|v| v.significant && v.distance.abs() > tol)
        .collect();
    // IoU and RMS over the given core points (the same points whatever the method; the
    // densified ones cluster at defect tops, where detection is easy).
    let iou = |detected: &[bool]| {
        let pairs = || is_true.iter().zip(detected).take(dev.given);
        let both = pairs().filter(|(a, b)| **a && **b).count();
        let either = pairs().filter(|(a, b)| **a || **b).count();
        both as f64 / either.max(1) as f64
    };
    let in_region: Vec<bool> = regions.labels.iter().map(|&l| l >= 0).collect();
    let errs: Vec<f64> = (0..dev.given)
        .filter(|&i| is_true[i])
        .map(|i| dev.values[i].distance - truth[i])
        .collect();
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len().max(1) as f64).sqrt();
    let peaks = case
        .truth
        .defects
        .iter()
        .filter(|d| d.height.abs() > tol)
        .map(|d| {
            let c = Point3::from(d.centre);
            let near = (0..dev.points.len())
                .filter(|&i| regions.labels[i] >= 0 && (dev.points[i] - c).norm() < d.support())
                .map(|i| regions.regions[regions.labels[i] as usize].peak)
                .max_by(|a, b| a.abs().total_cmp(&b.abs()));
            (d.height, near)
        })
        .collect();
    let mut with_truth = vec![false; regions.regions.len()];
    for i in 0..dev.points.len() {
        if regions.labels[i] >= 0 && is_true[i] {
            with_truth[regions.labels[i] as usize] = true;
        }
    }
    Score {
        iou: iou(&detected),
        region_iou: iou(&in_region),
        rms,
        peaks,
        false_regions: with_truth.iter().filter(|t| !**t).count(),
        regions: regions.regions.len(),
        densified: dev.added(),
        sizes: sizes(case, truth_sizes, dev, regions, tol),
    }
}

/// The defects of `case` taller than `tol`.
fn tall_defects(case: &SynthCase, tol: f64) -> impl Iterator<Item = &Defect> {
    case.truth
        .defects
        .iter()
        .filter(move |d| d.height.abs() > tol)
}

/// Per defect of `case` taller than `tol`: its true volume beyond the tolerance (mm³) and
/// area beyond it (mm²), summed over the reference points within its support with their area
/// shares.
fn true_sizes(case: &SynthCase, tol: f64) -> Vec<[f64; 2]> {
    let shares = polishbot::compare::area_shares(&case.reference.points);
    let normals = case.reference.normals.as_ref().unwrap();
    tall_defects(case, tol)
        .map(|d| {
            let c = Point3::from(d.centre);
            let (mut volume, mut area) = (0.0, 0.0);
            for (k, p) in case.reference.points.iter().enumerate() {
                let t = d.displacement(p, &normals[k]);
                if (p - c).norm() < d.support() && t.abs() > tol {
                    volume += shares[k] * (t.abs() - tol);
                    area += shares[k];
                }
            }
            [volume, area]
        })
        .collect()
}

/// Per defect of `case` taller than `tol`: [true volume, regions' volume, true area,
/// regions' area], the truth from `truth_sizes` ([`true_sizes`]), the regions those with a
/// member within its support.
fn sizes(
    case: &SynthCase,
    truth_sizes: &[[f64; 2]],
    dev: &Deviations,
    regions: &Regions,
    tol: f64,
) -> Vec<[f64; 4]> {
    tall_defects(case, tol)
        .zip(truth_sizes)
        .map(|(d, &[volume, area])| {
            let c = Point3::from(d.centre);
            let mut ids: Vec<usize> = (0..dev.points.len())
                .filter(|&i| regions.labels[i] >= 0 && (dev.points[i] - c).norm() < d.support())
                .map(|i| regions.labels[i] as usize)
                .collect();
            ids.sort_unstable();
            ids.dedup();
            let found = |f: fn(&polishbot::regions::Region) -> f64| {
                ids.iter().map(|&r| f(&regions.regions[r])).sum::<f64>()
            };
            [volume, found(|r| r.volume), area, found(|r| r.area)]
        })
        .collect()
}

/// Every defect of `score` taller than `above` (mm; its peaks are those of defects taller than
/// the tolerance) has a region whose peak is within `within` × its height.
fn assert_peaks(seed: u64, score: &Score, above: f64, within: f64) {
    for (h, peak) in score.peaks.iter().filter(|(h, _)| h.abs() > above) {
        let peak = peak.unwrap_or_else(|| panic!("seed {seed}: defect of height {h} missed"));
        assert!(
            (peak - h).abs() <= within * h.abs(),
            "seed {seed}: peak {peak} for height {h}"
        );
    }
}

/// The synth seeds of the accuracy tests: POLISHBOT_SEEDS (comma-separated), else `default`.
fn seeds(default: &[u64]) -> Vec<u64> {
    match std::env::var("POLISHBOT_SEEDS") {
        Ok(s) => s.split(',').map(|x| x.parse().unwrap()).collect(),
        Err(_) => default.to_vec(),
    }
}

/// Scan points of the accuracy cases: POLISHBOT_SCAN_POINTS, else `default`; the reference
/// has 4/3 as many.
fn scan_points(default: usize) -> usize {
    std::env::var("POLISHBOT_SCAN_POINTS").map_or(default, |s| s.parse().unwrap())
}

/// Scores of (adaptive, classic) on the femoral_dm cases of seeds 11 and 12 (see [`seeds`]),
/// scan aligned by the true pose, with `default_scan_points` scan points unless
/// POLISHBOT_SCAN_POINTS says otherwise.
fn scores(default_scan_points: usize) -> Vec<(u64, Score, Score)> {
    scores_of(&[11, 12], default_scan_points)
}

/// [`scores`] on the cases of `default_seeds`.
fn scores_of(default_seeds: &[u64], default_scan_points: usize) -> Vec<(u64, Score, Score)> {
    let tol = RegionConfig::default().tolerance;
    seeds(default_seeds)
        .into_iter()
        .map(|seed| {
            let scan_points = scan_points(default_scan_points);
            let case = aligned_case(seed, scan_points / 3 * 4, scan_points);
            // The core points `inspect` takes: the default sample for the scan's size, unless
            // POLISHBOT_CORE_POINTS gives the count.
            let core_cfg = CoreConfig {
                count: std::env::var("POLISHBOT_CORE_POINTS")
                    .ok()
                    .map(|s| s.parse().unwrap()),
                ..CoreConfig::default()
            };
            let core = core_points(&case.reference, case.scan.len(), &core_cfg).unwrap();
            let truth_sizes = true_sizes(&case, tol);
            let run = |method| {
                let mut cfg = CompareConfig {
                    method,
                    ..CompareConfig::default()
                };
                // POLISHBOT_PEAK_FIT=0: the peaks without the peak fit (for comparison).
                cfg.adaptive.peak_fit =
                    std::env::var("POLISHBOT_PEAK_FIT").map_or(true, |v| v != "0");
                let dev = compare(&core, &case.reference, &case.scan, &cfg).unwrap();
                let regions = find_regions(&dev, &RegionConfig::default());
                score(seed, &case, &truth_sizes, &dev, &regions, tol)
            };
            let (ours, classic) = (run(Method::Adaptive), run(Method::Classic));
            eprintln!("seed {seed} adaptive: {ours:?}");
            eprintln!("seed {seed} classic:  {classic:?}");
            (seed, ours, classic)
        })
        .collect()
}

/// What the adaptive method reaches at 300,000 scan points (19 points/mm², spacing 0.23 mm;
/// a regression floor below issue 5's targets, see `acceptance_targets`), on `inspect`'s
/// core points (50,500 of the 400,000 reference points, drawn at random; until 2026-12-01
/// every 4th reference point): IoU 0.975 / 0.935, RMS 0.0042 / 0.0048 mm on seeds 11 / 12
/// since the model fill (docs/ALGORITHMS.md, adaptive step 13; before it 0.912 / 0.905 and
/// 0.012 / 0.010 mm). The per-point results do not depend on the sample, but IoU over a
/// sample spreads by about ±0.03 on one case (docs/ALGORITHMS.md, Comparison). It beats
/// classic on IoU and RMS, raises no region that truth does not have (classic raises dozens
/// along the box-cut edges) and finds every defect taller than the tolerance, seed 12's
/// narrow 0.09 mm pit included (a peak model measures it, -4 %: adaptive step 12; missed
/// before), with its peak within 15 % (the peak fit: every one within 10 % but seed 11's
/// 0.29 mm, 0.64 mm wide bump, -11 %; before the fit seed 11's bump was reported 0.17 mm,
/// -42 %).
#[test]
fn adaptive_finds_the_planted_defects_and_beats_classic() {
    for (seed, ours, classic) in scores(300_000) {
        assert!(
            ours.iou > classic.iou + 0.3,
            "seed {seed}: adaptive must beat classic on IoU"
        );
        assert!(
            ours.rms < classic.rms,
            "seed {seed}: adaptive must beat classic on RMS"
        );
        assert!(ours.iou >= 0.92, "seed {seed}: IoU {}", ours.iou);
        // Region members: 0.975 / 0.935 (isolated error points at the box cuts drop out).
        assert!(
            ours.region_iou >= 0.92,
            "seed {seed}: region IoU {}",
            ours.region_iou
        );
        // Issue 5's RMS target, met at 300k since the model fill (0.0042 / 0.0048 mm).
        assert!(ours.rms <= 0.01, "seed {seed}: RMS {}", ours.rms);
        assert_eq!(
            ours.false_regions, 0,
            "seed {seed}: regions truth does not have"
        );
        assert!(
            classic.false_regions > 0,
            "seed {seed}: the case must have sharp-edge traps"
        );
        assert!(ours.regions > 0, "seed {seed}: no region at all");
        assert_peaks(seed, &ours, RegionConfig::default().tolerance, 0.15);
        // Volume and area beyond the tolerance against truth, summed over the case's defects:
        // -10 % / -8 % and -12 % / -8 % (-13 % / -9 % and -13 % / -8 % before the model
        // fill); each defect's volume within -25 % (seed 12's 0.09 mm pit; -38 % before) to
        // +3 %.
        let total = |k: usize| ours.sizes.iter().map(|s| s[k]).sum::<f64>();
        for (what, truth, found) in [("volume", 0, 1), ("area", 2, 3)] {
            let (t, f) = (total(truth), total(found));
            assert!((f - t).abs() <= 0.2 * t, "seed {seed}: {what} {f} for {t}");
        }
        for s in &ours.sizes {
            assert!(
                (s[1] - s[0]).abs() <= 0.5 * s[0],
                "seed {seed}: volume {s:?}"
            );
        }
    }
}

/// Two cases outside the seeds the method was tuned on (11-34), where 300k missed the RMS
/// target: seed 36 (0.0106 mm: an elongated-Gaussian model of a 5.6 mm ridge read 0.055 mm
/// high at the ridge's end, and the lack-of-fit test left out the points that showed it as
/// outliers) and seed 45 (0.024 mm: a 0.39 mm deep, 0.57 mm wide pit read 0.16 mm, its peak
/// fit started from a cylinder's 0.16 mm and its top cut off beyond twice that). Now 0.0094
/// and 0.0037 mm. Every defect taller than twice the tolerance is found: seed 45's 0.134 mm
/// deep, 0.51 mm wide pit, 0.41 mm from the nearest core point, was missed until 2026-12-01
/// (two reference points near its bottom had a scan point beyond the tolerance, and step 12
/// wanted three before fitting; now -15 %). Seed 80 (0.0104 mm until 2026-12-01; now 0.0031):
/// a 0.368 mm, 0.45 mm wide bump with one scan point near its top read 0.093 mm, its peak fit
/// refused for 7 supporting points and a height limit from the cylinders' value. Seed 80
/// also has a 0.135 mm deep, 0.42 mm wide pit that no method here finds: its deepest scan
/// point reads 0.076 mm (the data do not show it beyond 0.1 mm), so the check that every
/// defect taller than twice the tolerance is found covers seeds 36 and 45.
#[test]
fn cases_beyond_the_tuned_seeds_meet_the_rms_target() {
    let tolerance = RegionConfig::default().tolerance;
    for (seed, ours, _) in scores_of(&[36, 45, 80], 300_000) {
        assert!(ours.rms <= 0.01, "seed {seed}: RMS {}", ours.rms);
        assert_eq!(ours.false_regions, 0, "seed {seed}");
        for (height, peak) in ours.peaks.iter().filter(|_| seed != 80) {
            let tall = height.abs() > 2.0 * tolerance;
            assert!(!tall || peak.is_some(), "seed {seed}: {height} mm missed");
        }
    }
}

/// Narrow faces and the strips beside the box cuts hold a few points of a cylinder, where the
/// error of a fit is largest. On the first five cases at 300,000 scan points main had one region
/// that truth does not have on seeds 24, 26 and 27 until 2026-12-01, and intermediate versions
/// of the fix one on seeds 25 and 32 (traced in docs/ALGORITHMS.md, adaptive M3C2,
/// "Precomputed once" and step 5):
/// - seeds 24, 27 and 32: scan points of a neighbouring face within a reference spacing of a
///   sharp edge were paired with the nearer reference point of the other face and lay
///   0.05-0.19 mm off its tangent plane (seed 24: a 3-point region reading 0.055 mm);
/// - seed 26: a plane through six scan points on a strip 0.3-0.76 mm to one side of the axis
///   extrapolated to -0.44 mm (a 5-point pit region; the points' mean is 0.00);
/// - seed 25: a 3-point pit region of smallest-radius fits on a narrow face.
///
/// Pairing a scan point at a sharp edge with the face whose patch lies nearest removed all of
/// them; quadrics that extrapolate now step down to planes. Seed 37 (not among the seeds the
/// method was tuned on) had one until 2026-12-01: a narrow face at a corner, between faces
/// 23-35° off it (within the normal filter: no sharp edge), read +0.013 to +0.063 mm towards
/// the corner, 4 core points beyond the tolerance; pairing at such shallow edges with the
/// upper face's plane at a convex edge and the lower one's at a concave edge removed it.
#[test]
fn narrow_faces_raise_no_false_region() {
    for (seed, ours, _) in scores_of(&[24, 25, 26, 27, 32, 37], 300_000) {
        assert_eq!(
            ours.false_regions, 0,
            "seed {seed}: regions truth does not have"
        );
    }
}

/// At 1.2 million scan points (76 points/mm², spacing 0.115 mm: a 0.64 mm wide bump holds
/// about 25 points, where it holds 6 at 300,000) issue 5's targets are met: RMS 0.0028 /
/// 0.0025 mm, IoU 0.964 / 0.988 on seeds 11 / 12 (`inspect`'s 100,000 core points, drawn at
/// random; 0.920 / 0.965 before the model fill of adaptive step 13 and the peak window's
/// 2 mm floor: seed 11's 0.07 mm ridge, 2.7 mm wide and 8.5 mm long, lies within the noise of
/// the tolerance over most of its area), every defect is found and its peak is within 10 %
/// (the ridge: +13 % before, the largest of the many core points along its crest).
/// Seed 12's 0.09 mm deep, 0.65 mm wide pit exceeds the tolerance on about 0.3 mm² (two core
/// points' share): it is found (-0.092 mm) by the core points densification adds around it,
/// and was missed before.
#[test]
fn dense_scan_meets_the_rms_target() {
    for (seed, ours, classic) in scores(1_200_000) {
        assert!(ours.rms <= 0.006, "seed {seed}: RMS {}", ours.rms);
        assert!(ours.iou >= 0.95, "seed {seed}: IoU {}", ours.iou);
        assert!(ours.iou > classic.iou + 0.3, "seed {seed}: IoU vs classic");
        assert_eq!(ours.false_regions, 0, "seed {seed}: false regions");
        // Densification stays local: 1,400-3,400 core points added to 100,000 (seeds 11-22).
        assert!(
            ours.densified > 0 && ours.densified < 5_000,
            "seed {seed}: {} core points added",
            ours.densified
        );
        assert_peaks(seed, &ours, 0.0, 0.1);
    }
}

/// The same at 1.2 million scan points on ten more cases (seeds 13-22; 59 defects taller
/// than the tolerance, 0.059-0.5 mm, from 0.43 mm wide): every defect taller than the
/// tolerance has a region whose peak is within 15 % (the largest errors: seed 15's 0.072 mm
/// bump -13 %, seed 16's 0.059 mm pit -11 %), no region that truth does not have, IoU 0.963
/// (seed 16) to 1.000 (`inspect`'s core points; 0.889 to 0.974 before the model fill of
/// adaptive step 13 and the peak window's 2 mm floor). At
/// 300,000 points the same seeds miss a 0.1 mm, 0.5 mm wide bump (17; peak models find the
/// narrow 0.21 and 0.32 mm bumps of seeds 18 and 22) and reach IoU 0.88-0.98:
/// docs/ALGORITHMS.md.
#[test]
fn dense_scan_finds_every_defect_of_ten_more_cases() {
    let seeds: Vec<u64> = (13..=22).collect();
    for (seed, ours, _) in scores_of(&seeds, 1_200_000) {
        assert!(ours.iou >= 0.95, "seed {seed}: IoU {}", ours.iou);
        assert_eq!(ours.false_regions, 0, "seed {seed}: false regions");
        assert_peaks(seed, &ours, 0.0, 0.15);
    }
}

/// Issue 5's acceptance targets (IoU >= 0.95, RMS <= 0.01 mm, every peak within 10 %): at
/// 300,000 scan points RMS is met since the model fill (0.0042 / 0.0048 mm on seeds 11 / 12;
/// every one of seeds 11-34 within 0.0087 mm) and IoU on seed 11 (0.975), not on seed 12
/// (0.935: a few of its 120 true error points read just inside the tolerance, a few just
/// outside read just beyond it; docs/ALGORITHMS.md, step 13, "What is left"), and seed 11's narrow
/// 0.29 mm bump is reported -11 %. At 1.2 million (POLISHBOT_SCAN_POINTS=1200000) every target is
/// met on both seeds. docs/ALGORITHMS.md, adaptive step 13. Run with --ignored.
#[test]
#[ignore]
fn acceptance_targets() {
    for (seed, ours, _) in scores(300_000) {
        assert!(ours.iou >= 0.95, "seed {seed}: IoU {}", ours.iou);
        assert!(ours.rms <= 0.01, "seed {seed}: RMS {}", ours.rms);
        assert_peaks(seed, &ours, 0.0, 0.1);
    }
}

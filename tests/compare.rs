//! compare + regions + inspect: py4dgeo oracle, accuracy against synth truth, the CLI files.
mod common;

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

/// A plane sampled every 0.1 mm (reference) and, with 0.01 mm Gaussian noise, at random
/// (scan, 100 points/mm²) carrying a Gaussian bump 0.15 mm high, 0.5 mm wide at half height,
/// whose top lies 0.3 mm from the nearest of core points 0.8 mm apart: that core point's
/// truth is 0.055 mm and only it exceeds the tolerance, so without densification no region
/// can form (one error point at most). With it the reference points around the bump become
/// core points: one region, at the bump, peak within 15 % (0.146-0.156 on noise seeds 1-10,
/// 26-35 points; found on 20 of 20 seeds); nothing elsewhere. A summit needs LoD within the
/// tolerance and a covered disc: with LoD within half of it (the first rule) noise seed 10's
/// core point (0.050, LoD 0.047, at the smallest radius) was no summit and the bump was
/// missed (docs/ALGORITHMS.md, adaptive step 11).
#[test]
fn densification_finds_a_bump_between_core_points() {
    let bump = Bump {
        top: Point3::new(4.3, 4.0, 0.0),
        height: 0.15,
        fwhm: 0.5,
        profile: Profile::Gaussian,
        scan_density: 100.0,
        noise: 0.01,
        core_step: 0.8,
        seed: 5,
    };
    let (core, reference, scan) = bump.case();
    let mut bad = CompareConfig::default();
    bad.adaptive.densify_above = Some(f64::NAN);
    let err = compare(&core, &reference, &scan, &bad)
        .unwrap_err()
        .to_string();
    assert!(err.contains("densify_above"), "{err}");
    let (dev, regions) = bump.run(&core, &reference, &scan, f64::INFINITY);
    assert_eq!(dev.added(), 0);
    assert!(regions.regions.is_empty(), "{:?}", regions.regions);
    let (dev, regions) = bump.run(&core, &reference, &scan, densify_above());
    assert!(dev.added() > 0);
    let peak = bump.found(&regions).expect("one region, at the bump");
    assert!(
        (peak - bump.height).abs() <= 0.15 * bump.height,
        "peak {peak} for height {}",
        bump.height
    );
}

/// Shapes of [`Bump`].
#[derive(Debug, Clone, Copy)]
enum Profile {
    /// exp(-r² / 2σ²).
    Gaussian,
    /// Linear flanks: half the height at half the `fwhm`, zero at the `fwhm`.
    Cone,
    /// A spherical cap whose base circle has the radius `fwhm`.
    Cap,
    /// Flat within half the `fwhm`, a cosine flank out to the `fwhm`.
    Plateau,
}

/// The default densification threshold (half the default tolerance).
fn densify_above() -> f64 {
    CompareConfig::default().densify_above()
}

/// A bump (Gaussian unless `profile` says otherwise) on the plane z = 0 over [0, 8]², sampled:
/// the reference every 0.1 mm with normals +z, core points every `core_step`, the scan at
/// random with `scan_density` points per mm² and Gaussian noise.
struct Bump {
    top: Point3<f64>,
    height: f64,
    /// Full width at half height, mm.
    fwhm: f64,
    profile: Profile,
    scan_density: f64,
    noise: f64,
    core_step: f64,
    seed: u64,
}

impl Bump {
    /// `profile` bump sampled as the 300k synth cases are: 19 scan points/mm² with 0.015 mm
    /// noise.
    fn at_300k(
        top: Point3<f64>,
        (height, fwhm): (f64, f64),
        profile: Profile,
        core_step: f64,
        seed: u64,
    ) -> Bump {
        Bump {
            top,
            height,
            fwhm,
            profile,
            scan_density: 19.0,
            noise: 0.015,
            core_step,
            seed,
        }
    }

    /// Core points, reference and scan.
    fn case(&self) -> (PointCloud, PointCloud, PointCloud) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.seed);
        let bump = |x: f64, y: f64| self.height_at(x, y);
        let lattice = |step: f64| -> Vec<Point3<f64>> {
            let n = (8.0 / step).round() as usize;
            (0..=n)
                .flat_map(|i| {
                    (0..=n).map(move |j| Point3::new(i as f64 * step, j as f64 * step, 0.0))
                })
                .collect()
        };
        let with_normals = |points: Vec<Point3<f64>>| PointCloud {
            normals: Some(vec![nalgebra::Vector3::z(); points.len()]),
            points,
            fields: Vec::new(),
        };
        let scan = PointCloud {
            points: (0..(64.0 * self.scan_density) as usize)
                .map(|_| {
                    let (x, y) = (rng.gen::<f64>() * 8.0, rng.gen::<f64>() * 8.0);
                    let (u1, u2): (f64, f64) = (rng.gen::<f64>().max(1e-300), rng.gen());
                    let noise =
                        self.noise * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
                    Point3::new(x, y, bump(x, y) + noise)
                })
                .collect(),
            normals: None,
            fields: Vec::new(),
        };
        (
            with_normals(lattice(self.core_step)),
            with_normals(lattice(0.1)),
            scan,
        )
    }

    /// The bump's height at (x, y).
    fn height_at(&self, x: f64, y: f64) -> f64 {
        let r = (x - self.top.x).hypot(y - self.top.y);
        let half = self.fwhm / 2.0;
        self.height
            * match self.profile {
                Profile::Gaussian => {
                    let sigma = self.fwhm / 2.3548;
                    (-r * r / (2.0 * sigma * sigma)).exp()
                }
                Profile::Cone => (1.0 - 0.5 * r / half).max(0.0),
                Profile::Cap => {
                    // The sphere through the top and the base circle of radius `fwhm`.
                    let (h, a) = (self.height, self.fwhm);
                    let sphere = (a * a + h * h) / (2.0 * h);
                    (((sphere * sphere - r * r).max(0.0).sqrt() - (sphere - h)) / h).max(0.0)
                }
                Profile::Plateau => {
                    // Flat within `half`, a cosine flank as wide again.
                    let t = ((r - half) / half).clamp(0.0, 1.0);
                    0.5 * (1.0 + (std::f64::consts::PI * t).cos())
                }
            }
    }

    /// The default comparison with `densify_above`, and its regions; with `densify_above`
    /// infinite, the cylinders alone (no densification, no peak fit and no model fill).
    fn run(
        &self,
        core: &PointCloud,
        reference: &PointCloud,
        scan: &PointCloud,
        densify_above: f64,
    ) -> (Deviations, Regions) {
        let mut cfg = CompareConfig::default();
        cfg.adaptive.densify_above = Some(densify_above);
        cfg.adaptive.model_fill = densify_above.is_finite();
        cfg.adaptive.peak_fit = densify_above.is_finite();
        let dev = compare(core, reference, scan, &cfg).unwrap();
        let regions = find_regions(&dev, &RegionConfig::default());
        (dev, regions)
    }

    /// The peak of the only region when there is one, within 0.2 mm of the top.
    fn found(&self, regions: &Regions) -> Option<f64> {
        self.region(regions).map(|r| r.peak)
    }

    /// The one region at the top, if that is what `regions` holds.
    fn region<'a>(&self, regions: &'a Regions) -> Option<&'a Region> {
        match &regions.regions[..] {
            [region] if (Point3::from(region.centroid) - self.top).norm() < 0.2 => Some(region),
            _ => None,
        }
    }
}

/// Bumps narrower than the smallest cylinder, as the 300k synth cases have (seed 22's
/// 0.32 mm high, 0.44 mm wide one): 0.3 mm high, 0.44 mm wide, 19 scan points/mm² with
/// 0.015 mm noise (the smallest cylinder, 12 scan points, is 0.45 mm in radius), the top
/// 0.28 mm from the nearest of core points 0.4 mm apart; 20 noise seeds. The cylinders miss
/// them (no region on 19 of 20 seeds: half of r0's reference points still match, so the radius
/// grows and the bump's points are trimmed). With densification one region at the bump on
/// every seed: on 17 a peak model fitted where the scan's own heights (δ) rise measures it
/// (`Reason::PeakModel`), on 2 the cylinders at the added core points do. The peak is within
/// 10 % on 15 seeds (the others +14 %, -10.1 %, +18 %, +12 %, and -44 % on the seed the
/// cylinders find alone): about 8 scan points lie on such a bump. Requiring 8 supporting
/// points (the peak fit's own floor) left 5 of 20 without a region.
#[test]
fn bumps_narrower_than_the_cylinders_are_measured_by_a_peak_model() {
    let (mut found_by_cylinders, mut within, mut modelled) = (0, 0, 0);
    for seed in 1..=20 {
        let bump = Bump::at_300k(
            Point3::new(4.2, 4.2, 0.0),
            (0.3, 0.44),
            Profile::Gaussian,
            0.4,
            seed,
        );
        let (core, reference, scan) = bump.case();
        let (_, regions) = bump.run(&core, &reference, &scan, f64::INFINITY);
        let by_cylinders = !regions.regions.is_empty();
        found_by_cylinders += usize::from(by_cylinders);
        let (dev, regions) = bump.run(&core, &reference, &scan, densify_above());
        let peak = bump
            .found(&regions)
            .unwrap_or_else(|| panic!("seed {seed}: {:?}", regions.regions));
        within += usize::from((peak - bump.height).abs() <= 0.1 * bump.height);
        let model = dev
            .values
            .iter()
            .any(|v| v.reason == polishbot::compare::Reason::PeakModel);
        modelled += usize::from(model);
        eprintln!(
            "seed {seed}: peak {peak:.4}, cylinders alone {by_cylinders}, peak model {model}"
        );
    }
    assert!(found_by_cylinders <= 1, "{found_by_cylinders}");
    assert!(modelled >= 15, "a peak model on {modelled} of 20");
    assert!(within >= 14, "{within} of 20 peaks within 10 %");
}

/// RMS error (over the given core points where the truth exceeds 0.01 mm) and IoU (points
/// beyond the default tolerance, 0.05 mm) of the default comparison of `bump`, with or
/// without the model fill, and how many core points a model measured.
fn bump_scores(bump: &Bump, model_fill: bool) -> (f64, f64, usize) {
    let (core, reference, scan) = bump.case();
    let mut cfg = CompareConfig::default();
    cfg.adaptive.model_fill = model_fill;
    let dev = compare(&core, &reference, &scan, &cfg).unwrap();
    let (mut sum2, mut n, mut both, mut either, mut modelled) = (0.0, 0, 0, 0, 0);
    for (p, v) in dev.points.iter().zip(&dev.values).take(dev.given) {
        let truth = bump.height_at(p.x, p.y);
        modelled += usize::from(v.reason == polishbot::compare::Reason::PeakModel);
        if truth > 0.01 {
            sum2 += (v.distance - truth).powi(2);
            n += 1;
        }
        let (is_true, detected) = (truth > 0.05, v.significant && v.distance > 0.05);
        both += usize::from(is_true && detected);
        either += usize::from(is_true || detected);
    }
    (
        (sum2 / n as f64).sqrt(),
        both as f64 / either as f64,
        modelled,
    )
}

/// The model fill (adaptive step 13) on bumps of four shapes, three sizes and four noise seeds
/// each, at 300k-like density (19 scan points/mm², 0.015 mm noise), core points 0.2 mm apart.
/// Gaussian bumps (what the peak model is) are measured much better: mean RMS 0.0129 →
/// 0.0049 mm, mean IoU 0.83 → 0.92. Cones, spherical caps and flat-topped plateaus are not
/// Gaussians: where a Gaussian was accepted on them anyway, the profile test (mean residuals
/// per level of the model, chi-square) refuses the flat tops and most caps, and no case ends
/// up worse than the cylinders (without the profile test a 0.1 mm plateau read
/// 0.0164-0.0181 mm RMS against 0.0121-0.0148 mm; with four levels tested one by one,
/// 0.0175 against 0.0144 on one seed).
#[test]
fn model_fill_measures_gaussian_defects_and_spares_other_shapes() {
    let profiles = [
        Profile::Gaussian,
        Profile::Cone,
        Profile::Cap,
        Profile::Plateau,
    ];
    let mut gaussian = [[0.0; 2]; 2];
    for profile in profiles {
        for (height, fwhm) in [(0.1, 1.0), (0.3, 0.8), (0.2, 1.6)] {
            for seed in 1..=4 {
                let bump = Bump::at_300k(
                    Point3::new(4.1, 3.9, 0.0),
                    (height, fwhm),
                    profile,
                    0.2,
                    seed,
                );
                let (rms_off, iou_off, none) = bump_scores(&bump, false);
                let (rms_on, iou_on, modelled) = bump_scores(&bump, true);
                let case = format!("{profile:?} {height} mm high, {fwhm} mm wide, seed {seed}");
                eprintln!(
                    "{case}: RMS {rms_off:.4} -> {rms_on:.4}, IoU {iou_off:.3} -> {iou_on:.3}, \
                     {modelled} core points modelled"
                );
                assert_eq!(none, 0, "{case}");
                assert!(rms_on <= rms_off + 0.0005, "{case}: worse with the fill");
                if let Profile::Gaussian = profile {
                    assert!(modelled > 0, "{case}: no model");
                    for (k, (off, on)) in [(rms_off, rms_on), (iou_off, iou_on)].iter().enumerate()
                    {
                        gaussian[k][0] += off / 12.0;
                        gaussian[k][1] += on / 12.0;
                    }
                }
            }
        }
    }
    let [rms, iou] = gaussian;
    eprintln!("Gaussian bumps: mean RMS {rms:?}, mean IoU {iou:?}");
    assert!(rms[1] <= 0.5 * rms[0], "{rms:?}");
    assert!(iou[1] >= iou[0] + 0.05, "{iou:?}");
}

/// Issue 5's acceptance targets (IoU >= 0.95, RMS <= 0.01 mm, every peak within 10 %): at
/// 300,000 scan points RMS is met since the model fill (0.0042 / 0.0048 mm on seeds 11 / 12;
/// every one of seeds 11-34 within 0.0087 mm) and IoU on seed 11 (0.975), not on seed 12
/// (0.935: a few of its 120 true error points read just inside the tolerance, a few just
/// outside read just beyond it; docs/ALGORITHMS.md, step 13, "What is left"), and seed 11's narrow 0.29 mm bump is reported -11 %.
/// At 1.2 million (POLISHBOT_SCAN_POINTS=1200000) every target is met on both seeds.
/// docs/ALGORITHMS.md, adaptive step 13. Run with --ignored.
#[test]
#[ignore]
fn acceptance_targets() {
    for (seed, ours, _) in scores(300_000) {
        assert!(ours.iou >= 0.95, "seed {seed}: IoU {}", ours.iou);
        assert!(ours.rms <= 0.01, "seed {seed}: RMS {}", ours.rms);
        assert_peaks(seed, &ours, 0.0, 0.1);
    }
}

/// `polishbot synth` of femoral_dm (seed 4) with these point counts into `case`.
fn synth_femoral_case(case: &Path, reference_points: &str, scan_points: &str) {
    let data = common::shared_data("femoral_dm.stl");
    let status = common::polishbot()
        .args(["synth", "--mesh", data.to_str().unwrap(), "--units", "m"])
        .args(["--seed", "4", "--reference-points", reference_points])
        .args(["--scan-points", scan_points, "--out"])
        .arg(case)
        .status()
        .unwrap();
    assert!(status.success());
}

/// `polishbot inspect` of a synth `case` at its true pose into `out`, with `extra` options.
fn inspect_with_true_pose(case: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    common::polishbot()
        .arg("inspect")
        .arg("--reference")
        .arg(case.join("reference.ply"))
        .arg("--scan")
        .arg(case.join("scan.ply"))
        .arg("--pose")
        .arg(case.join("truth.json"))
        .args(extra)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap()
}

/// A reference cloud no larger than the core-point sample makes every reference point a core
/// point, and densification has nothing left to add around a defect's top (docs/ALGORITHMS.md,
/// Comparison: 10 defects missed on seeds 11-34 at 300k instead of 6): `inspect` says so on
/// stderr and in the report's summary; with a larger reference it says which share it took.
#[test]
fn inspect_warns_when_every_reference_point_is_a_core_point() {
    let dir = common::tempdir();
    for (reference_points, warned, sample) in [
        ("30000", true, "all 30000 reference points"),
        ("60000", false, "50000 of 60000 reference points"),
    ] {
        let case = dir.path().join(reference_points);
        synth_femoral_case(&case, reference_points, "40000");
        let out = case.join("out");
        let run = inspect_with_true_pose(&case, &out, &[]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "{stderr}");
        assert_eq!(
            stderr.contains("every one of the 30000 reference points is a core point"),
            warned,
            "{stderr}"
        );
        let report = std::fs::read_to_string(out.join("report.html")).unwrap();
        assert!(
            report.contains(sample),
            "{reference_points}: no '{sample}' in the report"
        );
    }
}

#[test]
fn inspect_writes_the_design_files() {
    let dir = common::tempdir();
    let case = dir.path().join("case");
    let out = dir.path().join("out");
    synth_femoral_case(&case, "120000", "90000");
    let run = inspect_with_true_pose(
        &case,
        &out,
        &["--tolerance", "0.05", "--method", "adaptive"],
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("verdict:"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("deviations.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "x,y,z,nx,ny,nz,distance,uncertainty,significant,radius,n_ref,n_scan,region"
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    // 50,000 selected core points (the default for a scan of 90,000 points, see
    // `default_count`), then those added around the defects' tops.
    let added = count_before(&stdout, " added around defects", '(');
    assert!(added > 0, "{stdout}");
    assert_eq!(rows.len(), 50_000 + added);
    // Rows measured by a defect model have n_ref 0 and a distance; the summary counts them.
    let modelled = count_before(&stdout, " measured by defect models", ' ');
    let n_ref_0 = rows
        .iter()
        .filter(|r| r[10] == 0.0 && r[6].is_finite())
        .count();
    assert!(
        modelled > 0 && modelled == n_ref_0,
        "{modelled} / {n_ref_0}: {stdout}"
    );
    let ply = std::fs::read(out.join("deviations.ply")).unwrap();
    let head = String::from_utf8_lossy(&ply[..600]);
    for field in [
        "distance",
        "uncertainty",
        "significant",
        "radius",
        "n_ref",
        "n_scan",
        "region",
    ] {
        assert!(
            head.contains(&format!("property float {field}\n")),
            "{head}"
        );
    }
    let ply_cloud =
        polishbot::cloud::load_cloud(&out.join("deviations.ply"), None, Some(Units::Mm)).unwrap();
    assert_eq!(ply_cloud.len(), rows.len());
    let regions: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("regions.json")).unwrap()).unwrap();
    let list = regions["regions"].as_array().unwrap();
    // Every region id in the CSV is a region of regions.json with that many points.
    for r in list {
        let id = r["id"].as_f64().unwrap();
        let n = rows.iter().filter(|row| row[12] == id).count();
        assert_eq!(n as u64, r["points"].as_u64().unwrap());
        assert_eq!(
            r["repairable"].as_bool().unwrap(),
            r["peak"].as_f64().unwrap() > 0.0
        );
    }
    // The truth pose went into registration.json.
    let reg: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("registration.json")).unwrap())
            .unwrap();
    let truth = polishbot::synth::Truth::load(&case.join("truth.json")).unwrap();
    assert_eq!(
        reg["scan_to_reference"][1][3].as_f64().unwrap(),
        truth.scan_to_reference[1][3]
    );
    // Bad input: one line naming the file.
    let bad = common::polishbot()
        .args(["inspect", "--reference", "/nonexistent.ply", "--scan"])
        .arg(case.join("scan.ply"))
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("/nonexistent.ply") && err.trim().lines().count() == 1,
        "{err}"
    );
}

/// Writes a synth case (femoral_dm with its contact surface, default densities) into `case`.
fn synth_files(case: &Path, seed: u64) {
    common::succeed(
        common::polishbot()
            .arg("synth")
            .arg("--mesh")
            .arg(common::shared_data("femoral_dm.stl"))
            .arg("--surface")
            .arg(common::shared_data("femoral_dm_contact.stl"))
            .args(["--units", "m", "--seed", &seed.to_string(), "--out"])
            .arg(case),
    );
}

/// Runs `polishbot inspect` with `extra` arguments into `out`; panics with its stderr.
fn inspect(reference: &Path, scan: &Path, out: &Path, extra: &[&str]) {
    common::succeed(
        common::polishbot()
            .arg("inspect")
            .arg("--reference")
            .arg(reference)
            .arg("--scan")
            .arg(scan)
            .args(extra)
            .arg("-o")
            .arg(out),
    );
}

/// The count printed in `stdout` right before `label`, after the last `start` before it
/// (the summary line's "N (K added around defects, M measured by defect models, ...)").
fn count_before(stdout: &str, label: &str, start: char) -> usize {
    stdout
        .split(label)
        .next()
        .and_then(|head| head.rsplit(start).next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count before {label:?}: {stdout}"))
}

/// IoU, against truth.json, of the error points (significant, beyond the tolerance) that
/// `inspect` wrote into `out`/deviations.csv.
fn csv_iou(out: &Path, truth: &Path) -> f64 {
    let truth = polishbot::synth::Truth::load(truth).unwrap();
    let tol = RegionConfig::default().tolerance;
    let csv = std::fs::read_to_string(out.join("deviations.csv")).unwrap();
    let (mut both, mut either) = (0usize, 0usize);
    for line in csv.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let p = Point3::new(v[0], v[1], v[2]);
        let n = nalgebra::Vector3::new(v[3], v[4], v[5]);
        let is_true = truth.deviation_at(&p, &n).abs() > tol;
        let detected = v[8] == 1.0 && v[6].abs() > tol;
        both += usize::from(is_true && detected);
        either += usize::from(is_true || detected);
    }
    both as f64 / either.max(1) as f64
}

/// The whole `inspect` as a user runs it (outlier filter, registration, comparison; no
/// truth pose) finds seed 11's defects as well as the comparison does from the true pose
/// (`adaptive_finds_the_planted_defects_and_beats_classic`: IoU 0.905 over the given core
/// points; this test, over every row of deviations.csv, the points densification added at
/// defect tops included: 0.944). The LoD's
/// registration term is the pose's uncertainty (registration.json `registration_error`, a
/// few 10⁻⁴ mm), not a residual RMSE: the point-to-plane RMSE (0.028 mm) would keep every
/// deviation below 0.055 mm insignificant and drop the IoU to 0.77.
#[test]
fn registered_inspection_scores_like_the_true_pose() {
    let dir = common::tempdir();
    let (case, out) = (dir.path().join("case"), dir.path().join("out"));
    synth_files(&case, 11);
    inspect(
        &case.join("reference.ply"),
        &case.join("scan.ply"),
        &out,
        &[],
    );
    let reg: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("registration.json")).unwrap())
            .unwrap();
    let reg_error = reg["registration_error"].as_f64().unwrap();
    assert!(reg_error > 0.0 && reg_error < 0.005, "{reg_error}");
    let iou = csv_iou(&out, &case.join("truth.json"));
    eprintln!("registered inspection, seed 11: IoU {iou:.3}, registration error {reg_error}");
    assert!(iou >= 0.85, "IoU {iou}");
}

/// A reference cloud without normals gets PCA normals oriented outward by propagation
/// (`compare::cloud_reference`): against femoral_dm.stl's facet normals, none of 400,000 is
/// flipped (beyond 120°; Prim with Hoppe's cost alone on a 30k sample flipped 53, a patch
/// beside a 1.1 mm wall), and `inspect` with that cloud finds seed 12's defects as with the
/// mesh normals.
#[test]
fn a_reference_cloud_without_normals_is_oriented_outward() {
    let mesh =
        match polishbot::cloud::load(&common::shared_data("femoral_dm.stl"), None, Some(Units::M))
            .unwrap()
            .geometry
        {
            polishbot::cloud::Geometry::Mesh { mesh, .. } => mesh,
            polishbot::cloud::Geometry::Cloud(_) => panic!("femoral_dm.stl has faces"),
        };
    let sampled = polishbot::compare::mesh_reference(&mesh, 400_000, 1).unwrap();
    let bare = PointCloud::from_points(sampled.points.clone());
    let (oriented, note) = polishbot::compare::cloud_reference(bare).unwrap();
    let (est, truth) = (oriented.normals.unwrap(), sampled.normals.unwrap());
    let flipped = est
        .iter()
        .zip(&truth)
        .filter(|(a, b)| a.dot(b) < -0.5)
        .count();
    let disagree = est
        .iter()
        .zip(&truth)
        .filter(|(a, b)| a.dot(b) < 0.0)
        .count();
    eprintln!("{note}: {flipped} flipped, {disagree} of 400000 on the wrong side of 90°");
    assert_eq!(flipped, 0);
    assert!(disagree <= 40, "{disagree}");

    let dir = common::tempdir();
    let case = dir.path().join("case");
    synth_files(&case, 12);
    let reference = polishbot::cloud::load_cloud(&case.join("reference.ply"), None, None).unwrap();
    assert!(reference.normals.is_some());
    let bare_file = dir.path().join("bare.ply");
    polishbot::cloud::write_ply(
        &bare_file,
        &PointCloud::from_points(reference.points),
        None,
        polishbot::cloud::PlyPrecision::F64,
    )
    .unwrap();
    let (with, without) = (dir.path().join("with"), dir.path().join("without"));
    let pose = case.join("truth.json");
    let pose = ["--pose", pose.to_str().unwrap()];
    inspect(
        &case.join("reference.ply"),
        &case.join("scan.ply"),
        &with,
        &pose,
    );
    inspect(&bare_file, &case.join("scan.ply"), &without, &pose);
    let (iou_with, iou_without) = (
        csv_iou(&with, &case.join("truth.json")),
        csv_iou(&without, &case.join("truth.json")),
    );
    eprintln!("seed 12 IoU: reference normals {iou_with:.3}, estimated {iou_without:.3}");
    assert!(
        iou_without >= iou_with - 0.03,
        "{iou_without} vs {iou_with}"
    );
    let summary = std::fs::read_to_string(without.join("report.html")).unwrap();
    assert!(
        summary.contains("propagated"),
        "the report says where the normals came from"
    );
}

/// Peaks of `Gaussian` defects (height, FWHM) at 19 scan points/mm² with 0.015 mm noise and
/// core points 0.57 mm apart (`inspect`'s default spacing at 300k), with the top at `top`,
/// noise seeds 1..=20: the peak of the only region near the top, or None.
fn small_defect_peaks(defects: &[(f64, f64)], top: Point3<f64>) -> Vec<Option<(f64, f64)>> {
    let mut peaks = Vec::new();
    for &(height, fwhm) in defects {
        for seed in 1..=20 {
            let bump = Bump::at_300k(top, (height, fwhm), Profile::Gaussian, 0.57, seed);
            let (core, reference, scan) = bump.case();
            let (_, regions) = bump.run(&core, &reference, &scan, densify_above());
            peaks.push(bump.found(&regions).map(|peak| (peak, height)));
        }
        eprintln!(
            "{height} mm, {fwhm} mm wide: {:?}",
            &peaks[peaks.len() - 20..]
        );
    }
    peaks
}

/// Defects a little beyond the tolerance and narrower than the largest cylinder (1.26 mm):
/// the cylinders there read them at about half their height, between `densify_above` and the
/// tolerance, so step 10's summit fits (error points only) do not look at them, and the
/// scan's own heights (δ) hold too few points beyond the tolerance for step 12's search. A
/// peak model at each such summit (step 12) finds them: 59 of 60 instead of 52 (seeds 24,
/// 27 and 34 at 300k: 0.054-0.074 mm defects missed before).
#[test]
fn shallow_narrow_defects_are_found_by_a_peak_model() {
    let peaks = small_defect_peaks(
        &[(-0.075, 0.8), (0.07, 0.9), (-0.065, 1.0)],
        Point3::new(4.2, 4.2, 0.0),
    );
    let found = peaks.iter().flatten().count();
    assert!(found >= 57, "{found} of 60 found");
}

/// Deep defects narrower than the smallest cylinder whose top lies 0.14 mm from a core point:
/// that core point's cylinder (0.45 mm) reads them at a third to a half of their height, and
/// a peak fit started there cut their top off as beyond twice that (seed 45 at 300k: a
/// 0.39 mm deep, 0.57 mm wide pit read 0.16 mm). Started from the second largest scan height
/// near the summit: 37 of 40 peaks within 25 % instead of 35.
#[test]
fn deep_narrow_pits_keep_their_depth() {
    let peaks = small_defect_peaks(&[(-0.39, 0.57), (-0.3, 0.45)], Point3::new(4.66, 4.66, 0.0));
    let within = peaks
        .iter()
        .flatten()
        .filter(|(peak, height)| (peak - height).abs() <= 0.25 * height.abs())
        .count();
    assert!(within >= 36, "{within} of 40 peaks within 25 %");
}

/// A pit 0.366 mm deep and 0.43 mm wide (seed 72 at 300k) whose bottom no scan point comes
/// near: the scan points within 0.1, 0.15 or 0.2 mm of its centre removed, 20 noise seeds
/// each. Its peak model then follows the points around it but does not pin its depth (seed
/// 72: 0.73 ± 0.27 mm, 4 supporting points) and was refused, and the cylinders read it at a
/// few hundredths: missed on 11 of 60 runs (seed 72: missed). Measured by its point pairs
/// when the model follows the points and 3 scan points lie far beyond the tolerance, it is
/// missed on 5 of 60 (seed 72: found, -0.200 mm, a lower bound of its depth); 6 runs use
/// point pairs, and `inspect`'s summary line says so (their peaks are lower bounds).
#[test]
fn a_deep_narrow_pit_without_a_scan_point_at_its_bottom_makes_a_region() {
    let top = Point3::new(4.845, 4.845, 0.0);
    let (mut found, mut paired, mut bounded) = (0, 0, 0);
    for hole in [0.1, 0.15, 0.2] {
        for seed in 1..=20 {
            let bump = Bump::at_300k(top, (-0.366, 0.43), Profile::Gaussian, 0.57, seed);
            let (core, reference, mut scan) = bump.case();
            scan.points
                .retain(|p| (p.x - top.x).hypot(p.y - top.y) > hole);
            let (dev, regions) = bump.run(&core, &reference, &scan, densify_above());
            let region = bump.region(&regions);
            found += usize::from(region.is_some());
            // A peak flagged as a lower bound is one: within the pit's depth (plus 3 noise
            // SDs: a point pair is one noisy reading).
            if let Some(r) = region.filter(|r| r.peak_lower_bound) {
                bounded += 1;
                assert!(r.peak < 0.0 && r.peak > -0.366 - 0.045, "{r:?}");
            }
            // The summary says when peaks are lower bounds.
            paired += usize::from(dev.point_pairs() > 0);
            assert_eq!(
                dev.point_pairs() > 0,
                dev.summary().contains("lower bounds"),
                "{}",
                dev.summary()
            );
        }
    }
    assert!(found >= 54, "{found} of 60 found");
    assert!(paired >= 5, "point pairs measured {paired} of 60 runs");
    eprintln!("found {found}, point pairs in {paired}, peak a lower bound in {bounded} of 60");
    assert!(
        bounded >= 5,
        "peaks flagged as lower bounds in {bounded} of 60 runs"
    );
}

/// Defects wider than the peak window reaches (2.3 mm at 19 scan points/mm²): the tolerance
/// crosses a 0.42 mm, 2.75 mm wide bump 2.4 mm from its top. A model is refitted over 3.5 of
/// its standard deviations (at most twice its window), so that its window holds the defect's
/// foot and the crossing: over three such bumps and four noise seeds, core points 0.2 mm
/// apart, mean RMS 0.0034 → 0.0018 mm and mean IoU 0.948 → 0.968 (seed 32 at 300k: IoU
/// 0.872 → 0.923 from its 2.2 mm wide, 0.068 mm deep pit).
#[test]
fn wide_defects_are_measured_by_a_widened_model() {
    let (mut rms, mut iou) = (Vec::new(), Vec::new());
    for (height, fwhm) in [(0.42, 2.75), (0.15, 2.5), (0.1, 2.9)] {
        for seed in 1..=4 {
            let bump = Bump::at_300k(
                Point3::new(4.0, 4.0, 0.0),
                (height, fwhm),
                Profile::Gaussian,
                0.2,
                seed,
            );
            let (r, i, _) = bump_scores(&bump, true);
            eprintln!("{height} mm, {fwhm} mm wide, seed {seed}: RMS {r:.4}, IoU {i:.3}");
            rms.push(r);
            iou.push(i);
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(mean(&rms) <= 0.0025, "mean RMS {}", mean(&rms));
    assert!(mean(&iou) >= 0.96, "mean IoU {}", mean(&iou));
}

//! Small and narrow defects on synthetic planes: densification, peak models, the model fill.
use super::*;

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

/// A grind's loss at a conform rim point, as the closed loop meets it (survey case 161, cell
/// 29): a dip 0.03 mm deep and 1 mm wide at half depth, at the simulated scans' 8 points/mm²
/// with 0.015 mm noise, core points 0.4 mm apart, 10 noise seeds. At the core point nearest
/// its bottom (truth -0.0284 mm) the adaptive comparison's cylinders, grown to the radius the
/// noise asks, read 0.29 of the depth on average (-0.0081 mm, one seed +0.0004), the classic
/// reading at the tool's footprint (`cycle::FINE_RADIUS_MM`, which the loop's planner reads,
/// `cycle::planner_input`) 0.60 (-0.0170 mm), deeper on every seed.
#[test]
fn a_ground_dip_reads_deeper_at_the_tools_footprint() {
    let (mut wide, mut fine, mut truth) = (0.0, 0.0, 0.0);
    let seeds = 1..=10;
    for seed in seeds.clone() {
        let mut dip = Bump::at_300k(
            Point3::new(4.1, 3.9, 0.0),
            (-0.03, 1.0),
            Profile::Gaussian,
            0.4,
            seed,
        );
        dip.scan_density = 8.0;
        let (mut core, reference, scan) = dip.case();
        // off the plane the flat reference lattice lies in, which two slabs of a classic
        // cylinder share and both leave out (`reference_near`)
        core.points.iter_mut().for_each(|p| p.z += 1e-4);
        let nearest = (0..core.points.len())
            .min_by(|&a, &b| {
                let d = |i: usize| (core.points[i] - dip.top).norm();
                d(a).total_cmp(&d(b))
            })
            .unwrap();
        let adaptive = compare(&core, &reference, &scan, &CompareConfig::default()).unwrap();
        let classic = CompareConfig {
            method: Method::Classic,
            radius: Some(polishbot::cycle::FINE_RADIUS_MM),
            ..CompareConfig::default()
        };
        let footprint = compare(&core, &reference, &scan, &classic).unwrap();
        let p = core.points[nearest];
        let (w, f) = (
            adaptive.values[nearest].distance,
            footprint.values[nearest].distance,
        );
        let t = dip.height_at(p.x, p.y);
        eprintln!("seed {seed}: truth {t:.4}, adaptive {w:.4}, footprint {f:.4}");
        assert!(
            f < w,
            "seed {seed}: the footprint read {f:.4} mm, the cylinders {w:.4} mm"
        );
        truth += t / 10.0;
        wide += w / 10.0;
        fine += f / 10.0;
    }
    eprintln!("mean: truth {truth:.4}, adaptive {wide:.4}, footprint {fine:.4}");
    assert!(
        fine <= 0.5 * truth && wide >= 0.4 * truth,
        "{fine} {wide} {truth}"
    );
}

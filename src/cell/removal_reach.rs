//! How far the tool really ground beyond where its plan predicted removal (issue 50, "learn
//! where the tool really grinds ... from every rescan"): after a grind, the measured removal
//! (the deviation before minus the deviation after, at the same core points) at the points
//! outside every region and outside the plan's predicted footprint (predicted removal below
//! [`ReachConfig::planned_mm`]) is binned by each point's distance to that footprint; the far
//! field ([`ReachConfig::far_mm`], where no removal reaches) gives the inspections' null level
//! and scatter, and the reach is the outer edge of the farthest bin whose mean removal stands
//! above that null by [`ReachConfig::z`] standard errors and by [`ReachConfig::least_mm`].
//! The bins pool every region of the plan: a rim loss is a few hundredths of a millimetre
//! under a noise of about as much per point, and only an average over tens of points sees it.
//! Measured against the plan's own prediction (the removal moved by the carried aim), the
//! reach holds the grind's landing error beside the footprint's widening; the next plan's
//! landing margin is at least it (`motion::landing::landing_margins`, through `motion::aim::Aim`).
//! Checked against the simulator's truth on the int13 survey's kept runs (documented arm, ten
//! cases, cell seed 29): after grind 1 the reach read 0.75-2.75 mm where the true removal's
//! 95th percentile per bin stayed above 0.005 mm out to 0.75-2.75 mm, never less than the
//! truth; grinds 2 and 3 remove less and read 0 mm in 4 of 16 where the truth reached
//! 0.75-1.75 mm, which is why the loop carries the largest reach of its grinds.
//! Method: docs/ALGORITHMS.md, "How far the tool really grinds".
use nalgebra::Point3;

use crate::removal::matching::GrindPair;
use crate::spatial::Neighbours;

/// Settings of the reach's reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReachConfig {
    /// Least predicted removal inside the plan's footprint, mm (0.005: the removal fit's least
    /// predicted removal, as `removal_shift::ShiftConfig::planned_mm`).
    pub planned_mm: f64,
    /// Width of a distance bin, mm (0.25: the core points lie 0.3-0.5 mm apart, so a bin one
    /// patch radius long around a footprint holds 10-80 points).
    pub bin_mm: f64,
    /// The far field, from and to, mm beyond the footprint (3.5-5: the kept runs' true
    /// removal beyond 3.5 mm stayed under 0.0011 mm; 1.5 mm wide, it holds hundreds of points).
    pub far_mm: [f64; 2],
    /// Standard errors a bin's mean must stand above the far field's (3: 14 bins are tested
    /// per grind, and a one-sided 3-sigma false reading in any of them is about 2 %).
    pub z: f64,
    /// Least scatter per point taken for the far field, mm (0.003: the far field's measured
    /// scatter after the int13 survey's first grinds, 0.0028-0.0036 mm; later inspections
    /// that keep the unchanged points' values read 0.0000-0.0002 mm there, which would make
    /// any mean significant).
    pub noise_floor_mm: f64,
    /// Least mean removal above the far field's that counts as reach, mm (0.001: the rescan
    /// reads narrow rim loss at 0.3-0.47 of its depth, `motion::dwell::RIM_READ_SHARE`, so a
    /// true loss of 0.003 mm, a seventeenth of the 0.05 mm tolerance, reads about this).
    pub least_mm: f64,
    /// Least points in a bin (and in the far field) for its mean to be read (8).
    pub least_points: usize,
}

impl Default for ReachConfig {
    fn default() -> Self {
        ReachConfig {
            planned_mm: 0.005,
            bin_mm: 0.25,
            far_mm: [3.5, 5.0],
            z: 3.0,
            noise_floor_mm: 0.003,
            least_mm: 0.001,
            least_points: 8,
        }
    }
}

/// What one grind's reach reading found.
#[derive(Debug, Clone, PartialEq)]
pub struct RemovalReach {
    /// How far beyond the predicted footprint the measured removal reached, mm (0: no bin
    /// stands above the far field).
    pub reach_mm: f64,
    /// Mean and scatter (at least the floor) of the measured removal in the far field, mm.
    pub far_mm: [f64; 2],
    /// Per bin: its outer distance, its points and its mean measured removal, mm.
    pub bins: Vec<(f64, usize, f64)>,
}

/// The reach of `points` (each: its distance beyond the predicted footprint, mm, and its
/// measured removal, mm): the outer edge of the farthest bin of `cfg.bin_mm` before the far
/// field whose mean stands above the far field's mean by `cfg.z` standard errors (the far
/// field's scatter, at least `cfg.noise_floor_mm`, over the bin's points) and by
/// `cfg.least_mm`. None when the far field holds fewer than `cfg.least_points`.
pub fn reach_of(points: &[(f64, f64)], cfg: &ReachConfig) -> Option<RemovalReach> {
    let far: Vec<f64> = (points.iter())
        .filter(|(d, _)| (cfg.far_mm[0]..cfg.far_mm[1]).contains(d))
        .map(|(_, m)| *m)
        .collect();
    if far.len() < cfg.least_points {
        return None;
    }
    let n = far.len() as f64;
    let mean = far.iter().sum::<f64>() / n;
    let sd = (far.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let sd = sd.max(cfg.noise_floor_mm);
    let count = (cfg.far_mm[0] / cfg.bin_mm).ceil() as usize;
    let mut sums = vec![(0usize, 0.0); count];
    let before_far = points
        .iter()
        .filter(|(d, _)| (0.0..cfg.far_mm[0]).contains(d));
    for (d, m) in before_far {
        // the bins reach the far field: only a division rounded up onto its edge has none
        if let Some(sum) = sums.get_mut((d / cfg.bin_mm) as usize) {
            sum.0 += 1;
            sum.1 += m;
        }
    }
    let mut reach_mm = 0.0;
    let mut bins = Vec::with_capacity(count);
    for (b, (k, s)) in sums.iter().enumerate() {
        let outer = (b + 1) as f64 * cfg.bin_mm;
        let m = if *k > 0 { s / *k as f64 } else { f64::NAN };
        bins.push((outer, *k, m));
        let excess = m - mean;
        if *k >= cfg.least_points && excess > (cfg.z * sd / (*k as f64).sqrt()).max(cfg.least_mm) {
            reach_mm = outer;
        }
    }
    Some(RemovalReach {
        reach_mm,
        far_mm: [mean, sd],
        bins,
    })
}

/// How far beyond the predicted footprint of a grind's plan (`predicted`, removal per core
/// point of `pair.before`, mm) its measured removal (`pair.before` minus `pair.after` at the
/// same core points) reached: [`reach_of`] over the points of `pair.before` outside every
/// region, outside the footprint and measured in both, each at its distance to the nearest
/// footprint point.
/// None when the plan predicted no removal or the far field is too thin to read.
pub fn measure(pair: &GrindPair, predicted: &[f64], cfg: &ReachConfig) -> Option<RemovalReach> {
    let before = pair.before;
    let inside = |i: usize| predicted.get(i).is_some_and(|p| *p >= cfg.planned_mm);
    let footprint: Vec<Point3<f64>> = (before.points.iter().enumerate())
        .filter(|(i, _)| inside(*i))
        .map(|(_, p)| p.position)
        .collect();
    if footprint.is_empty() {
        return None;
    }
    let index = Neighbours::new(&footprint);
    let points: Vec<(f64, f64)> = (before.points.iter().enumerate())
        .filter(|(i, p)| p.region < 0 && !inside(*i))
        .filter_map(|(i, p)| {
            let m = pair.removal(i)?;
            let d = index.nearest(&p.position)?.dist2.sqrt();
            m.is_finite().then_some((d, m))
        })
        .collect();
    reach_of(&points, cfg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::repair::{Inspection, SurfacePoint};
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A flat part: core points 0.35 mm apart over 16 x 16 mm, each with its distance from
    /// the centre.
    fn grid() -> Vec<(Point3<f64>, f64)> {
        let n = (16.0 / 0.35) as i32;
        let mut out = Vec::new();
        for i in 0..=n {
            for j in 0..=n {
                let p = Point3::new(i as f64 * 0.35 - 8.0, j as f64 * 0.35 - 8.0, 0.0);
                out.push((p, p.coords.norm()));
            }
        }
        out
    }

    fn inspection(points: Vec<SurfacePoint>) -> Inspection {
        Inspection {
            dir: std::path::PathBuf::new(),
            tolerance: Some(0.05),
            regions: Vec::new(),
            points,
            fine: Vec::new(),
        }
    }

    /// A plan predicting 0.04 mm of removal over a disc of 2 mm radius (region 0), the real
    /// removal that disc plus a skirt `wider` mm farther out whose depth falls from 0.012 to
    /// 0.004 mm (the rim loss the rescan reads at about a third of its depth), both
    /// inspections with 0.0025 mm of noise per point: the reach read.
    fn planted(wider: f64, seed: u64) -> f64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut before, mut after, mut predicted) = (Vec::new(), Vec::new(), Vec::new());
        for (p, r) in grid() {
            let planned = if r <= 2.0 { 0.04 } else { 0.0 };
            let skirt = match r - 2.0 {
                x if x > 0.0 && x <= wider => 0.012 - 0.008 * x / wider,
                _ => 0.0,
            };
            let removed = planned + skirt;
            let dev = 0.1;
            let point = |distance: f64| SurfacePoint {
                position: p,
                normal: Vector3::z(),
                distance,
                uncertainty: 0.01,
                region: if r <= 2.0 { 0 } else { -1 },
            };
            before.push(point(dev + rng.gen_range(-0.0025..0.0025) * 1.7));
            after.push(point(dev - removed + rng.gen_range(-0.0025..0.0025) * 1.7));
            predicted.push(planned);
        }
        let cfg = ReachConfig::default();
        let (before, after) = (inspection(before), inspection(after));
        measure(&GrindPair::new(&before, &after), &predicted, &cfg)
            .expect("far field read")
            .reach_mm
    }

    #[test]
    fn a_planted_wider_footprint_is_read_within_a_bin() {
        for (i, wider) in [0.5, 1.0, 1.5, 2.0, 2.75].into_iter().enumerate() {
            let read = planted(wider, 7 + i as u64);
            assert!(
                (read - wider).abs() <= 0.25 + 1e-9,
                "planted {wider} mm beyond the footprint, read {read} mm"
            );
        }
    }

    #[test]
    fn removal_only_where_planned_reads_no_reach() {
        for seed in 0..5 {
            let read = planted(0.0, 100 + seed);
            assert!(
                read <= 0.25 + 1e-9,
                "nothing planted beyond, read {read} mm"
            );
        }
    }

    #[test]
    fn no_far_field_no_reading() {
        let near: Vec<(f64, f64)> = (0..100).map(|i| (i as f64 * 0.03, 0.01)).collect();
        assert_eq!(reach_of(&near, &ReachConfig::default()), None);
    }

    #[test]
    fn a_quiet_far_field_does_not_make_every_bin_significant() {
        // later inspections keep unchanged points' values: a far field with no scatter
        let mut pts: Vec<(f64, f64)> = (0..200).map(|i| (3.5 + i as f64 * 0.007, 0.0)).collect();
        pts.extend((0..20).map(|i| (2.0 + i as f64 * 0.01, 0.0008)));
        pts.extend((0..20).map(|i| (1.0 + i as f64 * 0.01, 0.004)));
        let r = reach_of(&pts, &ReachConfig::default()).unwrap();
        assert_eq!(r.reach_mm, 1.25, "{:?}", r.bins);
    }
}

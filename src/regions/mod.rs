//! Defect regions: significant core points beyond the tolerance (error points), clustered.
//!
//! Error points of the same sign closer than `gap_factor` × the core-point spacing are
//! connected; each connected set of at least `min_points` (or with a member whose fitted peak
//! is beyond the tolerance by more than its LoD) is a region. Area is the sum of the
//! points' area shares (π d8² / 8, d8 the distance to the 8th nearest core point); volume
//! above tolerance is Σ share × (|distance| - tolerance). Material in excess (distance > 0)
//! can be ground away: repairable; pits cannot.
//!
//! Coverage: the share of the area to inspect (by the core points' area shares) that was
//! resolved ([`resolution`]: measured, with a cylinder narrow enough and a LoD within the
//! tolerance to see the smallest repairable defect); below `min_coverage` the verdict is
//! [`Verdict::Incomplete`]. Per
//! region, the measured share of its neighbourhood (the core points within the connection
//! distance of a member) and whether an unmeasured core point lies in it (then its peak and
//! area are lower bounds).
//!
//! Front: [`find_regions_in`] ([`find_regions`]: the whole reference is to be inspected).
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::compare::{area_shares, Deviation, Deviations, Reason, PEAK_LOD_RATIO};
use crate::spatial::Neighbours;

pub mod decision;
mod resolution;
pub use decision::{conformity, Conformity, Counts, Decision, MAX_UNDECIDED_SHARE};
pub use resolution::{Shortfall, MAX_RESOLVING_RADIUS_MM, MAX_SHARE_MM2, SMALLEST_DEFECT_MM};

/// Settings of [`find_regions`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegionConfig {
    /// Tolerance on |distance|, mm (default 0.05).
    pub tolerance: f64,
    /// Error points closer than this many core-point spacings are connected (default 2.5).
    pub gap_factor: f64,
    /// Fewest error points in a region; smaller clusters are dropped as noise (default 3),
    /// unless a member carries a peak model's fitted peak beyond the tolerance by more than
    /// its LoD (a defect too narrow for this many core points to read it beyond the
    /// tolerance).
    pub min_points: usize,
    /// Least share of the area to inspect that must be measured for a verdict; below it the
    /// verdict is `incomplete` (default 0.95).
    pub min_coverage: f64,
}

impl Default for RegionConfig {
    fn default() -> Self {
        RegionConfig {
            tolerance: 0.05,
            gap_factor: 2.5,
            min_points: 3,
            min_coverage: 0.95,
        }
    }
}

/// One defect region (regions.json).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Region {
    /// Index in the list (the `region` column of deviations.csv).
    pub id: usize,
    /// Mean position of its error points, mm.
    pub centroid: [f64; 3],
    /// Mean outward normal (unit).
    pub normal: [f64; 3],
    /// Surface area, mm².
    pub area: f64,
    /// Signed distance of largest magnitude, mm.
    pub peak: f64,
    /// The peak was read by a single point pair ([`crate::compare::Reason::PointPair`])
    /// under a defect too narrow for any model, with no scan point near its top: the true
    /// peak is at least this large in magnitude (a plan grinds only down to it; inspect
    /// again after grinding). Absent in files from before 2026-12-01: false.
    #[serde(default)]
    pub peak_lower_bound: bool,
    /// Mean signed distance, mm.
    pub mean: f64,
    /// Volume beyond the tolerance, mm³.
    pub volume: f64,
    /// Number of error points.
    pub points: usize,
    /// Material in excess (grinding can fix it); false for pits.
    pub repairable: bool,
    /// Share of the region's neighbourhood (the core points within the connection distance
    /// `gap` of a member, by area) that was measured. Absent in files from before
    /// 2026-12-02: 1.
    #[serde(default = "full")]
    pub measured_share: f64,
    /// An unmeasured core point (a hole or scan border) lies in the neighbourhood: the
    /// defect may extend into it, so `peak`, `area` and `volume` are lower bounds. Absent in
    /// files from before 2026-12-02: false.
    #[serde(default)]
    pub touches_unmeasured: bool,
}

/// The default of shares that older files do not have: all of it.
fn full() -> f64 {
    1.0
}

/// What the regions mean for the part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// No region, and the decision rule ([`decision`], ISO 14253-1) proves it: no
    /// non-conform core point and at most [`MAX_UNDECIDED_SHARE`] of the measured area
    /// undecided.
    WithinTolerance,
    /// Every region is material in excess.
    Repairable,
    /// At least one pit.
    Reject,
    /// Less of the area to inspect was measured than `min_coverage`: no verdict (the
    /// regions found in the measured part are still listed).
    Incomplete,
    /// No region is evidence of a defect (none has a non-conform member), but the decision
    /// rule does not prove the part within tolerance either: non-conform core points too few
    /// for a region, or more than [`MAX_UNDECIDED_SHARE`] of the area undecided. Rescan at a
    /// higher resolution ([`Decision::undecided_reason`]).
    Undecided,
}

/// The regions of a comparison.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Regions {
    /// Tolerance used, mm.
    pub tolerance: f64,
    /// Core-point spacing (square root of the median area per core point), mm.
    pub spacing: f64,
    /// Connection distance, mm.
    pub gap: f64,
    /// Overall verdict.
    pub verdict: Verdict,
    /// Share of the area to inspect (by area) that was resolved: measured densely and
    /// precisely enough to see the smallest repairable defect ([`resolution`]). Absent in
    /// files from before 2026-12-02: 1.
    #[serde(default = "full")]
    pub coverage: f64,
    /// Where the rest of the area to inspect went, by reason. Absent in older files: none.
    #[serde(default)]
    pub shortfall: Shortfall,
    /// Least coverage for a verdict (`min_coverage`). Absent in older files: 0.
    #[serde(default)]
    pub min_coverage: f64,
    /// The decision rule with uncertainty over the measured core points ([`decision`]).
    /// Absent in files from before 2026-12-05: every count 0.
    #[serde(default)]
    pub decision: Decision,
    /// The regions, largest volume first.
    pub regions: Vec<Region>,
    /// Region id per core point (-1 = none).
    #[serde(skip)]
    pub labels: Vec<i64>,
}

/// Whether core point `i` carries a fitted peak (a peak model's, whose own guard vouches for
/// it) beyond the tolerance by more than the point's LoD: evidence of a defect on its own,
/// when the defect is too narrow for `min_points` core points to read it beyond the
/// tolerance.
fn vouched(dev: &Deviations, i: usize, cfg: &RegionConfig) -> bool {
    let v = &dev.values[i];
    v.peak_fitted && v.peak.abs() - v.uncertainty > cfg.tolerance
}

fn find(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// Area share of each core point (pi r9^2 / 8, r9 the distance to the 8th neighbour) and the
/// core-point spacing: the square root of the median area share. (The median nearest-neighbour
/// distance of randomly placed core points is about half of that, and connecting within a few
/// of those sits at the percolation threshold: one defect fell apart into several regions.)
fn shares(points: &[Point3<f64>]) -> (Vec<f64>, f64) {
    let share = area_shares(points);
    let mut sorted: Vec<f64> = share.iter().copied().filter(|a| *a > 0.0).collect();
    sorted.sort_by(f64::total_cmp);
    let spacing = sorted.get(sorted.len() / 2).map_or(0.0, |a| a.sqrt());
    (share, spacing)
}

/// [`find_regions_in`] with the whole reference as the area to inspect.
pub fn find_regions(dev: &Deviations, cfg: &RegionConfig) -> Regions {
    find_regions_in(dev, cfg, None)
}

/// Clusters the error points of `dev` into regions, measures the coverage of the area to
/// inspect (`in_area`: per core point of `dev`, whether it lies in that area; None: all) and
/// gives the verdict.
pub fn find_regions_in(dev: &Deviations, cfg: &RegionConfig, in_area: Option<&[bool]>) -> Regions {
    let (share, spacing) = shares(&dev.points);
    let gap = cfg.gap_factor * spacing;
    let errors: Vec<usize> = (0..dev.values.len())
        .filter(|&i| {
            let v = &dev.values[i];
            v.significant && v.distance.abs() > cfg.tolerance
        })
        .collect();
    let pts: Vec<Point3<f64>> = errors.iter().map(|&i| dev.points[i]).collect();
    let index = Neighbours::new(&pts);
    let mut parent: Vec<usize> = (0..errors.len()).collect();
    for (a, p) in pts.iter().enumerate() {
        let sign = dev.values[errors[a]].distance > 0.0;
        for nb in index.within_unsorted(p, gap) {
            if (dev.values[errors[nb.index]].distance > 0.0) == sign {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, nb.index));
                parent[ra.max(rb)] = ra.min(rb);
            }
        }
    }
    let mut groups: std::collections::BTreeMap<usize, Vec<usize>> = Default::default();
    for (a, &core) in errors.iter().enumerate() {
        let root = find(&mut parent, a);
        groups.entry(root).or_default().push(core);
    }
    let mut regions: Vec<(Region, Vec<usize>)> = groups
        .into_values()
        .filter(|g| g.len() >= cfg.min_points || g.iter().any(|&i| vouched(dev, i, cfg)))
        .map(|g| (describe(dev, &g, &share, cfg.tolerance), g))
        .collect();
    regions.sort_by(|a, b| b.0.volume.total_cmp(&a.0.volume));
    let mut labels = vec![-1i64; dev.points.len()];
    for (id, (region, members)) in regions.iter_mut().enumerate() {
        region.id = id;
        members.iter().for_each(|&i| labels[i] = id as i64);
    }
    if !regions.is_empty() {
        neighbourhoods(dev, &share, gap, &mut regions);
    }
    let (coverage, shortfall) = resolution::coverage(dev, &share, in_area, cfg.tolerance);
    let mut decision = decision::decide(dev, &share, in_area, &labels, cfg.tolerance);
    let evidence = |members: &[usize]| {
        members.iter().any(|&i| {
            let v = &dev.values[i];
            vouched(dev, i, cfg)
                || conformity(v.distance, v.uncertainty, cfg.tolerance)
                    == Some(Conformity::NonConform)
        })
    };
    decision.undecided_regions = (regions.iter())
        .filter(|(_, m)| !evidence(m))
        .map(|(r, _)| r.id)
        .collect();
    let decided: Vec<&Region> = (regions.iter())
        .filter(|(r, _)| !decision.undecided_regions.contains(&r.id))
        .map(|(r, _)| r)
        .collect();
    // A NaN minimum gives no verdict either.
    let enough = coverage >= cfg.min_coverage;
    let verdict = if !enough {
        Verdict::Incomplete
    } else if decided.is_empty() && decision.proves_conform() {
        Verdict::WithinTolerance
    } else if decided.is_empty() {
        Verdict::Undecided
    } else if decided.iter().all(|r| r.repairable) {
        Verdict::Repairable
    } else {
        Verdict::Reject
    };
    let regions: Vec<Region> = regions.into_iter().map(|r| r.0).collect();
    Regions {
        tolerance: cfg.tolerance,
        spacing,
        gap,
        verdict,
        coverage,
        shortfall,
        min_coverage: cfg.min_coverage,
        decision,
        regions,
        labels,
    }
}

/// Whether core point `i` got a distance.
fn measured(dev: &Deviations, i: usize) -> bool {
    dev.values[i].distance.is_finite()
}

/// Sets each region's `measured_share` and `touches_unmeasured` from its neighbourhood: the
/// core points within `gap` of a member (`share`: their areas).
fn neighbourhoods(dev: &Deviations, share: &[f64], gap: f64, regions: &mut [(Region, Vec<usize>)]) {
    let index = Neighbours::new(&dev.points);
    let mut near = vec![false; dev.points.len()];
    for (region, members) in regions.iter_mut() {
        let mut hood: Vec<usize> = Vec::new();
        for &m in members.iter() {
            for nb in index.within_unsorted(&dev.points[m], gap) {
                if !near[nb.index] {
                    near[nb.index] = true;
                    hood.push(nb.index);
                }
            }
        }
        let total: f64 = hood.iter().map(|&i| share[i]).sum();
        let seen: f64 = hood
            .iter()
            .filter(|&&i| measured(dev, i))
            .map(|&i| share[i])
            .sum();
        region.measured_share = if total > 0.0 { seen / total } else { 1.0 };
        region.touches_unmeasured = hood.iter().any(|&i| !measured(dev, i));
        hood.iter().for_each(|&i| near[i] = false);
    }
}

/// Region peak: when members have a fitted peak (their own guard vouches for them), the
/// largest fitted one, unless another member's peak exceeds it by more than that member's LoD
/// (a second, taller top in the region whose fit was refused): the largest of many noisy
/// quadric estimates on a plateau is biased high, the fit is not. Other members count only
/// when their LoD is at most [`PEAK_LOD_RATIO`] × the members' median LoD; without a fitted
/// peak, the largest of those. Returns the member whose peak it is.
fn peak<'a>(dev: &'a Deviations, members: &[usize]) -> Option<&'a Deviation> {
    let mut lods: Vec<f64> = members.iter().map(|&i| dev.values[i].uncertainty).collect();
    let mid = lods.len() / 2;
    let cap = PEAK_LOD_RATIO * *lods.select_nth_unstable_by(mid, f64::total_cmp).1;
    let largest = |peaks: &mut dyn Iterator<Item = &'a Deviation>| {
        peaks.max_by(|a, b| a.peak.abs().total_cmp(&b.peak.abs()))
    };
    let eligible = || {
        members
            .iter()
            .map(|&i| &dev.values[i])
            .filter(move |v| v.peak_fitted || v.uncertainty <= cap)
    };
    match largest(&mut eligible().filter(|v| v.peak_fitted)) {
        Some(f) => largest(
            &mut eligible()
                .filter(|v| v.peak_fitted || v.peak.abs() > f.peak.abs() + v.uncertainty),
        ),
        None => largest(&mut eligible()),
    }
}

fn describe(dev: &Deviations, members: &[usize], share: &[f64], tolerance: f64) -> Region {
    let n = members.len() as f64;
    let centroid = members
        .iter()
        .map(|&i| dev.points[i].coords)
        .sum::<Vector3<f64>>()
        / n;
    let normal = members
        .iter()
        .map(|&i| dev.normals[i])
        .sum::<Vector3<f64>>();
    let normal = normal.try_normalize(0.0).unwrap_or_else(Vector3::zeros);
    let d = |i: usize| dev.values[i].distance;
    let top = peak(dev, members);
    let peak = top.map_or(0.0, |v| v.peak);
    Region {
        id: 0,
        centroid: centroid.into(),
        normal: normal.into(),
        area: members.iter().map(|&i| share[i]).sum(),
        peak,
        peak_lower_bound: top.is_some_and(|v| v.reason == Reason::PointPair),
        mean: members.iter().map(|&i| d(i)).sum::<f64>() / n,
        volume: members
            .iter()
            .map(|&i| share[i] * (d(i).abs() - tolerance))
            .sum(),
        points: members.len(),
        repairable: peak > 0.0,
        measured_share: 1.0,
        touches_unmeasured: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::{Deviation, Method, Reason};

    /// A 5 × 5 patch of error points 0.5 mm apart, every distance 0.1 mm with LoD 0.02 mm;
    /// `peaks` sets (index, peak, fitted).
    fn patch(peaks: &[(usize, f64, bool)]) -> Deviations {
        let points: Vec<Point3<f64>> = (0..25)
            .map(|i| Point3::new((i % 5) as f64 * 0.5, (i / 5) as f64 * 0.5, 0.0))
            .collect();
        let mut values = vec![
            Deviation {
                distance: 0.1,
                uncertainty: 0.02,
                significant: true,
                radius: 0.5,
                n_ref: 20,
                n_scan: 20,
                direction: Vector3::z(),
                spread: [0.0, 0.015],
                peak: 0.1,
                peak_fitted: false,
                reason: Reason::Ok,
            };
            25
        ];
        for &(i, peak, fitted) in peaks {
            values[i].peak = peak;
            values[i].peak_fitted = fitted;
        }
        Deviations {
            normals: vec![Vector3::z(); points.len()],
            points,
            values,
            given: 25,
            method: Method::Adaptive,
            noise: 0.015,
            radii: vec![0.5],
        }
    }

    fn region_peak(dev: &Deviations) -> f64 {
        let regions = find_regions(dev, &RegionConfig::default());
        assert_eq!(regions.regions.len(), 1);
        regions.regions[0].peak
    }

    #[test]
    fn region_peak_prefers_the_fitted_peak() {
        // Without a fit: the largest member peak.
        assert_eq!(
            region_peak(&patch(&[(12, 0.14, false), (3, 0.13, false)])),
            0.14
        );
        // A fitted peak below a noisy quadric maximum (within that member's LoD) wins...
        let dev = patch(&[(12, 0.125, true), (3, 0.14, false)]);
        assert_eq!(region_peak(&dev), 0.125);
        // ...and one above it too.
        assert_eq!(
            region_peak(&patch(&[(12, 0.16, true), (3, 0.14, false)])),
            0.16
        );
        // A second top clearly taller than the fitted one (by more than its LoD) counts.
        assert_eq!(
            region_peak(&patch(&[(12, 0.125, true), (3, 0.3, false)])),
            0.3
        );
        // A fitted member counts whatever its core point's LoD.
        let mut dev = patch(&[(12, 0.2, true)]);
        dev.values[12].uncertainty = 0.09;
        assert_eq!(region_peak(&dev), 0.2);
    }

    #[test]
    fn a_peak_read_by_a_point_pair_is_flagged_as_a_lower_bound() {
        let region =
            |dev: &Deviations| find_regions(dev, &RegionConfig::default()).regions[0].clone();
        // The region's peak is a point pair's: a lower bound.
        let mut dev = patch(&[(12, 0.2, false)]);
        dev.values[12].reason = Reason::PointPair;
        let r = region(&dev);
        assert!(r.peak == 0.2 && r.peak_lower_bound, "{r:?}");
        // A point pair below the peak (read by a cylinder) flags nothing.
        dev.values[12].peak = 0.12;
        dev.values[3].peak = 0.14;
        let r = region(&dev);
        assert!(r.peak == 0.14 && !r.peak_lower_bound, "{r:?}");
        // Nor does a fitted peak above it.
        dev.values[12].peak = 0.2;
        dev.values[3] = Deviation {
            peak: 0.3,
            peak_fitted: true,
            ..dev.values[3]
        };
        let r = region(&dev);
        assert!(r.peak == 0.3 && !r.peak_lower_bound, "{r:?}");
        // Files from before the flag read as false.
        let mut json = serde_json::to_value(&r).unwrap();
        json.as_object_mut().unwrap().remove("peak_lower_bound");
        let old: Region = serde_json::from_value(json).unwrap();
        assert!(!old.peak_lower_bound);
    }

    #[test]
    fn a_fitted_peak_beyond_the_tolerance_makes_a_region_of_fewer_points() {
        // Two error points (the rest within the tolerance): no region without a fitted peak.
        let pair = |peak: f64, fitted: bool, lod: f64| {
            let mut dev = patch(&[(12, peak, fitted)]);
            for (i, v) in dev.values.iter_mut().enumerate() {
                if i != 12 && i != 13 {
                    v.distance = 0.03;
                }
            }
            dev.values[12].uncertainty = lod;
            find_regions(&dev, &RegionConfig::default()).regions
        };
        assert!(pair(0.15, false, 0.05).is_empty());
        // A fitted peak beyond the tolerance by more than its point's LoD: a region.
        let regions = pair(0.15, true, 0.05);
        assert_eq!(
            (regions.len(), regions[0].points, regions[0].peak),
            (1, 2, 0.15)
        );
        // Not by more than the LoD: none.
        assert!(pair(0.15, true, 0.11).is_empty());
    }

    /// ISO 14253-1 on the patch (tolerance 0.05 mm): every verdict the rule can give, each
    /// of which the verdict without it (no region: within tolerance; a region: repairable)
    /// would get wrong except the first and the last.
    #[test]
    fn the_verdict_follows_the_decision_rule() {
        let judge = |d: f64, u: f64, tops: &[usize], top: f64| {
            let mut dev = patch(&[]);
            for (i, v) in dev.values.iter_mut().enumerate() {
                v.distance = if tops.contains(&i) { top } else { d };
                (v.peak, v.uncertainty) = (v.distance, u);
                v.significant = v.distance.abs() > u;
            }
            find_regions(&dev, &RegionConfig::default())
        };
        // |d| + U = 0.04 <= 0.05 everywhere: conform, within tolerance.
        let r = judge(0.03, 0.01, &[], 0.0);
        assert_eq!(r.verdict, Verdict::WithinTolerance);
        let c = &r.decision;
        assert_eq!((c.conform, c.nonconform, c.undecided), (25, 0, 0));
        // 0.045 +- 0.01 straddles the tolerance everywhere: undecided, no region.
        let r = judge(0.045, 0.01, &[], 0.0);
        assert_eq!((r.verdict, r.regions.len()), (Verdict::Undecided, 0));
        assert_eq!(
            (r.decision.undecided, r.decision.undecided_share),
            (25, 1.0)
        );
        // Two non-conform points (0.1 - 0.01 > 0.05), too few for a region: undecided.
        let r = judge(0.02, 0.01, &[0, 24], 0.1);
        assert_eq!((r.verdict, r.regions.len()), (Verdict::Undecided, 0));
        assert_eq!(r.decision.nonconform_outside_regions, 2);
        assert!(r.decision.undecided_reason().contains("2 non-conform"));
        // A region beyond the tolerance but within its LoD (0.06 - 0.02 < 0.05): listed, not
        // evidence; the verdict is undecided, not repairable.
        let r = judge(0.06, 0.02, &[], 0.0);
        assert_eq!((r.verdict, r.regions.len()), (Verdict::Undecided, 1));
        assert_eq!(r.decision.undecided_regions, vec![0]);
        // Beyond it by more than the LoD: repairable.
        let r = judge(0.1, 0.02, &[], 0.0);
        assert_eq!(r.verdict, Verdict::Repairable);
        assert!(r.decision.undecided_regions.is_empty());
    }
}

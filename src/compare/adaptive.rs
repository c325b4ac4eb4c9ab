//! Adaptive M3C2: per core point, the cylinder radius follows the RWME similarity of the
//! reference part X and the scan part Y inside it, and the distance is the offset between the
//! two surfaces' crossings of the normal line (a point pair), from local quadric fits.
//!
//! RWME (the seed paper): R(X, Y) = Σ w_i |X_i| / (λ + Σ w_i d(X_i, Y)), w_i = exp(-d(X_i, Y)/h),
//! with X_i a reference point and |X_i| its area share (cylinder disc area / count), and
//! d(X_i, Y) = |δ_i| the one-sided distance from X_i to the scan along X_i's normal (to the
//! scan point nearest to that normal line among X_i's 3 nearest scan points). The similarity
//! s(r) = R / R0 compares with a perfect match at the noise level (every d = d0 = σ sqrt(2/π)).
//! The radius grows through the candidate set while s >= threshold, then further while the
//! quadric fits describe the surface and their confidence intervals intersect (ICI). Error
//! points also evaluate the reference points around them for the region peaks, and at each
//! summit of those peaks a peak model is fitted to the scan points (`peakfit.rs`).
//! docs/ALGORITHMS.md has the details.
use anyhow::{ensure, Result};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::cover::{cover_radius2, filled, Sectors};
use super::densify::densify;
use super::fill::{fill, fit_window, gather_window, Model, ModelScratch};
use super::fit::{fit, student_t95, FitScratch, Local};
use super::{area_share, AdaptiveConfig, Clouds, CompareConfig, Deviation, Reason, PEAK_LOD_RATIO};
use crate::cloud::PointCloud;
use crate::spatial::Neighbours;

/// δ_i looks among this many nearest scan points of a reference point. 3 instead of 4 (until
/// 2026-12-01): every IoU, peak and false-region count of seeds 11-82 at 300k and 11-58 at
/// 1.2M identical, RMS within 0.0001 mm but one (0.0030 → 0.0025 mm), and the adaptive
/// comparison at 20k core points 0.397 → 0.361 s; 8 gave the same accuracy-test results at
/// a third more search time.
const DELTA_NEIGHBOURS: usize = 3;

/// Fewest scan points a fit may keep before the radius grows.
const FIT_MIN: usize = 6;

/// Smallest radius of a peak fit's window, mm: the window must reach the foot of a defect up
/// to 2 mm wide at half height (its 5 % level lies 2.1 mm from its core), or the model's
/// plane and amplitude trade off and its flanks (where the model fill measures the tolerance's
/// crossing) go astray. At 1.2M scan points the cylinder-based radius is 1.43 mm, and seed
/// 11's 0.07 mm, 2.7 mm wide ridge read IoU 0.936 instead of 0.956 (docs/ALGORITHMS.md,
/// adaptive step 10).
const MIN_PEAK_WINDOW: f64 = 2.0;

/// Per-cloud data shared by all core points.
pub(super) struct Prepared<'a> {
    pub(super) clouds: &'a Clouds<'a>,
    pub(super) ref_normals: &'a [Vector3<f64>],
    /// Per storage slot of the reference grid (its order keeps a cylinder's points close in
    /// memory): the point's normal and RWME terms.
    ref_slots: Vec<RefSlot>,
    /// Per storage slot of the scan grid: the normal of the reference point the scan point
    /// is paired with ([`Pairing`]) and the point-pair distance from its tangent plane; None
    /// when no reference point is within the reach of a cylinder around a reference point
    /// (looked up when needed).
    scan_slots: Vec<Option<(Vector3<f64>, f64)>>,
    pairing: Pairing<'a>,
    radii: Vec<f64>,
    /// Their squares.
    radii2: Vec<f64>,
    /// Half-length of every cylinder: max(max_distance, smallest radius), py4dgeo's rule
    /// with the smallest candidate radius (not the largest: that reached outlier clusters
    /// beyond max_distance; docs/ALGORITHMS.md, adaptive step 1).
    pub(super) half_length: f64,
    /// The core points and their index: [`refine`] evaluates the reference points whose
    /// nearest core point is the one refined (its Voronoi cell on the reference).
    pub(super) core: &'a [Point3<f64>],
    core_index: Neighbours,
    /// Radius around a core point that holds its cell: twice the core-point spacing.
    pub(super) refine_radius: f64,
    pub(super) noise: f64,
    pub(super) cos_limit: f64,
    /// δ of every reference point (see [`one_sided_distances`]).
    pub(super) delta: Vec<f64>,
}

impl Prepared<'_> {
    /// The core point nearest to `x` (None without core points).
    pub(super) fn nearest_core(&self, x: &Point3<f64>) -> Option<&Point3<f64>> {
        self.nearest_core_id(x).map(|i| &self.core[i])
    }

    /// Index of the core point nearest to `x` (None without core points).
    pub(super) fn nearest_core_id(&self, x: &Point3<f64>) -> Option<usize> {
        self.core_index.knn(x, 1).first().map(|c| c.index)
    }

    /// The smallest candidate radius.
    pub(super) fn smallest_radius(&self) -> f64 {
        self.radii[0]
    }

    /// Indices of the reference points within `radius` of the axis through `p` along `n` and
    /// within max(`max_distance`, `radius`) of `p` along it, in storage order: a plain
    /// cylinder (py4dgeo's slabs, [`crate::spatial::Grid::cylinder`], leave out a plane through
    /// `p` when the cylinder has two: it lies on their common boundary).
    pub(super) fn reference_near(
        &self,
        p: &Point3<f64>,
        n: &Vector3<f64>,
        radius: f64,
        max_distance: f64,
        out: &mut Vec<usize>,
    ) {
        out.clear();
        self.clouds
            .ref_grid
            .near_axis(p, n, radius, max_distance.max(radius), |slot, _, _| {
                out.push(slot)
            });
    }

    /// Radius of a peak fit's window: the largest candidate radius plus the refine radius
    /// (the cell's reach plus the widest flank a quadric estimate sees), at least
    /// [`MIN_PEAK_WINDOW`].
    pub(super) fn peak_window(&self) -> f64 {
        (self.radii.last().expect("radii") + self.refine_radius).max(MIN_PEAK_WINDOW)
    }
}

/// A reference point's data in grid storage order.
struct RefSlot {
    normal: Vector3<f64>,
    /// RWME terms: w = exp(-|δ|/h) and w·|δ| (NaN when δ is: unscanned surface).
    terms: [f64; 2],
    /// A scan point lies within the cover radius of the point (`cover.rs`).
    covered: bool,
}

/// The candidate radii: the configured ones, or r0·√2^k for k = 0..4 with `r0` the radius
/// that holds about 12 scan points.
pub fn radii(a: &AdaptiveConfig, r0: f64) -> Result<Vec<f64>> {
    let radii = if a.radii.is_empty() {
        (0..4).map(|k| r0 * 2f64.sqrt().powi(k)).collect()
    } else {
        a.radii.clone()
    };
    ensure!(
        !radii.is_empty() && radii.windows(2).all(|w| w[0] < w[1]) && radii[0] > 0.0,
        "adaptive radii must be positive and ascending"
    );
    Ok(radii)
}

/// Per-chunk scratch buffers of [`at`].
#[derive(Default)]
pub(super) struct Scratch {
    /// Per candidate radius: the reference points within it.
    rings: Vec<Ring>,
    /// Scan points in the cylinder: index of the smallest radius holding them, and the pair.
    tagged: Vec<(usize, Local)>,
    /// The same pairs, ordered by that radius: those within radius k are a prefix.
    pairs: Vec<Local>,
    /// Pairs within each radius.
    within: Vec<usize>,
    /// Next free place of each ring in `pairs` (the counting sort's cursors).
    next: Vec<usize>,
    fit: FitScratch,
    knn: Vec<(f64, u32)>,
    /// Reference points around a core point whose peak is refined.
    near: Vec<usize>,
    /// Both clouds' points per sector of the annulus (`cover.rs`).
    sectors: Sectors,
}

/// Reference points within a candidate radius ([`gather`] counts each in the ring between
/// the radius below and its own, then adds the rings up).
#[derive(Default, Clone, Copy)]
struct Ring {
    /// Points whose normal agrees with the core point's.
    count: usize,
    /// Of those, the ones no scan point covers (`cover.rs`).
    uncovered: usize,
    /// Of those, the scanned ones (finite δ) and the sums of their RWME terms.
    scanned: f64,
    sum_w: f64,
    sum_wd: f64,
}

/// Runs the adaptive variant at every core point with the candidate `radii`, adding core
/// points around the summits of defects (`densify.rs`).
pub fn run(
    clouds: &Clouds,
    core: &PointCloud,
    normals: &[Vector3<f64>],
    radii: &[f64],
    cfg: &CompareConfig,
) -> Result<Evaluated> {
    let a = &cfg.adaptive;
    let ref_normals = clouds.reference.normals.as_deref().ok_or_else(|| {
        anyhow::anyhow!("the adaptive method needs reference normals (give a mesh or normals)")
    })?;
    ensure!(
        a.lambda > 0.0 && a.h > 0.0,
        "adaptive lambda and h must be positive"
    );
    ensure!(
        a.refine_above >= 0.0 && a.densify_above >= 0.0,
        "adaptive refine_above and densify_above must be non-negative (inf turns them off)"
    );
    // A scan point inside a cylinder around a reference point is within `reach` of it.
    let r_max = *radii.last().expect("radii");
    let reach = r_max.hypot(cfg.max_distance.max(r_max)) * (1.0 + 1e-9);
    let halo = clouds
        .ref_grid
        .typical_kth(&clouds.scan.points, PAIR_CANDIDATES);
    let cos_limit = a.max_normal_angle.to_radians().cos();
    let pairing = Pairing {
        clouds,
        ref_normals,
        cos_limit,
        edge_cos: EDGE_ANGLE.to_radians().cos(),
        over: clouds.ref_grid.typical_kth(&clouds.scan.points, 1),
    };
    // Per scan point: its reference point's normal and the pair distance.
    let nearest: Vec<Option<(Vector3<f64>, f64)>> = clouds.ref_grid.knn_each(
        &clouds.scan_grid,
        PAIR_CANDIDATES,
        reach,
        halo,
        |j, found| pairing.pair(&clouds.scan.points[j], found),
    );
    let cover2 = cover_radius2(clouds.scan_density);
    let (delta, covered): (Vec<f64>, Vec<bool>) =
        one_sided_distances(clouds, ref_normals, &nearest, cos_limit, reach, cover2)
            .into_iter()
            .unzip();
    let noise = match a.noise {
        Some(s) => s,
        None => robust_sd(&delta),
    };
    let ref_slots = clouds
        .ref_grid
        .slot_ids()
        .par_iter()
        .map(|&i| {
            let d = delta[i as usize].abs();
            let w = (-d / a.h).exp();
            RefSlot {
                normal: ref_normals[i as usize],
                terms: [w, w * d],
                covered: covered[i as usize],
            }
        })
        .collect();
    let scan_slots = match clouds.scan_grid.numbered_in_storage_order() {
        true => nearest,
        false => (clouds.scan_grid.slot_ids().par_iter())
            .map(|&j| nearest[j as usize])
            .collect(),
    };
    let core_index = Neighbours::new(&core.points);
    let prep = Prepared {
        clouds,
        ref_normals,
        ref_slots,
        scan_slots,
        pairing,
        radii: radii.to_vec(),
        radii2: radii.iter().map(|r| r * r).collect(),
        half_length: cfg.max_distance.max(radii[0]),
        refine_radius: 2.0 * spacing(&core_index, &core.points),
        core: &core.points,
        core_index,
        noise,
        cos_limit,
        delta,
    };
    let refined = super::run(&clouds.ref_grid, core, normals, |s: &mut Scratch, p, n| {
        let dev = at(&prep, p, n, cfg, s);
        refine(&prep, dev, p, n, cfg, s)
    });
    let (mut values, mut tops): (Vec<Deviation>, Vec<Point3<f64>>) = refined.into_iter().unzip();
    // The added core points follow the given ones; each is its own top.
    let (extra, extra_values) = densify(&prep, normals, &values, cfg);
    values.extend(extra_values);
    tops.extend(&extra.points);
    let points = [&core.points[..], &extra.points].concat();
    let normals = [normals, &extra.normals].concat();
    let mut models = extra.models;
    if a.peak_fit {
        models.extend(fit_peaks(&prep, &points, &tops, &normals, &mut values, cfg));
    }
    if a.model_fill {
        fill(&prep, &points, &normals, &mut values, models, cfg);
    }
    Ok(Evaluated {
        values,
        noise,
        points,
        normals,
    })
}

/// What [`run`] returns: every core point (the given ones, then those densification added)
/// with its outward unit normal and result, and the noise used.
pub struct Evaluated {
    /// One result per core point.
    pub values: Vec<Deviation>,
    /// Scan noise used, mm.
    pub noise: f64,
    /// The core points.
    pub points: Vec<Point3<f64>>,
    /// Their outward unit normals.
    pub normals: Vec<Vector3<f64>>,
}

/// Sets `dev.peak` of a significant core point beyond `refine_above` to the distance of
/// largest magnitude, of the same sign, at it and at the reference points of its cell (nearest
/// to it among the core points; normal within `max_normal_angle`) whose fit describes the
/// surface (residual SD at most `max_misfit` × noise): a defect narrower than the core spacing
/// has its top between core points. Also returns where that peak was found (`p` unless a
/// reference point of the cell gave it).
fn refine(
    prep: &Prepared,
    mut dev: Deviation,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
    scratch: &mut Scratch,
) -> (Deviation, Point3<f64>) {
    let mut top = *p;
    if !refined(&dev, cfg) {
        return (dev, top);
    }
    // The candidate list is taken out of the scratch while `at` uses the rest of it.
    let mut near = std::mem::take(&mut scratch.near);
    near.clear();
    let c = prep.clouds;
    prep.reference_near(p, n, prep.refine_radius, cfg.max_distance, &mut near);
    for &m in &near {
        let (x, nx) = (&c.reference.points[m], &prep.ref_normals[m]);
        let own_cell = prep.nearest_core(x) == Some(p);
        if nx.dot(n) < prep.cos_limit || !own_cell {
            continue;
        }
        let d = at(prep, x, nx, cfg, scratch);
        if d.significant
            && d.spread[1] <= cfg.adaptive.max_misfit * prep.noise
            && d.uncertainty <= PEAK_LOD_RATIO * dev.uncertainty
            && d.distance * dev.peak > 0.0
            && d.distance.abs() > dev.peak.abs()
        {
            dev.peak = d.distance;
            top = *x;
        }
    }
    scratch.near = near;
    (dev, top)
}

/// Whether [`refine`] looks for a peak around this result: significant and beyond
/// `refine_above`.
fn refined(dev: &Deviation, cfg: &CompareConfig) -> bool {
    dev.significant && dev.distance.abs() > cfg.adaptive.refine_above
}

/// The peak fit (`peak_fit`): at every summit — a refined core point whose |peak| is the
/// largest among the refined core points of the same sign within the refine radius (one per
/// bump, a few along a ridge) — the peak model is fitted to the scan points within the
/// window radius (largest candidate radius + refine radius: the cell's reach plus the widest
/// flank a quadric estimate sees) of the refined top, in the tangent frame of the core point's
/// normal, heights = the point-pair distances. An accepted fit replaces that core point's peak;
/// the accepted models are returned.
fn fit_peaks(
    prep: &Prepared,
    points: &[Point3<f64>],
    tops: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &mut [Deviation],
    cfg: &CompareConfig,
) -> Vec<Model> {
    // Points a peak model measured (densification) have their peak from it already.
    let refined_ids: Vec<usize> = (0..values.len())
        .filter(|&i| refined(&values[i], cfg) && values[i].reason != Reason::PeakModel)
        .collect();
    if refined_ids.is_empty() {
        return Vec::new();
    }
    let peaks: Vec<f64> = values.iter().map(|v| v.peak).collect();
    let summits = summits(prep, points, &refined_ids, &peaks);
    let fitted: Vec<(usize, Model)> = summits
        .par_iter()
        .map_init(ModelScratch::default, |scratch, &i| {
            gather_window(prep, &tops[i], &normals[i], prep.peak_window(), scratch);
            let (fit, w) = fit_window(prep, values[i].peak, cfg, scratch)?;
            fit.accepted(&w)
                .then(|| (i, Model::new(tops[i], normals[i], fit)))
        })
        .flatten()
        .collect();
    fitted
        .into_iter()
        .map(|(i, model)| {
            values[i].peak = model.fit.peak;
            values[i].peak_fitted = true;
            model
        })
        .collect()
}

/// Those of the core points `ids` whose |value| (`values` per core point) is the largest
/// among the core points of `ids` of the same sign within the refine radius (ties: the lower
/// index): one per bump, a few along a ridge.
pub(super) fn summits(
    prep: &Prepared,
    points: &[Point3<f64>],
    ids: &[usize],
    values: &[f64],
) -> Vec<usize> {
    let pts: Vec<Point3<f64>> = ids.iter().map(|&i| points[i]).collect();
    let index = Neighbours::new(&pts);
    let magnitude = |k: usize| values[ids[k]].abs();
    let sign = |k: usize| values[ids[k]] > 0.0;
    (0..pts.len())
        .into_par_iter()
        .filter(|&k| {
            index
                .within_unsorted(&pts[k], prep.refine_radius)
                .iter()
                .filter(|nb| nb.index != k && sign(nb.index) == sign(k))
                .all(|nb| (magnitude(k), nb.index) > (magnitude(nb.index), k))
        })
        .map(|k| ids[k])
        .collect()
}

/// Core-point spacing: the square root of the median [`area_share`] over up to 1,000 evenly
/// spread core points (regions take it over all of them).
fn spacing(index: &Neighbours, points: &[Point3<f64>]) -> f64 {
    if points.len() < 9 {
        return 0.0;
    }
    let mut shares: Vec<f64> = points
        .iter()
        .step_by((points.len() / 1000).max(1))
        .filter_map(|p| area_share(index, p))
        .collect();
    let mid = shares.len() / 2;
    shares.select_nth_unstable_by(mid, f64::total_cmp).1.sqrt()
}

/// Reference points a scan point's pairing looks among ([`Pairing::pair`]).
const PAIR_CANDIDATES: usize = 4;

/// Candidates of a scan point's pairing whose normals differ by more than this (degrees) lie
/// on two faces of an edge ([`Pairing::pair`]). Facets of a smooth surface differ by a few
/// degrees over a reference spacing; 10, 15 and 20 gave the same accuracy-test numbers.
const EDGE_ANGLE: f64 = 15.0;

/// Which reference point a scan point is paired with: its point-pair distance is measured from
/// that point's tangent plane, and its normal decides which cylinders take the scan point.
pub(super) struct Pairing<'a> {
    clouds: &'a Clouds<'a>,
    ref_normals: &'a [Vector3<f64>],
    /// Cosine of the normal filter's angle (`max_normal_angle`).
    cos_limit: f64,
    /// Cosine of [`EDGE_ANGLE`].
    edge_cos: f64,
    /// Reach of a reference point's patch across its normal: the 90th percentile of the scan
    /// points' nearest-reference distance.
    over: f64,
}

impl Pairing<'_> {
    /// The normal and pair distance of scan point `y` given its nearest reference points
    /// `found` (squared distance, index; nearest first; None when empty): the nearest one's,
    /// unless a candidate's normal differs from it by more than [`EDGE_ANGLE`] (an edge within
    /// reach). At an edge a scan point of one face within a reference spacing of the edge is
    /// often nearer to a reference point of the other face, and lies off its tangent plane by
    /// up to the spacing times the sine of the edge's angle. Then:
    /// - beyond the normal filter's angle (a sharp edge, whose faces' points no cylinder
    ///   shares): the candidate whose patch is closest to `y`, a patch being the candidate's
    ///   tangent plane within `over` of it: distance² = t² + max(0, a − over)² for a height t
    ///   above the plane and an offset a across the normal (seed 24 at 300k: four of the nine
    ///   scan points of a narrow face were paired with the other face, 0.05-0.1 mm above its
    ///   plane, and three core points read 0.055 mm where the truth is 0);
    /// - a shallower edge: of the nearest candidate and the nearest one of the other face, the
    ///   upper plane at a convex edge and the lower one at a concave edge, as the surface of
    ///   a solid bounded by the two faces (seed 37 at 300k: a narrow face between faces 23-35°
    ///   off read +0.013 to +0.063 mm towards a corner, and 4 core points made a region where
    ///   the truth is 0). Not the closest patch there: a defect's height above one face is
    ///   smaller above the other's plane, and the closest patch reads it low (seed 15's
    ///   0.32 mm ridge across a 26° edge: RMS 0.0081 → 0.0287 mm).
    fn pair(&self, y: &Point3<f64>, found: &[(f64, u32)]) -> Option<(Vector3<f64>, f64)> {
        let (_, first) = *found.first()?;
        let normal = &self.ref_normals[first as usize];
        let at = |i: u32| {
            let n = self.ref_normals[i as usize];
            (n, n.dot(&(y - self.clouds.reference.points[i as usize])))
        };
        let cos_to_first = |i: u32| self.ref_normals[i as usize].dot(normal);
        let Some(other) = found
            .iter()
            .map(|&(_, i)| i)
            .find(|&i| cos_to_first(i) < self.edge_cos)
        else {
            return Some(at(first));
        };
        if found.iter().any(|&(_, i)| cos_to_first(i) < self.cos_limit) {
            let patch_distance2 = |d2: f64, t: f64| {
                let across = (d2 - t * t).max(0.0).sqrt();
                t * t + (across - self.over).max(0.0).powi(2)
            };
            return found
                .iter()
                .map(|&(d2, i)| {
                    let pair = at(i);
                    (patch_distance2(d2, pair.1), pair)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map(|(_, pair)| pair);
        }
        // Convex when each point lies below the other's tangent plane.
        let points = &self.clouds.reference.points;
        let convex = (normal - self.ref_normals[other as usize])
            .dot(&(points[other as usize] - points[first as usize]))
            < 0.0;
        let (near, far) = (at(first), at(other));
        Some(match convex == (near.1 >= far.1) {
            true => near,
            false => far,
        })
    }
}

/// δ_i for every reference point: along its normal, to the scan point (of its 3 nearest
/// within `reach`, paired with a reference point whose normal is within the normal filter's
/// angle of its own: `nearest` per scan point, [`Pairing`]) closest to its normal line; NaN
/// when there is none (unscanned surface: left out of the similarity and of the noise
/// estimate). With it, whether any of those scan points (of any face) lies within `cover2`
/// (squared) of the point's normal line (`cover.rs`). Beside a sharp edge the nearest scan points of a reference point are often the
/// other face's, 0.05-0.2 mm off its tangent plane, which would make a perfect match look
/// like a defect.
fn one_sided_distances(
    clouds: &Clouds,
    ref_normals: &[Vector3<f64>],
    nearest: &[Option<(Vector3<f64>, f64)>],
    cos_limit: f64,
    reach: f64,
    cover2: f64,
) -> Vec<(f64, bool)> {
    let scan = &clouds.scan.points;
    let halo = clouds
        .scan_grid
        .typical_kth(&clouds.reference.points, DELTA_NEIGHBOURS);
    clouds.scan_grid.knn_each(
        &clouds.ref_grid,
        DELTA_NEIGHBOURS,
        reach,
        halo,
        |i, found| {
            let (x, n) = (&clouds.reference.points[i], &ref_normals[i]);
            let mut best = (f64::INFINITY, f64::NAN);
            for &(_, j) in found {
                let same_face =
                    nearest[j as usize].is_some_and(|(normal, _)| normal.dot(n) >= cos_limit);
                if !same_face {
                    continue;
                }
                let d = scan[j as usize] - x;
                let t = d.dot(n);
                let across = d.norm_squared() - t * t;
                if across < best.0 {
                    best = (across, t);
                }
            }
            // Covered across the normal only: under a defect taller than the cover radius the
            // scan lies that far off along the normal (dense scans: the 1.2M suite's RMS went
            // NaN with the 3-D distance).
            let covered = found.iter().any(|&(_, j)| {
                let d = scan[j as usize] - x;
                let t = d.dot(n);
                d.norm_squared() - t * t <= cover2
            });
            (best.1, covered)
        },
    )
}

/// 1.4826 × median |δ| over up to 20,000 evenly spread values (the noise along the normal
/// when most of the part is in tolerance).
fn robust_sd(delta: &[f64]) -> f64 {
    let step = (delta.len() / 20_000).max(1);
    let mut abs: Vec<f64> = delta
        .iter()
        .step_by(step)
        .filter(|d| d.is_finite())
        .map(|d| d.abs())
        .collect();
    if abs.is_empty() {
        return 0.0;
    }
    let mid = abs.len() / 2;
    let (_, m, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *m
}

/// Two unit vectors completing `n` to a right-handed frame.
pub(super) fn tangent_frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    (e1, n.cross(&e1))
}

/// Similarity s(r) of the reference points counted in `ring` (those within r): the RWME of
/// the module doc, R = Σ w_i |X_i| / (λ + Σ w_i |δ_i|) with |X_i| = π r² / m, over its value
/// at a perfect match (every |δ_i| = d0).
fn similarity(prep: &Prepared, ring: &Ring, r: f64, h: f64, lambda: f64) -> f64 {
    let m = ring.scanned;
    if m == 0.0 {
        return 0.0;
    }
    let share = std::f64::consts::PI * r * r / m;
    let rwme = ring.sum_w * share / (lambda + ring.sum_wd);
    let d0 = prep.noise * (2.0 / std::f64::consts::PI).sqrt();
    let w0 = (-d0 / h).exp();
    let ideal = m * w0 * share / (lambda + m * w0 * d0);
    rwme / ideal
}

/// Index of the smallest of the squared radii `radii2` (ascending) that holds `rho2`.
#[inline]
fn ring_of(radii2: &[f64], rho2: f64) -> usize {
    // Without branches (the radii ascend, so those below rho are a prefix): the per-core-point
    // loop took 490 ms instead of 570 ms at 100k core points with a loop that stops at the
    // first radius holding rho (mispredicted branches).
    radii2.iter().map(|&r2| usize::from(rho2 > r2)).sum()
}

/// Gathers the cylinder of the largest radius at `p` (normal `n`) into `s`: per radius, the
/// reference points within it (`s.rings`, made cumulative) and the scan point pairs within it
/// (a prefix of `s.pairs` of length `s.within[k]`), in the tangent frame (`e1`, `e2`, `n`).
/// Points whose (nearest reference point's) normal is beyond `max_normal_angle` of `n` are
/// another surface and are left out.
fn gather(prep: &Prepared, p: &Point3<f64>, n: &Vector3<f64>, s: &mut Scratch) {
    let c = prep.clouds;
    let radii2 = &prep.radii2;
    let r_max = *prep.radii.last().expect("radii");
    s.rings.clear();
    s.rings.resize(radii2.len(), Ring::default());
    let rings = &mut s.rings;
    let (e1, e2) = tangent_frame(n);
    // The sectors' annulus starts at half the smallest radius.
    let inner2 = 0.25 * radii2[0];
    let sectors = &mut s.sectors;
    *sectors = Sectors::default();
    c.ref_grid
        .near_axis(p, n, r_max, prep.half_length, |slot, _, rho2| {
            let x = &prep.ref_slots[slot];
            if x.normal.dot(n) >= prep.cos_limit {
                if rho2 >= inner2 {
                    let d = Vector3::from(*c.ref_grid.slot_point(slot)) - p.coords;
                    sectors.add(d.dot(&e1), d.dot(&e2), false);
                }
                let ring = &mut rings[ring_of(radii2, rho2)];
                ring.count += 1;
                ring.uncovered += usize::from(!x.covered);
                if !x.terms[0].is_nan() {
                    ring.scanned += 1.0;
                    ring.sum_w += x.terms[0];
                    ring.sum_wd += x.terms[1];
                }
            }
        });
    for k in 1..rings.len() {
        let below = rings[k - 1];
        let ring = &mut rings[k];
        ring.count += below.count;
        ring.uncovered += below.uncovered;
        ring.scanned += below.scanned;
        ring.sum_w += below.sum_w;
        ring.sum_wd += below.sum_wd;
    }
    let tagged = &mut s.tagged;
    tagged.clear();
    scan_pairs(prep, p, n, r_max, &mut s.knn, |rho2, d, pair| {
        let (u, v) = (d.dot(&e1), d.dot(&e2));
        if rho2 >= inner2 {
            sectors.add(u, v, true);
        }
        tagged.push((ring_of(radii2, rho2), [u, v, pair]));
    });
    s.within.clear();
    s.within.resize(radii2.len(), 0);
    for &(k, _) in tagged.iter() {
        s.within[k] += 1;
    }
    for k in 1..s.within.len() {
        s.within[k] += s.within[k - 1];
    }
    // Counting sort by ring (stable): ring k's pairs follow those of the smaller radii.
    s.pairs.clear();
    s.pairs.resize(tagged.len(), [0.0; 3]);
    s.next.clear();
    s.next.push(0);
    s.next.extend_from_slice(&s.within);
    for &(k, local) in tagged.iter() {
        s.pairs[s.next[k]] = local;
        s.next[k] += 1;
    }
}

/// Calls `f(rho², y - p, pair distance)` for every scan point y within `radius` of the axis
/// through `p` along `n` (half-length: the cylinders') whose nearest reference point's normal
/// is within `max_normal_angle` of `n` (`knn`: scratch).
pub(super) fn scan_pairs(
    prep: &Prepared,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    radius: f64,
    knn: &mut Vec<(f64, u32)>,
    mut f: impl FnMut(f64, Vector3<f64>, f64),
) {
    let c = prep.clouds;
    c.scan_grid
        .near_axis(p, n, radius, prep.half_length, |slot, _, rho2| {
            let y = c.scan_grid.slot_point(slot);
            let y = Point3::new(y[0], y[1], y[2]);
            let (normal, pair) = match prep.scan_slots[slot] {
                Some(nearest) => nearest,
                None => {
                    c.ref_grid.knn(&y, PAIR_CANDIDATES, f64::INFINITY, knn);
                    let Some(pair) = prep.pairing.pair(&y, knn) else {
                        return;
                    };
                    pair
                }
            };
            if normal.dot(n) >= prep.cos_limit {
                f(rho2, y - p, pair);
            }
        });
}

/// The adaptive result at core point `p` with outward unit normal `n`.
pub(super) fn at(
    prep: &Prepared,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
    scratch: &mut Scratch,
) -> Deviation {
    let a = &cfg.adaptive;
    gather(prep, p, n, scratch);
    let Scratch {
        rings,
        pairs,
        within,
        fit: fit_scratch,
        sectors,
        ..
    } = scratch;
    let radii = &prep.radii;
    let min = cfg.min_points.max(1);
    // The scan on one side of the core point only (`cover.rs`): no distance.
    let unscanned = match within[0] {
        0 => Reason::FewScan,
        _ => Reason::ScanBorder,
    };
    if sectors.one_sided() {
        return Deviation::missing(unscanned, radii[0], rings[0].count, within[0]);
    }
    // Only radii whose disc the scan fills count (`cover.rs`; a disc with fewer than
    // min_points reference points cannot be judged): a prefix of the radii, as a disc the
    // scan does not fill is mostly within the next one; none at a scan border.
    let usable = (0..radii.len())
        .take_while(|&j| rings[j].count < min || filled(rings[j].count, rings[j].uncovered))
        .count();
    if usable == 0 {
        return Deviation::missing(unscanned, radii[0], rings[0].count, within[0]);
    }
    let radii = &radii[..usable];
    // Grow through the radii while every one so far is similar (stay at the smallest when
    // it is not); then further only as far as needed to hold min_points each.
    let mut k = 0;
    for (j, &r) in radii.iter().enumerate() {
        if similarity(prep, &rings[j], r, a.h, a.lambda) < a.similarity {
            break;
        }
        k = j;
    }
    while k + 1 < radii.len() && (rings[k].count < min || within[k] < min) {
        k += 1;
    }
    let mut fit_at = |k: usize| {
        fit(
            &pairs[..within[k]],
            radii[k],
            4.0 * prep.noise,
            prep.noise,
            fit_scratch,
        )
    };
    // The fit must keep at least FIT_MIN points after trimming, else the next radius.
    let (mut r, mut n_ref, mut fs) = loop {
        let r = radii[k];
        let (n_ref, n_scan) = (rings[k].count, within[k]);
        let last = k + 1 == radii.len();
        if n_ref < min {
            return Deviation::missing(Reason::FewReference, r, n_ref, n_scan);
        }
        if n_scan < min {
            return Deviation::missing(Reason::FewScan, r, n_ref, n_scan);
        }
        match fit_at(k) {
            Some(fs) if fs.n >= FIT_MIN || last => break (r, n_ref, fs),
            _ if last => return Deviation::missing(Reason::FewScan, r, n_ref, n_scan),
            _ => k += 1,
        }
    };
    // Then larger radii while the quadric still describes the surface (residual SD within
    // max_misfit × noise) and every fit's interval t0 ± gamma·se so far intersects
    // (intersection of confidence intervals).
    let gamma = a.gamma;
    if gamma > 0.0 {
        let (mut lo, mut hi) = (fs.t0 - gamma * fs.se, fs.t0 + gamma * fs.se);
        for j in k + 1..radii.len() {
            let Some(next) = fit_at(j).filter(|f| f.sigma <= a.max_misfit * prep.noise) else {
                break;
            };
            lo = lo.max(next.t0 - gamma * next.se);
            hi = hi.min(next.t0 + gamma * next.se);
            if lo > hi {
                break;
            }
            (r, n_ref, fs) = (radii[j], rings[j].count, next);
        }
    }
    // The fit's standard error comes from its own residuals: Student's t at their degrees of
    // freedom (a handful of points on a narrow face estimate their scatter poorly).
    let lod = student_t95(fs.dof) * fs.se + 1.96 * cfg.registration_error;
    Deviation {
        distance: fs.t0,
        uncertainty: lod,
        significant: false,
        radius: r,
        n_ref,
        n_scan: fs.n,
        direction: Vector3::zeros(),
        spread: [0.0, fs.sigma],
        peak: f64::NAN,
        peak_fitted: false,
        reason: Reason::Ok,
    }
    .finish(n)
}

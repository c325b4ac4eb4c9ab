//! Densification (adaptive variant): extra core points where a defect may lie between the
//! given ones. A defect narrower than about twice the core-point spacing holds one or two core
//! points, often off its top, and a region needs `min_points` error points; so at every summit
//! of the significant core points beyond `densify_above` (half the tolerance) whose LoD is at
//! most the tolerance and whose cylinder is mostly covered by the reference surface
//! (`densify.min_coverage`; the largest |distance| of its sign among them within the refine
//! radius),
//! each reference point within the refine radius (normal within `max_normal_angle`, not
//! itself a core point) becomes a core point of its own, evaluated like the others. Defects
//! too narrow for any cylinder's quadric are found from the scan's own heights instead, or
//! from those summits that read within `refine_above`, and measured by a peak model
//! ([`modelled`]). Step 5 of the adaptive variant; its settings:
//! [`crate::compare::DensifyConfig`]; docs/ACCURACY.md (steps 11 and 12) has the numbers.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::context::{tangent_frame, Context};
use super::fit::at;
use super::model::{fit_window, gather_window, model_result, Model, ModelScratch};
use super::peak_model::{height_limit, PeakFit};
use super::quadric::student_t95;
use super::radius::Scratch;
use crate::compare::config::{CompareConfig, DensifyConfig};
use crate::compare::deviation::{Deviation, Reason, Z95};

/// Where [`modelled`] fits a peak model.
struct Top {
    /// The reference point at the window's origin.
    at: usize,
    /// The height the fit starts from, mm.
    start: f64,
    /// Found from the scan's own heights (δ), not from a summit of the cylinders' values.
    from_delta: bool,
}

/// Core points added by [`densify`].
pub(super) struct Densified {
    /// The reference points made core points.
    pub points: Vec<Point3<f64>>,
    /// Their outward unit normals (the reference's).
    pub normals: Vec<Vector3<f64>>,
    /// Their results.
    pub values: Vec<Deviation>,
    /// The peak models that measured narrow defects ([`modelled`]).
    pub models: Vec<Model>,
}

/// The extra core points around the summits among `values` (one per given core point of
/// `prep`, whose outward unit normals are `normals`), evaluated like the others, then those
/// that peak models measure ([`modelled`]), and their results.
pub(super) fn densify(
    prep: &Context,
    normals: &[Vector3<f64>],
    values: &[Deviation],
    cfg: &CompareConfig,
) -> Densified {
    let (above, tolerance) = (prep.limits.densify_above, prep.limits.tolerance);
    let d = &cfg.adaptive.densify;
    // Reference points per mm² (median): a full disc of radius r holds about π r² of them.
    let density = crate::compare::clouds::surface_density(&prep.clouds.ref_grid);
    let is_candidate: Vec<bool> = values
        .iter()
        .map(|v| {
            let disc = std::f64::consts::PI * v.radius * v.radius * density;
            v.significant
                && v.distance.abs() > above
                && v.uncertainty <= tolerance
                && v.n_ref as f64 >= d.min_coverage * disc
        })
        .collect();
    let candidates: Vec<usize> = (0..values.len()).filter(|&i| is_candidate[i]).collect();
    let distances: Vec<f64> = values.iter().map(|v| v.distance).collect();
    let tops = match candidates.is_empty() {
        true => Vec::new(),
        false => prep.summits(prep.core, &candidates, &distances),
    };
    let c = prep.clouds;
    let mut extra: Vec<usize> = tops
        .par_iter()
        .map_init(Vec::new, |near, &i| {
            let (p, n) = (&prep.core[i], &normals[i]);
            prep.reference_near(p, n, prep.refine_radius, cfg.max_distance, near);
            near.iter()
                .copied()
                .filter(|&j| own_surface(prep, j, n))
                .collect::<Vec<usize>>()
        })
        .flatten()
        .collect();
    extra.sort_unstable();
    extra.dedup();
    let mut added: Vec<Deviation> = extra
        .par_iter()
        .map_init(Scratch::default, |scratch, &j| {
            let (x, n) = (&c.reference.points[j], &prep.ref_normals[j]);
            at(prep, x, n, cfg, scratch)
        })
        .collect();
    // A peak model's value replaces a cylinder's where both measured a point (each point
    // comes from one model at most).
    let position: std::collections::HashMap<usize, usize> =
        extra.iter().enumerate().map(|(k, &j)| (j, k)).collect();
    // Summits whose cylinders read between `densify_above` and `refine_above` are not step
    // 10's: a defect narrower than the largest radius reads low there, and a model may still
    // show it beyond the tolerance.
    let mut knn = Vec::new();
    let shallow: Vec<Top> = tops
        .iter()
        .filter(|&&i| values[i].distance.abs() <= prep.limits.refine_above)
        .filter_map(|&i| {
            c.ref_grid.knn(&prep.core[i], 1, f64::INFINITY, &mut knn);
            knn.first().map(|&(_, j)| Top {
                at: j as usize,
                start: values[i].distance,
                from_delta: false,
            })
        })
        .collect();
    let (values, models) = modelled(prep, &is_candidate, shallow, cfg);
    // Where the scan does not fill a cylinder (a scan border: `cover.rs`) the point keeps
    // its missing value: a model's flank there reaches beyond the data.
    let mut scratch = Scratch::default();
    for (j, value) in values {
        match position.get(&j) {
            Some(&k) if unscanned(&added[k]) => {}
            Some(&k) => added[k] = value,
            None => {
                let (x, n) = (&c.reference.points[j], &prep.ref_normals[j]);
                let own = at(prep, x, n, cfg, &mut scratch);
                extra.push(j);
                added.push(if unscanned(&own) { own } else { value });
            }
        }
    }
    Densified {
        points: extra.iter().map(|&j| c.reference.points[j]).collect(),
        normals: extra.iter().map(|&j| prep.ref_normals[j]).collect(),
        values: added,
        models,
    }
}

/// Whether a cylinder result says the scan does not cover its core point (a hole or a scan
/// border).
fn unscanned(v: &Deviation) -> bool {
    matches!(v.reason, Reason::FewScan | Reason::ScanBorder)
}

/// Whether reference point `j` may become a core point around a centre with normal `n`: its
/// normal within `max_normal_angle` of `n`, and not already a core point.
fn own_surface(prep: &Context, j: usize, n: &Vector3<f64>) -> bool {
    let x = &prep.clouds.reference.points[j];
    prep.ref_normals[j].dot(n) >= prep.cos_limit && prep.nearest_core(x).is_some_and(|c| c != x)
}

/// Defects narrower than the smallest cylinder, found from the scan's own evidence and
/// measured by a peak model (none while densification is off: `densify_above` infinite). A top
/// is a reference point whose δ (one scan point's height above it) is beyond the tolerance
/// (below `max_distance`) and the largest
/// |δ| of its sign within the refine radius, whose nearest core point is no summit candidate
/// of [`densify`] (else the summits above cover it), with `densify.min_cluster` such reference
/// points within the smallest radius, and a peak window holding at least `min_coverage` of
/// the scan points a full one holds (at a scan's border or hole a few points let a Gaussian
/// fit anything). The peak model (`peakfit.rs`) is fitted to the scan points of the peak
/// window around it; when the model describes them (the peak fit's guard without its bound
/// on the standard error: at 19 scan points/mm² a 0.44 mm wide bump has about 8 points on it
/// and its height a standard error of 15 %; `densify.min_support` supporting points, at least
/// `densify.min_width` scan spacings wide) and the fitted peak exceeds the tolerance by t95(n - 9)
/// standard errors, every reference point within the refine radius of the top (normal within
/// `max_normal_angle`, not a core point) becomes a core point whose distance is the model's
/// height there, with LoD t95(n - 9) × its standard error plus the registration term
/// ([`Reason::PeakModel`], [`measured`]). A top from δ whose model follows the scan
/// points without pinning its top (too few supporting points, or beyond its height limit;
/// [`PeakFit::fits_data`]) and that has `densify.min_far_points` scan points far beyond the
/// tolerance is measured by its point pairs instead ([`paired`]). Larger tops first; a
/// reference point goes to the first top that reaches it.
fn modelled(
    prep: &Context,
    is_candidate: &[bool],
    shallow: Vec<Top>,
    cfg: &CompareConfig,
) -> (Vec<(usize, Deviation)>, Vec<Model>) {
    let (tolerance, d) = (prep.limits.tolerance, &cfg.adaptive.densify);
    let c = prep.clouds;
    let on = prep.limits.densify_above.is_finite();
    let ids: Vec<usize> = (0..prep.delta.len())
        .filter(|&j| {
            let size = prep.delta[j].abs();
            on && size > tolerance && size < cfg.max_distance
        })
        .collect();
    let mut tops: Vec<Top> = match ids.is_empty() {
        true => Vec::new(),
        false => prep
            .summits(&c.reference.points, &ids, &prep.delta)
            .into_iter()
            .map(|j| Top {
                at: j,
                start: prep.delta[j],
                from_delta: true,
            })
            .collect(),
    };
    tops.extend(shallow);
    let window = prep.peak_window();
    // Scan points a covered window holds, and their spacing (median density).
    let full = std::f64::consts::PI * window * window * c.scan_density;
    let spacing = c.scan_density.sqrt().recip();
    let mut fits: Vec<(usize, TopMeasure)> = tops
        .par_iter()
        .map_init(ModelScratch::default, |scratch, top| {
            let j = top.at;
            let (x, n) = (&c.reference.points[j], &prep.ref_normals[j]);
            if top.from_delta {
                let caught = prep.nearest_core_id(x).is_some_and(|i| is_candidate[i]);
                if caught || cluster(prep, j, tolerance, cfg) < d.min_cluster {
                    return None;
                }
            }
            if (gather_window(prep, x, n, window, scratch) as f64) < d.min_coverage * full {
                return None;
            }
            let sign = top.start.signum();
            if top.from_delta
                && scratch.heights_between(prep.refine_radius, sign, tolerance, f64::MAX)
                    < d.min_near_beyond
            {
                return None;
            }
            let (f, w) = fit_window(prep, top.start, cfg, scratch)?;
            let margin = match top.from_delta {
                true => student_t95(f.dof()) * f.se,
                false => 0.0,
            };
            let wide = f.widths[0] >= d.min_width * spacing;
            if wide && f.describes(&w, d.min_support) && f.peak.abs() - margin > tolerance {
                return Some((j, TopMeasure::Model(Box::new(f))));
            }
            let unpinned = top.from_delta && wide && f.fits_data(&w);
            (unpinned && far_beyond(prep, scratch, top.start, tolerance, d))
                .then_some((j, TopMeasure::Pairs(top.start)))
        })
        .flatten()
        .collect();
    fits.sort_by(|a, b| {
        b.1.peak()
            .abs()
            .total_cmp(&a.1.peak().abs())
            .then(a.0.cmp(&b.0))
    });
    let mut used = vec![false; c.reference.len()];
    let values = fits
        .iter()
        .flat_map(|(j, measure)| match measure {
            TopMeasure::Model(fit) => measured(prep, *j, fit, cfg, &mut used),
            TopMeasure::Pairs(delta) => paired(prep, *j, *delta, tolerance, cfg, &mut used),
        })
        .collect();
    let models = fits
        .into_iter()
        .filter_map(|(j, measure)| match measure {
            TopMeasure::Model(fit) => {
                Some(Model::new(c.reference.points[j], prep.ref_normals[j], *fit))
            }
            TopMeasure::Pairs(_) => None,
        })
        .collect();
    (values, models)
}

/// How [`modelled`] measures a top.
enum TopMeasure {
    /// By its peak model.
    Model(Box<PeakFit>),
    /// By the point pairs under it, [`paired`] (the top's δ): its model follows the scan
    /// points but they do not pin its top, and `densify.min_far_points` of them lie far beyond the
    /// tolerance.
    Pairs(f64),
}

impl TopMeasure {
    /// The top's height: the fitted peak, or the top's δ.
    fn peak(&self) -> f64 {
        match self {
            TopMeasure::Model(fit) => fit.peak,
            TopMeasure::Pairs(delta) => *delta,
        }
    }
}

/// Whether at least `min_far_points` scan points of the window last gathered into
/// `scratch`, within the smallest candidate radius of its origin, lie beyond `tolerance` by
/// `far_noise` noise SDs with the sign of `start`: no noise (3 such points among about 12
/// have a chance of about 1e-7 with Gaussian noise), but a defect narrower than a model can
/// pin.
fn far_beyond(
    prep: &Context,
    scratch: &ModelScratch,
    start: f64,
    tolerance: f64,
    d: &DensifyConfig,
) -> bool {
    let low = tolerance + d.far_noise * prep.noise;
    let high = height_limit(start.abs(), prep.noise);
    let far = scratch.heights_between(prep.smallest_radius(), start.signum(), low, high);
    far >= d.min_far_points
}

/// The reference points within the smallest candidate radius of top `j` (normal within
/// `max_normal_angle`, not a core point, not `used`; marked used) whose δ is beyond
/// `tolerance` with the sign of the top's `delta`, each measured by its own point pair:
/// distance δ, LoD z95 × (noise + registration error), `radius` 0, one reference and one
/// scan point ([`Reason::PointPair`]). For a defect narrower than about two scan
/// spacings whose top no scan point comes near, no model is pinned by the data (seed 72 at
/// 300k: a 0.366 mm deep, 0.43 mm wide pit fitted 0.73 ± 0.27 mm), and the largest pair
/// distance is a lower bound of its height: a region, not a miss.
fn paired(
    prep: &Context,
    j: usize,
    delta: f64,
    tolerance: f64,
    cfg: &CompareConfig,
    used: &mut [bool],
) -> Vec<(usize, Deviation)> {
    let sign = delta.signum();
    let beyond = |k: usize| prep.delta[k] * sign > tolerance;
    let mut values = Vec::new();
    for k in claim_near(prep, j, prep.smallest_radius(), cfg, used, beyond) {
        let value = Deviation {
            distance: prep.delta[k],
            uncertainty: Z95 * (prep.noise + cfg.registration_error),
            significant: false,
            radius: 0.0,
            n_ref: 1,
            n_scan: 1,
            direction: Vector3::zeros(),
            spread: [0.0, prep.noise],
            peak: f64::NAN,
            peak_fitted: false,
            reason: Reason::PointPair,
        };
        values.push((k, value.finish(&prep.ref_normals[k])));
    }
    values
}

/// The reference points within `radius` of top `j` (cylinder along its normal, half-length
/// `max_distance`) on its own surface ([`own_surface`]), not yet `used` and passing `keep`;
/// marked used: a reference point goes to the first top that reaches it.
fn claim_near(
    prep: &Context,
    j: usize,
    radius: f64,
    cfg: &CompareConfig,
    used: &mut [bool],
    keep: impl Fn(usize) -> bool,
) -> Vec<usize> {
    let (x, n) = (&prep.clouds.reference.points[j], &prep.ref_normals[j]);
    let mut near = Vec::new();
    prep.reference_near(x, n, radius, cfg.max_distance, &mut near);
    near.retain(|&k| !used[k] && own_surface(prep, k, n) && keep(k));
    for &k in &near {
        used[k] = true;
    }
    near
}

/// The reference points within the refine radius of top `j` (normal within
/// `max_normal_angle`, not a core point, not `used`; marked used) with the peak model `fit`'s
/// height at each; the one nearest the fitted centre carries the fitted peak.
fn measured(
    prep: &Context,
    j: usize,
    fit: &PeakFit,
    cfg: &CompareConfig,
    used: &mut [bool],
) -> Vec<(usize, Deviation)> {
    let c = prep.clouds;
    let (x, n) = (&c.reference.points[j], &prep.ref_normals[j]);
    let (e1, e2) = tangent_frame(n);
    let mut values: Vec<(usize, Deviation)> = Vec::new();
    let mut nearest_centre = (f64::INFINITY, 0);
    for k in claim_near(prep, j, prep.refine_radius, cfg, used, |_| true) {
        let d = c.reference.points[k] - x;
        let (u, v) = (d.dot(&e1), d.dot(&e2));
        let (height, se) = fit.height_at(u, v);
        let off = (u - fit.centre[0]).hypot(v - fit.centre[1]);
        if off < nearest_centre.0 {
            nearest_centre = (off, values.len());
        }
        values.push((k, model_result(fit, height, se, &prep.ref_normals[k], cfg)));
    }
    if let Some((_, top)) = values.get_mut(nearest_centre.1) {
        top.peak = fit.peak;
        top.peak_fitted = true;
    }
    values
}

/// Reference points within the smallest candidate radius of reference point `j` (normal
/// within `max_normal_angle` of its own) whose δ is beyond `tolerance` with the sign of j's.
fn cluster(prep: &Context, j: usize, tolerance: f64, cfg: &CompareConfig) -> usize {
    let c = prep.clouds;
    let (x, n) = (&c.reference.points[j], &prep.ref_normals[j]);
    let sign = prep.delta[j].signum();
    let mut count = 0;
    c.ref_grid.near_axis(
        x,
        n,
        prep.smallest_radius(),
        cfg.max_distance,
        |slot, _, _| {
            if prep.delta[slot] * sign > tolerance
                && prep.ref_normals[slot].dot(n) >= prep.cos_limit
            {
                count += 1;
            }
        },
    );
    count
}

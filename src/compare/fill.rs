//! Model fill (adaptive step 13): inside a defect that an accepted peak model describes, the
//! model's height replaces the cylinder estimate at the core points. A cylinder's quadric
//! flattens a narrow defect and at the largest radius trims it as outliers, so the core points
//! on a defect's flanks (where its boundary at the tolerance lies) read 0.01-0.07 mm off; the
//! model is fitted to all the scan points of the defect and pins the flank to a few
//! micrometres where it describes them. A model counts only when its window's scan points
//! follow its profile level by level, and a core point takes it only where the scan points
//! around it agree with it (lack-of-fit tests), so a defect of another shape keeps its
//! cylinder values. docs/ALGORITHMS.md (adaptive step 13) has the numbers.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::adaptive::{scan_pairs, tangent_frame, Prepared};
use super::fit::{student_t95, Local};
use super::peakfit::{fit_peak, PeakFit, PeakScratch, PeakWindow, MIN_SUPPORT};
use super::{CompareConfig, Deviation, Reason};
use crate::spatial::Neighbours;

/// A core point is inside a model's defect where the defect term is at least this share of
/// its amplitude (5 %: about 2.4 standard deviations of a Gaussian from its core).
const MIN_SHARE: f64 = 0.05;

/// The mean residual of the scan points around a core point against the model must be within
/// this many of its standard errors: beyond, the model does not describe the surface there.
const LACK_OF_FIT: f64 = 3.0;

/// Levels of the defect term (share of its amplitude) that split a window's scan points for
/// [`follows_profile`].
const LEVELS: [f64; 7] = [0.05, 0.15, 0.3, 0.5, 0.7, 0.85, 1.01];

/// 99 % quantiles of the chi-square distribution with 0-6 degrees of freedom (one per level
/// of [`LEVELS`] that holds points).
const CHI2_99: [f64; 7] = [0.0, 6.63, 9.21, 11.34, 13.28, 15.09, 16.81];

/// Residuals beyond this many noise SD are outliers (the peak fit trims them likewise) and
/// do not count in the lack-of-fit tests.
const OUTLIER: f64 = 4.0;

/// A model is refitted over a window of this many of its narrow standard deviations when
/// that is larger than its own ([`widened`]): 3.5 σ holds the defect's foot (its 5 % level
/// lies at 2.45 σ) and enough plane beyond it.
const WIDE_WINDOW: f64 = 3.5;

/// A widened window is at most this many times the model's own.
const MAX_WIDENING: f64 = 2.0;

/// Fewest scan points around a core point for the lack-of-fit test (fewer: the model would
/// extrapolate into a hole, and the cylinder value stays).
const MIN_LOCAL: usize = 4;

/// An accepted peak model and its frame: the window's origin, normal and tangent axes.
pub(super) struct Model {
    /// The window's origin (the model's (u, v) = (0, 0)).
    pub origin: Point3<f64>,
    /// The window's normal (the model's heights are along it).
    pub normal: Vector3<f64>,
    /// The tangent axes of (u, v) ([`tangent_frame`] of the normal).
    axes: (Vector3<f64>, Vector3<f64>),
    /// The fitted model.
    pub fit: PeakFit,
}

impl Model {
    /// The model `fit` of the window around `origin` with outward unit `normal`.
    pub fn new(origin: Point3<f64>, normal: Vector3<f64>, fit: PeakFit) -> Model {
        let axes = tangent_frame(&normal);
        Model {
            origin,
            normal,
            axes,
            fit,
        }
    }

    /// (u, v) of `x` in the model's tangent frame and its offset along the normal.
    fn local(&self, x: &Point3<f64>) -> (f64, f64, f64) {
        let d = x - self.origin;
        (
            d.dot(&self.axes.0),
            d.dot(&self.axes.1),
            d.dot(&self.normal),
        )
    }
}

/// Reusable buffers of [`fit_window`].
#[derive(Default)]
pub(super) struct ModelScratch {
    knn: Vec<(f64, u32)>,
    window: Vec<Local>,
    /// Radius of the window last gathered, mm.
    radius: f64,
    peak: PeakScratch,
}

impl ModelScratch {
    /// Scan points of the window last gathered ([`gather_window`]) within `radius` of its
    /// origin whose height times `sign` lies in (`low`, `high`].
    pub(super) fn heights_between(&self, radius: f64, sign: f64, low: f64, high: f64) -> usize {
        self.window
            .iter()
            .filter(|p| p[0].hypot(p[1]) <= radius && p[2] * sign > low && p[2] * sign <= high)
            .count()
    }
}

/// Gathers the scan points within `radius` (the peak window, [`Prepared::peak_window`], or
/// a widened one) around `origin` (outward unit `normal`) into `scratch`: (u, v) in the
/// normal's tangent frame and height = the point-pair distance. Returns how many there are.
pub(super) fn gather_window(
    prep: &Prepared,
    origin: &Point3<f64>,
    normal: &Vector3<f64>,
    radius: f64,
    scratch: &mut ModelScratch,
) -> usize {
    let (e1, e2) = tangent_frame(normal);
    scratch.radius = radius;
    let window = &mut scratch.window;
    window.clear();
    scan_pairs(
        prep,
        origin,
        normal,
        radius,
        &mut scratch.knn,
        |_, d, pair| {
            window.push([d.dot(&e1), d.dot(&e2), pair]);
        },
    );
    window.len()
}

/// The peak model (`peakfit.rs`) fitted to the window last gathered into `scratch`
/// ([`gather_window`]), started from the height `start`, with the window's expectations for
/// the caller's guard; None when the fit does not converge.
pub(super) fn fit_window(
    prep: &Prepared,
    start: f64,
    cfg: &CompareConfig,
    scratch: &mut ModelScratch,
) -> Option<(PeakFit, PeakWindow)> {
    let w = PeakWindow {
        radius: scratch.radius,
        noise: prep.noise,
        max_misfit: cfg.adaptive.max_misfit,
        start: supported_start(&scratch.window, start, prep.smallest_radius()),
    };
    let fit = fit_peak(&scratch.window, &w, &mut scratch.peak)?;
    Some((fit, w))
}

/// The height a peak fit starts from: `start`, or the second largest height of its sign among
/// the `window`'s scan points within `radius` of the origin when that is larger. A cylinder
/// reads a defect narrower than it at about half its height (seed 45 at 300k: a 0.39 mm deep,
/// 0.57 mm wide pit at 0.16 mm), and the fit's height limit (twice the start) would cut its
/// top off; the second largest, as one stray scan point cannot raise it.
fn supported_start(window: &[Local], start: f64, radius: f64) -> f64 {
    let sign = start.signum();
    let (mut first, mut second) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in window.iter().filter(|p| p[0].hypot(p[1]) <= radius) {
        let h = p[2] * sign;
        if h > first {
            (first, second) = (h, first);
        } else if h > second {
            second = h;
        }
    }
    sign * start.abs().max(second)
}

/// Replaces the result of every core point (`points`, outward unit `normals`, `values`; rows
/// already measured by a model are left alone) that lies inside the defect of a model by that
/// model's height there. The models: `models` and those [`more_models`] fits, each kept when
/// its window follows its profile ([`follows_profile`]). Inside: the defect term at least
/// [`MIN_SHARE`] of its amplitude, within the window radius and the cylinders' half-length,
/// normal within `max_normal_angle`; the model whose origin is nearest when several reach a
/// point (those of `models` first). A point keeps its cylinder value unless the scan points
/// within the smallest radius around it pass the lack-of-fit test ([`LACK_OF_FIT`]). The LoD is t95(n - 9) × the height's standard error
/// from the fit's covariance plus the registration term; rows become [`Reason::PeakModel`]
/// (`radius` the window, `n_ref` 0, `n_scan` the model's points).
pub(super) fn fill(
    prep: &Prepared,
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &mut [Deviation],
    models: Vec<Model>,
    cfg: &CompareConfig,
) {
    let index = Neighbours::new(points);
    let mut models = shaped(prep, models, cfg);
    // Per core point: the nearest model that reaches it (distance from its origin, model).
    let mut owner: Vec<Option<(f64, usize)>> = vec![None; points.len()];
    claim(
        prep, &index, points, normals, values, &models, 0, &mut owner,
    );
    let first = models.len();
    let extra = more_models(prep, points, normals, values, &owner, cfg);
    models.extend(shaped(prep, extra, cfg));
    claim(
        prep, &index, points, normals, values, &models, first, &mut owner,
    );
    let filled: Vec<(usize, Deviation)> = owner
        .par_iter()
        .enumerate()
        .filter_map(|(k, o)| o.map(|(_, m)| (k, m)))
        .map_init(Vec::new, |knn, (k, m)| {
            let value = modelled_at(prep, &models[m], &points[k], &normals[k], cfg, knn)?;
            Some((k, value))
        })
        .flatten()
        .collect();
    for &(k, value) in &filled {
        let (peak_fitted, peak) = (values[k].peak_fitted, values[k].peak);
        values[k] = value;
        // A summit keeps its fitted peak, at least the height there (a widened model's refit
        // may read a little above the first fit's peak at the top).
        if peak_fitted {
            values[k].peak = peak.signum() * peak.abs().max(value.distance.abs());
            values[k].peak_fitted = true;
        }
    }
}

/// Those of `models` ([`widened`] where that applies) whose window follows their profile
/// ([`follows_profile`]).
fn shaped(prep: &Prepared, models: Vec<Model>, cfg: &CompareConfig) -> Vec<Model> {
    models
        .into_par_iter()
        .map_init(ModelScratch::default, |scratch, m| {
            let m = widened(prep, m, cfg, scratch);
            follows_profile(prep, &m, &mut scratch.knn).then_some(m)
        })
        .flatten()
        .collect()
}

/// `model` refitted over a window of [`WIDE_WINDOW`] × its narrow width (at most
/// [`MAX_WIDENING`] × its own) when that is clearly larger than its own, and the refit
/// describes its window (step 10's guard without the bound on the peak's standard error);
/// else `model`. A defect whose tolerance crossing lies near or beyond the window's edge is
/// otherwise measured there by the cylinders, and its model's plane and amplitude trade off
/// over a window that holds little of its foot.
fn widened(
    prep: &Prepared,
    model: Model,
    cfg: &CompareConfig,
    scratch: &mut ModelScratch,
) -> Model {
    let own = model.fit.window();
    let [narrow, wide] = model.fit.widths;
    let radius = (WIDE_WINDOW * narrow).min(MAX_WIDENING * own);
    if radius <= 1.1 * own || wide > 2.0 * narrow {
        return model;
    }
    gather_window(prep, &model.origin, &model.normal, radius, scratch);
    match fit_window(prep, model.fit.peak, cfg, scratch) {
        Some((fit, w)) if fit.describes(&w, MIN_SUPPORT) => {
            Model::new(model.origin, model.normal, fit)
        }
        _ => model,
    }
}

/// Sets `owner` of the core points inside the defects of `models[from..]` (see [`fill`]) to
/// the model whose origin is nearest; points owned before `from` keep their model.
#[allow(clippy::too_many_arguments)]
fn claim(
    prep: &Prepared,
    index: &Neighbours,
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &[Deviation],
    models: &[Model],
    from: usize,
    owner: &mut [Option<(f64, usize)>],
) {
    for (m, model) in models.iter().enumerate().skip(from) {
        let window = model.fit.window();
        for nb in index.within_unsorted(&model.origin, window) {
            let k = nb.index;
            let foreign =
                values[k].reason != Reason::Ok || normals[k].dot(&model.normal) < prep.cos_limit;
            if foreign || owner[k].is_some_and(|(_, earlier)| earlier < from) {
                continue;
            }
            let (u, v, along) = model.local(&points[k]);
            let r = u.hypot(v);
            let inside = r <= window
                && along.abs() <= prep.half_length
                && model.fit.defect_share(u, v) >= MIN_SHARE;
            if inside && owner[k].is_none_or(|(best, _)| r < best) {
                owner[k] = Some((r, m));
            }
        }
    }
}

/// Models for the error points that no model reaches (beyond `refine_above`, significant,
/// not `owner`ed): a long ridge holds a few summits whose fits do not all converge, and the
/// windows of those that do cover a part of it. Larger |distance| first, each at least half
/// a window radius from those taken before, a model fitted around it that describes its
/// window (step 10's guard without the bound on the peak's standard error).
fn more_models(
    prep: &Prepared,
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &[Deviation],
    owner: &[Option<(f64, usize)>],
    cfg: &CompareConfig,
) -> Vec<Model> {
    let mut open: Vec<usize> = (0..values.len())
        .filter(|&k| {
            let v = &values[k];
            owner[k].is_none()
                && v.reason == Reason::Ok
                && v.significant
                && v.distance.abs() > cfg.adaptive.refine_above
        })
        .collect();
    open.sort_by(|&a, &b| {
        values[b]
            .distance
            .abs()
            .total_cmp(&values[a].distance.abs())
            .then(a.cmp(&b))
    });
    let apart = 0.5 * prep.peak_window();
    let mut starts: Vec<usize> = Vec::new();
    for k in open {
        if starts
            .iter()
            .all(|&s| (points[s] - points[k]).norm() >= apart)
        {
            starts.push(k);
        }
    }
    starts
        .par_iter()
        .map_init(ModelScratch::default, |scratch, &k| {
            // The model need not pin a peak: the fill's LoD carries each height's own
            // standard error.
            gather_window(prep, &points[k], &normals[k], prep.peak_window(), scratch);
            let (fit, w) = fit_window(prep, values[k].distance, cfg, scratch)?;
            let described = fit.describes(&w, MIN_SUPPORT);
            described.then(|| Model::new(points[k], normals[k], fit))
        })
        .flatten()
        .collect()
}

/// Whether the scan points of `model`'s window follow its profile: split by the level of the
/// defect term ([`LEVELS`]; levels with fewer than [`MIN_LOCAL`] points left out), the sum of
/// the squared standardised mean residuals (mean / (noise / √n) per level) is within the
/// 99 % quantile of a chi-square with one degree of freedom per level ([`CHI2_99`]). A
/// Gaussian fitted to a flat-topped or spherical defect passes the peak fit's guard (residual
/// SD within 1.3 × the noise) but overshoots at the top and falls short on the shoulders,
/// which these means show.
fn follows_profile(prep: &Prepared, model: &Model, knn: &mut Vec<(f64, u32)>) -> bool {
    let mut bins = [(0usize, 0.0); LEVELS.len() - 1];
    let o = model.origin;
    scan_pairs(
        prep,
        &o,
        &model.normal,
        model.fit.window(),
        knn,
        |_, d, pair| {
            let (u, v, _) = model.local(&(o + d));
            let share = model.fit.defect_share(u, v);
            let residual = pair - model.fit.height_at(u, v).0;
            let level = LEVELS
                .windows(2)
                .position(|w| share >= w[0] && share < w[1]);
            if let (Some(b), true) = (level, residual.abs() <= OUTLIER * prep.noise) {
                bins[b].0 += 1;
                bins[b].1 += residual;
            }
        },
    );
    // The levels' standardised mean residuals, squared and summed: a chi-square with as
    // many degrees of freedom as levels when the model is right.
    let (mut chi2, mut levels) = (0.0, 0);
    for &(n, sum) in &bins {
        if n >= MIN_LOCAL {
            let z = sum / n as f64 / (prep.noise / (n as f64).sqrt());
            chi2 += z * z;
            levels += 1;
        }
    }
    chi2 <= CHI2_99[levels]
}

/// `model`'s result at core point `p` (outward unit normal `n`), or None when the scan points
/// within the smallest radius of `p` do not agree with the model ([`LACK_OF_FIT`]) or are
/// fewer than [`MIN_LOCAL`] (`knn`: scratch).
fn modelled_at(
    prep: &Prepared,
    model: &Model,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
    knn: &mut Vec<(f64, u32)>,
) -> Option<Deviation> {
    let fit = &model.fit;
    let (u, v, _) = model.local(p);
    let (height, se) = fit.height_at(u, v);
    if !se.is_finite() {
        return None;
    }
    let (mut count, mut sum, mut far) = (0usize, 0.0, 0usize);
    scan_pairs(prep, p, n, prep.smallest_radius(), knn, |_, d, pair| {
        let (su, sv, _) = model.local(&(p + d));
        let residual = pair - fit.height_at(su, sv).0;
        if residual.abs() <= OUTLIER * prep.noise {
            sum += residual;
            count += 1;
        } else {
            far += 1;
        }
    });
    // Outliers are rare; many points beyond OUTLIER noise SD are the model missing the
    // surface (seed 36 at 300k: a ridge model 0.055 mm high at the ridge's end, where all but
    // 5 of the points lay beyond).
    if count < MIN_LOCAL || far > 1 + (count + far) / 10 {
        return None;
    }
    let mean = sum / count as f64;
    let se_mean = (prep.noise * prep.noise / count as f64 + se * se).sqrt();
    if mean.abs() > LACK_OF_FIT * se_mean {
        return None;
    }
    Some(model_result(fit, height, se, n, cfg))
}

/// The [`Reason::PeakModel`] result of `fit`'s `height` (standard error `se`) at a core point
/// with outward unit normal `n`: LoD t95(n - 9) × se plus the registration term, `radius` the
/// window, `n_ref` 0, `n_scan` the model's points.
pub(super) fn model_result(
    fit: &PeakFit,
    height: f64,
    se: f64,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
) -> Deviation {
    let value = Deviation {
        distance: height,
        uncertainty: student_t95(fit.dof()) * se + 1.96 * cfg.registration_error,
        significant: false,
        radius: fit.window(),
        n_ref: 0,
        n_scan: fit.n,
        direction: Vector3::zeros(),
        spread: [0.0, fit.sigma],
        peak: f64::NAN,
        peak_fitted: false,
        reason: Reason::PeakModel,
    };
    value.finish(n)
}

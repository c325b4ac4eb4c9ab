//! Step 7, model fill: inside a defect that an accepted peak model describes, the
//! model's height replaces the cylinder estimate at the core points. A cylinder's quadric
//! flattens a narrow defect and at the largest radius trims it as outliers, so the core points
//! on a defect's flanks (where its boundary at the tolerance lies) read 0.01-0.07 mm off; the
//! model is fitted to all the scan points of the defect and pins the flank to a few
//! micrometres where it describes them. A model counts only when its window's scan points
//! follow its profile level by level, and a core point takes it only where the scan points
//! around it agree with it (lack-of-fit tests), so a defect of another shape keeps its
//! cylinder values. docs/ACCURACY.md (step 13) has the numbers.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::context::Context;
use super::model::{fit_window, gather_window, model_result, Model, ModelScratch};
use super::peak_model::MIN_SUPPORT;
use super::quadric::TRIM_NOISE;
use crate::compare::config::{CompareConfig, FillConfig};
use crate::compare::deviation::{Deviation, Reason};
use crate::spatial::Neighbours;

/// Levels of the defect term (share of its amplitude) that split a window's scan points for
/// [`follows_profile`].
const LEVELS: [f64; 7] = [0.05, 0.15, 0.3, 0.5, 0.7, 0.85, 1.01];

/// 99 % quantiles of the chi-square distribution with 0-6 degrees of freedom (one per level
/// of [`LEVELS`] that holds points).
const CHI2_99: [f64; 7] = [0.0, 6.63, 9.21, 11.34, 13.28, 15.09, 16.81];

/// Residuals beyond this many noise SD are outliers (the peak fit trims them likewise) and
/// do not count in the lack-of-fit tests.
const OUTLIER: f64 = TRIM_NOISE;

/// A model is widened only when the wider window is more than this many times its own (a
/// few per cent more plane is not worth a refit).
const MIN_WIDENING: f64 = 1.1;

/// A model whose wide width exceeds this many times its narrow one is a ridge: a window of
/// a few narrow widths would cut it across, and it keeps its own.
const RIDGE_ASPECT: f64 = 2.0;

/// A core point takes a model only when at most 1 + n / this of its n scan points lie beyond
/// the outlier limit: outliers are rare, many such points are the model missing the surface
/// (seed 36 at 300k: a ridge model 0.055 mm high at the ridge's end, where all but 5 of the
/// points lay beyond).
const MAX_FAR_SHARE: usize = 10;

/// Starts of [`more_models`] lie at least this share of a peak window apart (closer ones'
/// windows would mostly overlap).
const MODEL_SPACING: f64 = 0.5;

/// Replaces the result of every core point (`points`, outward unit `normals`, `values`; rows
/// already measured by a model are left alone) that lies inside the defect of a model by that
/// model's height there. The models: `models` and those [`more_models`] fits, each kept when
/// its window follows its profile ([`follows_profile`]). Inside: the defect term at least
/// `fill.min_share` of its amplitude, within the window radius and the cylinders' half-length,
/// normal within `max_normal_angle`; the model whose origin is nearest when several reach a
/// point (those of `models` first). A point keeps its cylinder value unless the scan points
/// within the smallest radius around it pass the lack-of-fit test (`fill.lack_of_fit`). The
/// LoD is t95(n - 9) × the height's standard error from the fit's covariance plus the
/// registration term; rows become [`Reason::PeakModel`] (`radius` the window, `n_ref` 0,
/// `n_scan` the model's points).
pub(super) fn fill(
    prep: &Context,
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
    let f = &cfg.adaptive.fill;
    let at = Claim {
        index: &index,
        points,
        normals,
        values,
    };
    claim(prep, &at, f, &models, 0, &mut owner);
    let first = models.len();
    let extra = more_models(prep, points, normals, values, &owner, cfg);
    models.extend(shaped(prep, extra, cfg));
    claim(prep, &at, f, &models, first, &mut owner);
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
fn shaped(prep: &Context, models: Vec<Model>, cfg: &CompareConfig) -> Vec<Model> {
    models
        .into_par_iter()
        .map_init(ModelScratch::default, |scratch, m| {
            let m = widened(prep, m, cfg, scratch);
            let min_local = cfg.adaptive.fill.min_local;
            follows_profile(prep, &m, min_local, &mut scratch.knn).then_some(m)
        })
        .flatten()
        .collect()
}

/// `model` refitted over a window of `fill.wide_window` × its narrow width (at most
/// `fill.max_widening` × its own) when that is clearly larger than its own ([`MIN_WIDENING`];
/// not on a ridge, [`RIDGE_ASPECT`]), and the refit
/// describes its window (the peak fit's guard without the bound on the peak's standard error);
/// else `model`. A defect whose tolerance crossing lies near or beyond the window's edge is
/// otherwise measured there by the cylinders, and its model's plane and amplitude trade off
/// over a window that holds little of its foot.
fn widened(prep: &Context, model: Model, cfg: &CompareConfig, scratch: &mut ModelScratch) -> Model {
    let own = model.fit.window();
    let [narrow, wide] = model.fit.widths;
    let f = &cfg.adaptive.fill;
    let radius = (f.wide_window * narrow).min(f.max_widening * own);
    if radius <= MIN_WIDENING * own || wide > RIDGE_ASPECT * narrow {
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

/// The core points [`claim`] hands to models: their index, positions, outward unit normals
/// and results.
struct Claim<'a> {
    index: &'a Neighbours,
    points: &'a [Point3<f64>],
    normals: &'a [Vector3<f64>],
    values: &'a [Deviation],
}

/// Sets `owner` of the core points of `at` inside the defects of `models[from..]` (see
/// [`fill`]) to the model whose origin is nearest; points owned before `from` keep their
/// model.
fn claim(
    prep: &Context,
    at: &Claim,
    f: &FillConfig,
    models: &[Model],
    from: usize,
    owner: &mut [Option<(f64, usize)>],
) {
    let Claim {
        index,
        points,
        normals,
        values,
    } = at;
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
                && model.fit.defect_share(u, v) >= f.min_share;
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
/// window (the peak fit's guard without the bound on the peak's standard error).
fn more_models(
    prep: &Context,
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
                && v.distance.abs() > prep.limits.refine_above
        })
        .collect();
    open.sort_by(|&a, &b| {
        values[b]
            .distance
            .abs()
            .total_cmp(&values[a].distance.abs())
            .then(a.cmp(&b))
    });
    let apart = MODEL_SPACING * prep.peak_window();
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
/// defect term ([`LEVELS`]; levels with fewer than `min_local` points left out), the sum of
/// the squared standardised mean residuals (mean / (noise / √n) per level) is within the
/// 99 % quantile of a chi-square with one degree of freedom per level ([`CHI2_99`]). A
/// Gaussian fitted to a flat-topped or spherical defect passes the peak fit's guard (residual
/// SD within 1.3 × the noise) but overshoots at the top and falls short on the shoulders,
/// which these means show.
fn follows_profile(
    prep: &Context,
    model: &Model,
    min_local: usize,
    knn: &mut Vec<(f64, u32)>,
) -> bool {
    let mut bins = [(0usize, 0.0); LEVELS.len() - 1];
    let o = model.origin;
    prep.scan_pairs(&o, &model.normal, model.fit.window(), knn, |_, d, pair| {
        let (u, v, _) = model.local(&(o + d));
        let share = model.fit.defect_share(u, v);
        let residual = pair - model.fit.height_at(u, v).0;
        let level = LEVELS
            .windows(2)
            .position(|w| share >= w[0] && share < w[1]);
        if let (Some(b), true) = (level, residual.abs() <= OUTLIER * prep.model_noise) {
            bins[b].0 += 1;
            bins[b].1 += residual;
        }
    });
    // The levels' standardised mean residuals, squared and summed: a chi-square with as
    // many degrees of freedom as levels when the model is right.
    let (mut chi2, mut levels) = (0.0, 0);
    for &(n, sum) in &bins {
        if n >= min_local {
            let z = sum / n as f64 / (prep.model_noise / (n as f64).sqrt());
            chi2 += z * z;
            levels += 1;
        }
    }
    chi2 <= CHI2_99[levels]
}

/// `model`'s result at core point `p` (outward unit normal `n`), or None when the scan points
/// within the smallest radius of `p` do not agree with the model (`fill.lack_of_fit`) or are
/// fewer than `fill.min_local` (`knn`: scratch).
fn modelled_at(
    prep: &Context,
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
    let f = &cfg.adaptive.fill;
    prep.scan_pairs(p, n, prep.smallest_radius(), knn, |_, d, pair| {
        let (su, sv, _) = model.local(&(p + d));
        let residual = pair - fit.height_at(su, sv).0;
        if residual.abs() <= OUTLIER * prep.model_noise {
            sum += residual;
            count += 1;
        } else {
            far += 1;
        }
    });
    // Outliers are rare; many points beyond OUTLIER noise SD are the model missing the
    // surface ([`MAX_FAR_SHARE`]).
    if count < f.min_local || far > 1 + (count + far) / MAX_FAR_SHARE {
        return None;
    }
    let mean = sum / count as f64;
    let se_mean = (prep.model_noise * prep.model_noise / count as f64 + se * se).sqrt();
    if mean.abs() > f.lack_of_fit * se_mean {
        return None;
    }
    Some(model_result(fit, height, se, n, cfg))
}

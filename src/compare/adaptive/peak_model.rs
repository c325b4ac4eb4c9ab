//! Local peak fit: the height of a defect's top from a model of its shape, not from the
//! largest of a few smoothed values (at 19 scan points/mm² the best scan point on a 0.4 mm wide
//! bump is typically a quarter below its top, and a quadric over the top flattens it).
//!
//! Model over the scan points' heights h above the reference surface, in the tangent frame
//! (u, v) of a window around the top:
//! h(x) = a0 + a1 u + a2 v + A exp(-½ (x - c)ᵀ P (x - c)), P = LᵀL, L = [[l11, l12], [0, l22]]
//! (an elliptic Gaussian whose precision P is positive semi-definite by construction: a ridge's
//! cross-section is fitted and its length may be unbounded). When that ellipse is elongated,
//! a capsule is fitted as well — A exp(-½ d²/s²), d the distance to a segment through the
//! centre (a Gaussian cross-section with a flat top along the length, as a ridge whose ends
//! lie in the window has) — and kept when it explains clearly more. Nine parameters, fitted by
//! Levenberg-Marquardt (nalgebra), trimmed twice like the quadric fits
//! (residual beyond max(4σ, 3 × 1.4826 × MAD)). The peak is the fitted surface at the centre,
//! a0 + a1 c_u + a2 c_v + A: a deviation from the reference like every distance (the plane is
//! the deviation of the surroundings, e.g. a neighbouring defect's flank), and the height the
//! data pins best when the window does not reach the defect's foot (a0 and A then trade off,
//! their sum does not). docs/ALGORITHMS.md has the guard, docs/ACCURACY.md the measured numbers.
use super::peak_shape::{
    levenberg_marquardt, model, principal, support, Normal, Params, Shape, PARAMS,
};
use super::quadric::{inliers, Local, TRIM_NOISE};

/// An ellipse whose wide width is at least this many times its narrow one is a ridge, and the
/// capsule is tried as well.
const ELONGATED: f64 = 2.0;

/// Fewest points where the fitted Gaussian contributes at least 10 % of its amplitude: fewer
/// cannot pin its six shape parameters (a spike through one noisy point). 7, not 8, since
/// 2026-12-01 (seed 80 at 300k: a 0.368 mm bump with 7; docs/ACCURACY.md, step 10).
pub(super) const MIN_SUPPORT: usize = 7;

/// A peak fit needs at least this many points (before and after trimming): two per
/// parameter, so that the residuals estimate the scatter.
const MIN_WINDOW_POINTS: usize = 2 * PARAMS;

/// An accepted peak's standard error is at most this share of its height (else the data do
/// not pin it: the quadric estimates' peak stays).
const MAX_RELATIVE_SE: f64 = 0.1;

/// The fitted centre lies within this share of the window radius from the window's origin
/// (the top the fit started from): farther, it fitted another bump or the window's edge.
const MAX_OFFSET_SHARE: f64 = 0.5;

/// At most 1 + n / this of a fit's n points may be trimmed (2 %): the model describes the
/// data, not a subset that suits it.
const TRIMMED_PER: usize = 50;

/// [`height_limit`]: heights beyond this many times the supported height ...
const HEIGHT_LIMIT_FACTOR: f64 = 2.0;

/// ... plus this many noise SDs are outliers or another surface.
const HEIGHT_LIMIT_NOISE: f64 = 4.0;

/// The start's plane is the median height of the points beyond this share of the window
/// radius (the defect's top lies near the origin).
const OUTER_SHARE: f64 = 0.6;

/// The start's centre and width come from the points above this share of the start's
/// amplitude (the Gaussian's half height: its area is 2π ln 2 σ²).
const HALF_HEIGHT: f64 = 0.5;

/// The start's width, in units of the window radius, is clamped to this range (a patch of one
/// point, or the whole window, says little about the width).
const START_WIDTH: (f64, f64) = (0.05, 0.4);

/// The 95 % quantile of a chi-square with one degree of freedom: the capsule's one extra
/// freedom must lower the RSS by more than this many residual variances.
const CHI2_1_95: f64 = 3.84;

/// Relative tolerance of the covariance's pseudo-inverse (singular values below this share
/// of JᵀJ's norm are a null direction: a ridge longer than the window).
const PINV_TOLERANCE: f64 = 1e-12;

/// A wide width beyond the window radius (scaled units: 1) makes the centre's offset count
/// across the wide axis only (the centre slides along a ridge freely).
const RIDGE_WIDE: f64 = 1.0;

/// The capsule's start segment is at most this long in window radii (the window's diameter).
const MAX_CAPSULE_WIDE: f64 = 2.0;

/// Smallest narrow width a capsule starts from, scaled units (its inverse is a parameter).
const MIN_START_WIDTH: f64 = 1e-3;

/// The window and the expectations of a peak fit.
#[derive(Debug, Clone, Copy)]
pub struct PeakWindow {
    /// Window radius around the start (the points' (u, v) origin), mm.
    pub radius: f64,
    /// Scan noise (one standard deviation), mm.
    pub noise: f64,
    /// The fit must leave a residual standard deviation of at most this many times the noise.
    pub max_misfit: f64,
    /// The top's height from the quadric estimates (its sign is the defect's), mm.
    pub start: f64,
}

/// A converged peak fit, before the guard.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeakFit {
    /// Fitted height at the centre, a0 + a1 c_u + a2 c_v + A, mm.
    pub peak: f64,
    /// Its standard error from the fit's covariance, mm.
    pub se: f64,
    /// Amplitude A of the Gaussian, mm.
    pub amplitude: f64,
    /// Centre c relative to the window's origin, mm.
    pub centre: [f64; 2],
    /// Distance of the centre from the window's origin across the Gaussian's wide axis
    /// (|c| for a round bump; on a ridge longer than the window the centre slides along it
    /// freely, and only its distance across counts), mm.
    pub offset: f64,
    /// Standard deviations of the Gaussian along its principal axes (narrow, wide), mm; the
    /// wide one is infinite on a ridge longer than the window.
    pub widths: [f64; 2],
    /// Residual standard deviation, mm.
    pub sigma: f64,
    /// Points used (after trimming).
    pub n: usize,
    /// Points trimmed as outliers of the model (beyond those over twice the start height).
    pub trimmed: usize,
    /// Points where the Gaussian is at least 10 % of A.
    pub support: usize,
    /// The largest height of the start's sign among the points used, mm (0 when none).
    pub top_kept: f64,
    /// The fitted parameters (scaled units), their covariance and the scale (the window
    /// radius), for [`PeakFit::height_at`].
    params: Params,
    cov: Normal,
    scale: f64,
    shape: Shape,
}

impl PeakFit {
    /// The guard: the centre ([`PeakFit::offset`]) within half the window, the narrow width at
    /// most the window radius (a wider defect is the quadric estimates' case) and supported by
    /// [`MIN_SUPPORT`] points, A and the peak of the start's sign, the residual SD at most
    /// `max_misfit` × noise and at most 1 + 2 % of the points trimmed (the model describes the
    /// data, not a subset that suits it), the peak's standard error at most a tenth of its height,
    /// and the peak at most twice the larger of the start and the highest point kept, plus 4 noise
    /// SD.
    pub fn accepted(&self, w: &PeakWindow) -> bool {
        self.describes(w, MIN_SUPPORT) && self.se <= MAX_RELATIVE_SE * self.peak.abs()
    }

    /// The guard of [`PeakFit::accepted`] without its bound on the standard error, with
    /// `min_support` points in place of [`MIN_SUPPORT`]: the model describes the data around
    /// a top of the start's sign.
    pub fn describes(&self, w: &PeakWindow, min_support: usize) -> bool {
        let supported = w.start.abs().max(self.top_kept);
        self.fits_data(w)
            && self.support >= min_support
            && self.peak.abs() <= height_limit(supported, w.noise)
    }

    /// The part of [`PeakFit::describes`] that asks whether the model follows the window's
    /// scan points, not whether they pin its top: at most 1 + 2 % of them trimmed, the centre
    /// within half the window, the narrow width at most the window radius, A and the peak of
    /// the start's sign, the residual SD at most `max_misfit` × noise.
    pub fn fits_data(&self, w: &PeakWindow) -> bool {
        let sign = w.start.signum();
        self.trimmed <= 1 + (self.n + self.trimmed) / TRIMMED_PER
            && self.offset <= MAX_OFFSET_SHARE * w.radius
            && self.widths[0] <= w.radius
            && self.amplitude * sign > 0.0
            && self.peak * sign > 0.0
            && self.sigma <= w.max_misfit * w.noise
    }

    /// Radius of the window it was fitted over, mm.
    pub fn window(&self) -> f64 {
        self.scale
    }

    /// Residual degrees of freedom: points used minus the model's parameters.
    pub fn dof(&self) -> usize {
        self.n - PARAMS
    }

    /// The defect term's share of its amplitude at (u, v) of the window's frame (mm): 1 at
    /// the top, falling to 0 off the defect.
    pub fn defect_share(&self, u: f64, v: f64) -> f64 {
        // The gradient along the amplitude is the defect term over the amplitude.
        model(self.shape, &self.params, u / self.scale, v / self.scale).1[3]
    }

    /// The fitted surface's height at (u, v) of the window's frame (mm) and its standard
    /// error from the fit's covariance (NaN when that is not positive there).
    pub fn height_at(&self, u: f64, v: f64) -> (f64, f64) {
        let (value, grad) = model(self.shape, &self.params, u / self.scale, v / self.scale);
        let var = grad.dot(&(self.cov * grad));
        (value, if var > 0.0 { var.sqrt() } else { f64::NAN })
    }
}

/// Heights beyond twice a supported `height` (the start, or the highest point a fit kept)
/// plus 4 noise SD are outliers or another surface, and a fitted peak beyond it is not what
/// the data support.
pub(super) fn height_limit(height: f64, noise: f64) -> f64 {
    HEIGHT_LIMIT_FACTOR * height + HEIGHT_LIMIT_NOISE * noise
}

/// Reusable buffers of [`fit_peak`].
#[derive(Default)]
pub struct PeakScratch {
    scaled: Vec<Local>,
    kept: Vec<Local>,
    capsule_kept: Vec<Local>,
    abs: Vec<f64>,
}

/// The median of `values` (scratch: reordered).
fn median(values: &mut [f64]) -> f64 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// The starting parameters over scaled points: the plane at the median height of the outer
/// part of the window, A = start − that, the centre and an isotropic width from the points
/// above half of A (the width: that patch's area = 2π ln 2 σ²).
fn start(pts: &[Local], w: &PeakWindow, abs: &mut Vec<f64>) -> Option<Params> {
    abs.clear();
    abs.extend(
        pts.iter()
            .filter(|p| p[0].hypot(p[1]) > OUTER_SHARE)
            .map(|p| p[2]),
    );
    let base = if abs.is_empty() { 0.0 } else { median(abs) };
    let amplitude = w.start - base;
    if amplitude * w.start <= 0.0 {
        return None;
    }
    let top: Vec<&Local> = pts
        .iter()
        .filter(|p| (p[2] - base) / amplitude > HALF_HEIGHT)
        .collect();
    let (mut cu, mut cv) = (0.0, 0.0);
    if !top.is_empty() {
        cu = top.iter().map(|p| p[0]).sum::<f64>() / top.len() as f64;
        cv = top.iter().map(|p| p[1]).sum::<f64>() / top.len() as f64;
    }
    // Scaled window area π; area per point π / n.
    let area = top.len().max(1) as f64 * std::f64::consts::PI / pts.len() as f64;
    let s = (area / (2.0 * std::f64::consts::PI * std::f64::consts::LN_2))
        .sqrt()
        .clamp(START_WIDTH.0, START_WIDTH.1);
    Some(Params::from([
        base,
        0.0,
        0.0,
        amplitude,
        cu,
        cv,
        1.0 / s,
        0.0,
        1.0 / s,
    ]))
}

/// Fits the peak model to `pts` (scan points as (u, v, height above the reference), mm, with
/// the window's origin at (0, 0)); None when the fit does not converge or is degenerate. The
/// caller applies [`PeakFit::accepted`].
pub fn fit_peak(pts: &[Local], w: &PeakWindow, scratch: &mut PeakScratch) -> Option<PeakFit> {
    let PeakScratch {
        scaled,
        kept,
        capsule_kept,
        abs,
    } = scratch;
    let s = w.radius;
    let limit = height_limit(w.start.abs(), w.noise);
    scaled.clear();
    scaled.extend(
        pts.iter()
            .filter(|p| p[2].abs() <= limit && p[0].hypot(p[1]) <= s)
            .map(|p| [p[0] / s, p[1] / s, p[2]]),
    );
    if scaled.len() < MIN_WINDOW_POINTS {
        return None;
    }
    let ellipse = fit_shape(Shape::Ellipse, scaled, start(scaled, w, abs)?, w, abs, kept)?;
    // Only for an elongated ellipse: on a round bump the capsule's extra freedom (a short
    // flat top) fits the noise and lowers the peak.
    let capsule = capsule_start(&ellipse.0)
        .and_then(|t0| fit_shape(Shape::Capsule, scaled, t0, w, abs, capsule_kept));
    // The capsule when it explains clearly more: its residual sum of squares lower than the
    // ellipse's (over the ellipse's points) by more than a chi-square(1) 95 % quantile
    // of its residual variance.
    let variance = |f: &(Params, f64, Normal, usize)| f.1 / (f.3 - PARAMS) as f64;
    let clearly_better = |c: &(Params, f64, Normal, usize)| {
        let rss_ellipse_pts: f64 = kept
            .iter()
            .map(|p| (p[2] - model(Shape::Capsule, &c.0, p[0], p[1]).0).powi(2))
            .sum();
        ellipse.1 - rss_ellipse_pts > CHI2_1_95 * variance(c)
    };
    let (shape, (t, rss, jtj, n), current) = match capsule {
        Some(c) if clearly_better(&c) => (Shape::Capsule, c, &*capsule_kept),
        _ => (Shape::Ellipse, ellipse, &*kept),
    };
    let var = rss / (n - PARAMS) as f64;
    // Pseudo-inverse: along a ridge longer than the window the centre is undetermined (a
    // null direction of JᵀJ that the peak barely depends on).
    let cov = jtj.pseudo_inverse(PINV_TOLERANCE * jtj.norm()).ok()? * var;
    let (cu, cv) = (t[4], t[5]);
    let peak = t[0] + t[1] * cu + t[2] * cv + t[3];
    let grad = Params::from([1.0, cu, cv, 1.0, t[1], t[2], 0.0, 0.0, 0.0]);
    // NaN (refused by the guard) when the covariance is not positive along the gradient.
    let var_peak = grad.dot(&(cov * grad));
    let se = if var_peak > 0.0 {
        var_peak.sqrt()
    } else {
        f64::NAN
    };
    let (narrow_axis, [narrow, wide]) = match shape {
        Shape::Ellipse => principal(&t),
        Shape::Capsule => {
            let (sin, cos) = t[6].sin_cos();
            let width = 1.0 / t[7].abs();
            let half = t[8] * t[8];
            (nalgebra::Vector2::new(-sin, cos), [width, width + half])
        }
    };
    let c = nalgebra::Vector2::new(cu, cv) * s;
    let offset = match wide > RIDGE_WIDE {
        true => c.dot(&narrow_axis).abs(),
        false => c.norm(),
    };
    let support = support(shape, &t, current);
    let sign = w.start.signum();
    let top_kept = current.iter().map(|p| p[2] * sign).fold(0.0, f64::max);
    Some(PeakFit {
        peak,
        se,
        amplitude: t[3],
        centre: [cu * s, cv * s],
        offset,
        widths: [narrow * s, wide * s],
        sigma: var.sqrt(),
        n,
        trimmed: scaled.len() - n,
        support,
        top_kept,
        params: t,
        cov,
        scale: s,
        shape,
    })
}

/// The capsule's start from a fitted ellipse `t` when that is elongated ([`ELONGATED`]):
/// along its wide axis, with its narrow width and a segment as long as the wide width exceeds
/// the narrow one (capped by the window).
fn capsule_start(t: &Params) -> Option<Params> {
    let (narrow_axis, widths) = principal(t);
    if widths[1] < ELONGATED * widths[0] {
        return None;
    }
    let theta = (-narrow_axis.x).atan2(narrow_axis.y);
    let half = (widths[1].min(MAX_CAPSULE_WIDE) - widths[0]).max(0.0);
    let mut start = *t;
    let narrow = 1.0 / widths[0].max(MIN_START_WIDTH);
    (start[6], start[7], start[8]) = (theta, narrow, half.sqrt());
    Some(start)
}

/// Levenberg-Marquardt of `shape` from `t` over `scaled`, then twice more over the points
/// within the trimming limit of the last fit (left in `kept`): the parameters, RSS, JᵀJ and
/// the number of points kept (the first of `kept`).
fn fit_shape(
    shape: Shape,
    scaled: &[Local],
    t: Params,
    w: &PeakWindow,
    abs: &mut Vec<f64>,
    kept: &mut Vec<Local>,
) -> Option<(Params, f64, Normal, usize)> {
    let mut fitted = levenberg_marquardt(shape, scaled, t)?;
    for _ in 0..2 {
        let t = fitted.0;
        let model_at = |p: &Local| model(shape, &t, p[0], p[1]).0;
        inliers(scaled, TRIM_NOISE * w.noise, model_at, abs, kept);
        if kept.len() < MIN_WINDOW_POINTS {
            return None;
        }
        fitted = levenberg_marquardt(shape, kept, t)?;
    }
    Some((fitted.0, fitted.1, fitted.2, kept.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Scan points at 19 points/mm² (the 300k case) over a 2 mm window with 0.015 mm noise;
    /// `shape(u, v)` is the true height.
    fn planted(shape: impl Fn(f64, f64) -> f64, seed: u64) -> Vec<Local> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let n = (19.0 * std::f64::consts::PI * 4.0) as usize;
        (0..n)
            .map(|_| loop {
                let (u, v): (f64, f64) = (rng.gen_range(-2.0..2.0), rng.gen_range(-2.0..2.0));
                if u.hypot(v) <= 2.0 {
                    let noise: f64 = (0..12).map(|_| rng.gen::<f64>()).sum::<f64>() - 6.0;
                    break [u, v, shape(u, v) + 0.015 * noise];
                }
            })
            .collect()
    }

    fn window(start: f64) -> PeakWindow {
        PeakWindow {
            radius: 2.0,
            noise: 0.015,
            max_misfit: 1.3,
            start,
        }
    }

    /// Fits of `shape` (true top `height`) planted on noise seeds 0..8, started from `start`:
    /// each accepted and within 10 % of the height, their mean within 3 %.
    fn recovered(shape: impl Fn(f64, f64) -> f64 + Copy, height: f64, start: f64) -> Vec<PeakFit> {
        let w = window(start);
        let fits: Vec<PeakFit> = (0..8)
            .map(|seed| {
                let pts = planted(shape, seed);
                let f = fit_peak(&pts, &w, &mut PeakScratch::default()).expect("converges");
                assert!(f.accepted(&w), "seed {seed}: {f:?}");
                assert!(
                    (f.peak - height).abs() <= 0.1 * height,
                    "seed {seed}: {f:?}"
                );
                f
            })
            .collect();
        let mean = fits.iter().map(|f| f.peak).sum::<f64>() / fits.len() as f64;
        assert!((mean - height).abs() <= 0.03 * height, "mean {mean}");
        fits
    }

    /// A 0.3 mm high, 0.64 mm wide (FWHM) Gaussian bump 0.15 mm off the window's origin,
    /// started from a quadric-flattened 0.22 mm: the fit's peak is within 10 % on every seed
    /// (its standard error is 3-6 %: about 6 points lie within the top half of the bump) and
    /// within 3 % on average.
    #[test]
    fn recovers_a_gaussian_bump() {
        let sigma = 0.64 / 2.3548;
        let bump = |u: f64, v: f64| {
            let r2 = (u - 0.1).powi(2) + (v + 0.1).powi(2);
            0.3 * (-r2 / (2.0 * sigma * sigma)).exp()
        };
        for (seed, f) in recovered(bump, 0.3, 0.22).iter().enumerate() {
            assert!(
                (f.widths[0] - sigma).abs() < 0.2 * sigma,
                "seed {seed}: {f:?}"
            );
        }
        // A ridge: the cross-section is fitted, the length is left open.
        let ridge = |u: f64, _v: f64| -0.2 * (-(u * u) / (2.0 * sigma * sigma)).exp();
        let pts = planted(ridge, 9);
        let w = window(-0.15);
        let f = fit_peak(&pts, &w, &mut PeakScratch::default()).expect("converges");
        assert!(
            f.accepted(&w) && (f.peak + 0.2).abs() <= 0.04 * 0.2,
            "{f:?}"
        );
        assert!(f.widths[1] > 5.0 * f.widths[0], "{f:?}");
    }

    /// A ridge whose ends lie in the window (0.2 mm high, 0.5 mm wide, its core segment
    /// 1.5 mm long: the synth cases' ridge shape, a Gaussian cross-section around a segment).
    /// An elliptic Gaussian must bend down along the flat top and overshoots it (measured:
    /// +11 to +22 % on the 300k synth cases' short ridges); the capsule fits the flat top:
    /// every seed within 10 %, the mean within 3 %.
    #[test]
    fn recovers_a_short_ridge() {
        let sigma = 0.5 / 2.3548;
        let (dir, half) = ((0.6f64, 0.8f64), 0.75);
        let ridge = |u: f64, v: f64| {
            let (du, dv) = (u - 0.1, v + 0.05);
            let along = (du * dir.0 + dv * dir.1).clamp(-half, half);
            let r2 = (du - along * dir.0).powi(2) + (dv - along * dir.1).powi(2);
            0.2 * (-r2 / (2.0 * sigma * sigma)).exp()
        };
        recovered(ridge, 0.2, 0.17);
    }

    /// Shapes that are not Gaussian: a cone (0.3 mm high, 0.5 mm base radius) and a spherical
    /// cap (0.3 mm high, 0.6 mm base radius). The fit is either refused (the caps: the model
    /// fits only after trimming many points) or within 15 % (the cone's sharp tip is held by
    /// a single point or none at this density) and never above the true top by more than 10 %.
    #[test]
    fn stays_sane_on_other_shapes() {
        let cone = |u: f64, v: f64| 0.3 * (1.0 - u.hypot(v) / 0.5).max(0.0);
        let radius = (0.6f64 * 0.6 + 0.3 * 0.3) / (2.0 * 0.3);
        let cap = |u: f64, v: f64| {
            let r2 = u * u + v * v;
            (radius * radius - r2).max(0.0).sqrt() - (radius - 0.3)
        };
        let mut accepted = 0;
        for seed in 0..8 {
            for (name, pts) in [("cone", planted(cone, seed)), ("cap", planted(cap, seed))] {
                let w = window(0.2);
                let Some(f) = fit_peak(&pts, &w, &mut PeakScratch::default()) else {
                    continue;
                };
                if f.accepted(&w) {
                    accepted += 1;
                    assert!(
                        (f.peak - 0.3).abs() <= 0.15 * 0.3 && f.peak <= 1.1 * 0.3,
                        "{name} seed {seed}: {f:?}"
                    );
                }
            }
        }
        eprintln!("{accepted} of 16 non-Gaussian fits accepted");
    }
}

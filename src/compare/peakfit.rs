//! Local peak fit: the height of a defect's top from a model of its shape, not from the
//! largest of a few smoothed values (at 19 scan points/mm² the best scan point on a 0.4 mm wide
//! bump is typically a quarter below its top, and a quadric over the top flattens it).
//!
//! Model over the scan points' heights h above the reference surface, in the tangent frame
//! (u, v) of a window around the top:
//! h(x) = a0 + a1 u + a2 v + A exp(-½ (x - c)ᵀ P (x - c)), P = LᵀL, L = [[l11, l12], [0, l22]]
//! (an elliptic Gaussian whose precision P is positive semi-definite by construction: a ridge's
//! cross-section is fitted and its length may be unbounded). Nine parameters, fitted by
//! Levenberg-Marquardt (nalgebra), trimmed twice like the quadric fits
//! (residual beyond max(4σ, 3 × 1.4826 × MAD)). The peak is the fitted surface at the centre,
//! a0 + a1 c_u + a2 c_v + A: a deviation from the reference like every distance (the plane is
//! the deviation of the surroundings, e.g. a neighbouring defect's flank), and the height the
//! data pins best when the window does not reach the defect's foot (a0 and A then trade off,
//! their sum does not). docs/ALGORITHMS.md has the guard and the measured numbers.
use nalgebra::{Matrix2, SMatrix, SVector};

use super::fit::{inliers, Local};

type Params = SVector<f64, 9>;
type Normal = SMatrix<f64, 9, 9>;

/// Parameters of the model.
const PARAMS: usize = 9;

/// Levenberg-Marquardt iterations before a fit counts as not converged.
const MAX_ITERATIONS: usize = 100;

/// Fewest points where the fitted Gaussian contributes at least 10 % of its amplitude: fewer
/// cannot pin its six shape parameters (a spike through one noisy point).
const MIN_SUPPORT: usize = 8;

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
    /// The fitted parameters (scaled units), their covariance and the scale (the window
    /// radius), for [`PeakFit::height_at`].
    params: Params,
    cov: Normal,
    scale: f64,
}

impl PeakFit {
    /// The guard: the centre ([`PeakFit::offset`]) within half the window, the narrow width at
    /// most the window radius (a wider defect is the quadric estimates' case) and supported by
    /// [`MIN_SUPPORT`] points, A and the peak of the start's sign, the residual SD at most `max_misfit` × noise and at
    /// most 1 + 2 % of the points trimmed (the model describes the data, not a subset that
    /// suits it), the peak's standard error at most a tenth of its height, and the peak at
    /// most twice the quadric top plus 4 noise SD.
    pub fn accepted(&self, w: &PeakWindow) -> bool {
        self.describes(w, MIN_SUPPORT) && self.se <= 0.1 * self.peak.abs()
    }

    /// The guard of [`PeakFit::accepted`] without its bound on the standard error, with
    /// `min_support` points in place of [`MIN_SUPPORT`]: the model describes the data around
    /// a top of the start's sign.
    pub fn describes(&self, w: &PeakWindow, min_support: usize) -> bool {
        let sign = w.start.signum();
        self.trimmed <= 1 + (self.n + self.trimmed) / 50
            && self.offset <= 0.5 * w.radius
            && self.widths[0] <= w.radius
            && self.support >= min_support
            && self.amplitude * sign > 0.0
            && self.peak * sign > 0.0
            && self.peak.abs() <= height_limit(w)
            && self.sigma <= w.max_misfit * w.noise
    }

    /// Residual degrees of freedom: points used minus the model's parameters.
    pub fn dof(&self) -> usize {
        self.n - PARAMS
    }

    /// The fitted surface's height at (u, v) of the window's frame (mm) and its standard
    /// error from the fit's covariance (NaN when that is not positive there).
    pub fn height_at(&self, u: f64, v: f64) -> (f64, f64) {
        let (value, grad) = model(&self.params, u / self.scale, v / self.scale);
        let var = grad.dot(&(self.cov * grad));
        (value, if var > 0.0 { var.sqrt() } else { f64::NAN })
    }
}

/// Heights beyond twice the quadric top plus 4 noise SD are outliers or another surface, and
/// a fitted peak beyond it is not what the data support.
fn height_limit(w: &PeakWindow) -> f64 {
    2.0 * w.start.abs() + 4.0 * w.noise
}

/// Reusable buffers of [`fit_peak`].
#[derive(Default)]
pub struct PeakScratch {
    scaled: Vec<Local>,
    kept: Vec<Local>,
    abs: Vec<f64>,
}

/// The model's value at scaled (u, v) and its gradient in the parameters.
fn model(t: &Params, u: f64, v: f64) -> (f64, Params) {
    let (du, dv) = (u - t[4], v - t[5]);
    let w1 = t[6] * du + t[7] * dv;
    let w2 = t[8] * dv;
    let g = (-0.5 * (w1 * w1 + w2 * w2)).exp();
    let ag = t[3] * g;
    let value = t[0] + t[1] * u + t[2] * v + ag;
    let grad = Params::from([
        1.0,
        u,
        v,
        g,
        ag * w1 * t[6],
        ag * (w1 * t[7] + w2 * t[8]),
        -ag * w1 * du,
        -ag * w1 * dv,
        -ag * w2 * dv,
    ]);
    (value, grad)
}

/// Residual sum of squares, JᵀJ and Jᵀr over `pts` at `t`.
fn normal_equations(pts: &[Local], t: &Params) -> (f64, Normal, Params) {
    let (mut rss, mut jtj, mut jtr) = (0.0, Normal::zeros(), Params::zeros());
    for p in pts {
        let (value, grad) = model(t, p[0], p[1]);
        let r = p[2] - value;
        rss += r * r;
        jtj.ger(1.0, &grad, &grad, 1.0);
        jtr += grad * r;
    }
    (rss, jtj, jtr)
}

/// Levenberg-Marquardt from `t`: the parameters, the RSS and JᵀJ at the minimum; None when it
/// does not converge within [`MAX_ITERATIONS`].
fn levenberg_marquardt(pts: &[Local], mut t: Params) -> Option<(Params, f64, Normal)> {
    let (mut rss, mut jtj, mut jtr) = normal_equations(pts, &t);
    let mut mu = 1e-3;
    for _ in 0..MAX_ITERATIONS {
        let mut damped = jtj;
        for i in 0..PARAMS {
            damped[(i, i)] += mu * jtj[(i, i)].max(1e-12);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&jtr)) else {
            mu *= 10.0;
            continue;
        };
        let next = t + step;
        let (rss_next, jtj_next, jtr_next) = normal_equations(pts, &next);
        if rss_next < rss {
            let done = rss - rss_next <= 1e-10 * rss || step.norm() <= 1e-10 * t.norm();
            (t, rss, jtj, jtr) = (next, rss_next, jtj_next, jtr_next);
            mu = (mu / 3.0).max(1e-12);
            if done {
                return Some((t, rss, jtj));
            }
        } else {
            mu *= 4.0;
            // No step lowers the RSS: a minimum.
            if mu > 1e10 {
                return Some((t, rss, jtj));
            }
        }
    }
    None
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
    abs.extend(pts.iter().filter(|p| p[0].hypot(p[1]) > 0.6).map(|p| p[2]));
    let base = if abs.is_empty() { 0.0 } else { median(abs) };
    let amplitude = w.start - base;
    if amplitude * w.start <= 0.0 {
        return None;
    }
    let top: Vec<&Local> = pts
        .iter()
        .filter(|p| (p[2] - base) / amplitude > 0.5)
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
        .clamp(0.05, 0.4);
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
    let PeakScratch { scaled, kept, abs } = scratch;
    let s = w.radius;
    let limit = height_limit(w);
    scaled.clear();
    scaled.extend(
        pts.iter()
            .filter(|p| p[2].abs() <= limit && p[0].hypot(p[1]) <= s)
            .map(|p| [p[0] / s, p[1] / s, p[2]]),
    );
    if scaled.len() < 2 * PARAMS {
        return None;
    }
    let mut t = start(scaled, w, abs)?;
    let mut current: &[Local] = scaled;
    let mut fitted = levenberg_marquardt(current, t)?;
    for _ in 0..2 {
        t = fitted.0;
        let model_at = |p: &Local| model(&t, p[0], p[1]).0;
        inliers(scaled, 4.0 * w.noise, model_at, abs, kept);
        current = kept;
        if current.len() < 2 * PARAMS {
            return None;
        }
        fitted = levenberg_marquardt(current, t)?;
    }
    let (t, rss, jtj) = fitted;
    let n = current.len();
    let var = rss / (n - PARAMS) as f64;
    // Pseudo-inverse: along a ridge longer than the window the centre is undetermined (a
    // null direction of JᵀJ that the peak barely depends on).
    let cov = jtj.pseudo_inverse(1e-12 * jtj.norm()).ok()? * var;
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
    // Principal widths from the precision LᵀL (scaled units).
    let l = Matrix2::new(t[6], t[7], 0.0, t[8]);
    let eig = (l.transpose() * l).symmetric_eigen();
    let (narrow, wide) = match eig.eigenvalues[0] >= eig.eigenvalues[1] {
        true => (0, 1),
        false => (1, 0),
    };
    let (big, small) = (eig.eigenvalues[narrow], eig.eigenvalues[wide]);
    let width = |lambda: f64| match lambda > 1e-12 {
        true => s / lambda.sqrt(),
        false => f64::INFINITY,
    };
    let c = nalgebra::Vector2::new(cu, cv) * s;
    let offset = match width(small) > s {
        true => c.dot(&eig.eigenvectors.column(narrow)).abs(),
        false => c.norm(),
    };
    let support = current
        .iter()
        .filter(|p| {
            let (du, dv) = (p[0] - cu, p[1] - cv);
            let (w1, w2) = (t[6] * du + t[7] * dv, t[8] * dv);
            w1 * w1 + w2 * w2 <= 2.0 * std::f64::consts::LN_10
        })
        .count();
    Some(PeakFit {
        peak,
        se,
        amplitude: t[3],
        centre: [cu * s, cv * s],
        offset,
        widths: [width(big), width(small)],
        sigma: var.sqrt(),
        n,
        trimmed: scaled.len() - n,
        support,
        params: t,
        cov,
        scale: s,
    })
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
        let mut sum = 0.0;
        for seed in 0..8 {
            let pts = planted(bump, seed);
            let w = window(0.22);
            let f = fit_peak(&pts, &w, &mut PeakScratch::default()).expect("converges");
            assert!(f.accepted(&w), "seed {seed}: {f:?}");
            assert!((f.peak - 0.3).abs() <= 0.1 * 0.3, "seed {seed}: {f:?}");
            assert!(
                (f.widths[0] - sigma).abs() < 0.2 * sigma,
                "seed {seed}: {f:?}"
            );
            sum += f.peak;
        }
        assert!((sum / 8.0 - 0.3).abs() <= 0.03 * 0.3, "mean {}", sum / 8.0);
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

//! The peak model's shapes and its solver: the defect term of an elliptic Gaussian or of a
//! capsule (a Gaussian cross-section around a segment) on a plane, their values and gradients
//! in the nine parameters, and Levenberg-Marquardt over them (nalgebra). [`super::peak_model`]
//! fits them to a window and guards the result.
use nalgebra::{Matrix2, SMatrix, SVector};

use super::quadric::Local;

pub(super) type Params = SVector<f64, 9>;
pub(super) type Normal = SMatrix<f64, 9, 9>;

/// Parameters of the model.
pub(super) const PARAMS: usize = 9;

/// Levenberg-Marquardt iterations before a fit counts as not converged. Fits that do
/// converge take about 16 on average; most of those that reach the cap are windows of noise
/// that never converge. Against 100: the same results on seeds 11-34 at 300k, and the
/// narrow-defect search (`densify.rs`) at 20k core points takes 35 ms instead of 68 ms.
const MAX_ITERATIONS: usize = 50;

/// Levenberg-Marquardt's damping μ (relative to JᵀJ's diagonal): it starts at this (close to
/// Gauss-Newton: the start is near the minimum).
const DAMPING_START: f64 = 1e-3;

/// μ is multiplied by this when the damped system is singular.
const DAMPING_SINGULAR: f64 = 10.0;

/// μ is divided by this after a step that lowers the RSS, down to [`DAMPING_FLOOR`].
const DAMPING_DOWN: f64 = 3.0;

/// Smallest μ, and smallest diagonal element of JᵀJ scaled (a parameter the data do not
/// touch still gets a damped step).
const DAMPING_FLOOR: f64 = 1e-12;

/// μ is multiplied by this after a step that does not lower the RSS.
const DAMPING_UP: f64 = 4.0;

/// Beyond this μ no step lowers the RSS: the fit is at a minimum.
const DAMPING_MAX: f64 = 1e10;

/// Converged when a step lowers the RSS, or moves the parameters, by at most this share.
const CONVERGED: f64 = 1e-10;

/// An eigenvalue of the precision below this (scaled units) is a null direction: an infinite
/// width (a ridge longer than the window).
const NULL_PRECISION: f64 = 1e-12;

/// A point supports the model where its defect term is at least this share of the amplitude.
pub(super) const SUPPORT_SHARE: f64 = 0.1;

/// The shape of the defect term.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Shape {
    /// A exp(-½ (x - c)ᵀ LᵀL (x - c)), L = [[t6, t7], [0, t8]]: an elliptic Gaussian.
    Ellipse,
    /// A exp(-½ k² d²), d the distance from x to the segment of half-length ℓ = t8² through
    /// the centre along (cos t6, sin t6), k = t7: a Gaussian cross-section with a flat top
    /// along its length (a ridge whose ends lie in the window; ℓ = 0 is a round bump).
    Capsule,
}

/// The model's value at scaled (u, v) and its gradient in the parameters.
pub(super) fn model(shape: Shape, t: &Params, u: f64, v: f64) -> (f64, Params) {
    match shape {
        Shape::Ellipse => ellipse(t, u, v),
        Shape::Capsule => capsule(t, u, v),
    }
}

/// [`Shape::Ellipse`]'s value and gradient.
fn ellipse(t: &Params, u: f64, v: f64) -> (f64, Params) {
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

/// [`Shape::Capsule`]'s value and gradient.
fn capsule(t: &Params, u: f64, v: f64) -> (f64, Params) {
    let (du, dv) = (u - t[4], v - t[5]);
    let (sin, cos) = t[6].sin_cos();
    let (k, half) = (t[7], t[8] * t[8]);
    // Position along the axis and across it; the nearest point of the segment.
    let (along, across) = (du * cos + dv * sin, -du * sin + dv * cos);
    let end = along.clamp(-half, half);
    let (qa, qc) = (along - end, across);
    let d2 = qa * qa + qc * qc;
    let g = (-0.5 * k * k * d2).exp();
    let ag = t[3] * g;
    let value = t[0] + t[1] * u + t[2] * v + ag;
    // d² = |x - c - end·e|²: ∂/∂c = -2q (q the offset from the segment), ∂/∂θ = -2 along·across
    // inside the segment and -2 end·qc at its caps (∂ along/∂θ = across), ∂/∂ℓ = -2 |qa| at
    // the caps.
    let (qu, qv) = (qa * cos - qc * sin, qa * sin + qc * cos);
    let inside = along.abs() < half;
    let dd_theta = if inside {
        -2.0 * along * across
    } else {
        -2.0 * end * qc
    };
    let dd_half = if inside { 0.0 } else { -2.0 * qa.abs() };
    let f = -0.5 * k * k * ag;
    let grad = Params::from([
        1.0,
        u,
        v,
        g,
        f * -2.0 * qu,
        f * -2.0 * qv,
        f * dd_theta,
        -k * d2 * ag,
        f * dd_half * 2.0 * t[8],
    ]);
    (value, grad)
}

/// Residual sum of squares, JᵀJ and Jᵀr over `pts` at `t`.
fn normal_equations(shape: Shape, pts: &[Local], t: &Params) -> (f64, Normal, Params) {
    let (mut rss, mut jtj, mut jtr) = (0.0, Normal::zeros(), Params::zeros());
    for p in pts {
        let (value, grad) = model(shape, t, p[0], p[1]);
        let r = p[2] - value;
        rss += r * r;
        jtj.ger(1.0, &grad, &grad, 1.0);
        jtr += grad * r;
    }
    (rss, jtj, jtr)
}

/// Levenberg-Marquardt from `t`: the parameters, the RSS and JᵀJ at the minimum; None when it
/// does not converge within [`MAX_ITERATIONS`].
pub(super) fn levenberg_marquardt(
    shape: Shape,
    pts: &[Local],
    mut t: Params,
) -> Option<(Params, f64, Normal)> {
    let (mut rss, mut jtj, mut jtr) = normal_equations(shape, pts, &t);
    let mut mu = DAMPING_START;
    for _ in 0..MAX_ITERATIONS {
        let mut damped = jtj;
        for i in 0..PARAMS {
            damped[(i, i)] += mu * jtj[(i, i)].max(DAMPING_FLOOR);
        }
        let Some(step) = damped.cholesky().map(|c| c.solve(&jtr)) else {
            mu *= DAMPING_SINGULAR;
            continue;
        };
        let next = t + step;
        let (rss_next, jtj_next, jtr_next) = normal_equations(shape, pts, &next);
        if rss_next < rss {
            let done = rss - rss_next <= CONVERGED * rss || step.norm() <= CONVERGED * t.norm();
            (t, rss, jtj, jtr) = (next, rss_next, jtj_next, jtr_next);
            mu = (mu / DAMPING_DOWN).max(DAMPING_FLOOR);
            if done {
                return Some((t, rss, jtj));
            }
        } else {
            mu *= DAMPING_UP;
            // No step lowers the RSS: a minimum.
            if mu > DAMPING_MAX {
                return Some((t, rss, jtj));
            }
        }
    }
    None
}

/// An ellipse's narrow axis (unit, scaled frame) and its principal standard deviations
/// (narrow, wide; scaled units, infinite along a null direction of the precision).
pub(super) fn principal(t: &Params) -> (nalgebra::Vector2<f64>, [f64; 2]) {
    let l = Matrix2::new(t[6], t[7], 0.0, t[8]);
    let eig = (l.transpose() * l).symmetric_eigen();
    let (narrow, wide) = match eig.eigenvalues[0] >= eig.eigenvalues[1] {
        true => (0, 1),
        false => (1, 0),
    };
    let width = |lambda: f64| match lambda > NULL_PRECISION {
        true => 1.0 / lambda.sqrt(),
        false => f64::INFINITY,
    };
    (
        eig.eigenvectors.column(narrow).into_owned(),
        [width(eig.eigenvalues[narrow]), width(eig.eigenvalues[wide])],
    )
}

/// Points of `pts` where the defect term is at least 10 % of A.
pub(super) fn support(shape: Shape, t: &Params, pts: &[Local]) -> usize {
    pts.iter()
        .filter(|p| {
            let (value, _) = model(shape, t, p[0], p[1]);
            let plane = t[0] + t[1] * p[0] + t[2] * p[1];
            (value - plane) / t[3] >= SUPPORT_SHARE
        })
        .count()
}

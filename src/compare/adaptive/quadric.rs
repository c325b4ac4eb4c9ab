//! Least-squares height fields t(u, v) over a cylinder's points, in the core point's tangent
//! frame: a full quadric (6 terms) when there are at least 10 points and they pin its value at
//! the axis ([`MAX_LEVERAGE`]), else a plane (3) from 4, a constant below. The value at the
//! axis, t(0, 0), is where the surface crosses the normal line through the core point; its
//! standard error comes from the fit's residuals.
use nalgebra::{Matrix6, Vector6};

/// Residuals beyond this many noise SDs (or 3 robust SDs when more) are trimmed by a fit:
/// outliers, and the other side of a thin wall.
pub(super) const TRIM_NOISE: f64 = 4.0;

/// A point in the tangent frame: (u, v) across the axis, t along it (mm).
pub type Local = [f64; 3];

/// What a fit says about the surface at the axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisFit {
    /// t(0, 0), mm.
    pub t0: f64,
    /// Standard error of t0, mm (NaN with no residual degrees of freedom).
    pub se: f64,
    /// Residual standard deviation, mm.
    pub sigma: f64,
    /// Points used.
    pub n: usize,
    /// Residual degrees of freedom: points used minus the model's terms.
    pub dof: usize,
}

/// Two-sided 95 % quantile of Student's t distribution with `dof` degrees of freedom
/// (`scipy.stats.t.ppf(0.975, dof)`): exact to 8 digits up to 30, then the Cornish–Fisher
/// expansion around the normal quantile (within 1e-4). NaN for 0: no residual estimates the
/// scatter (like py4dgeo's NaN LoD of a one-point cylinder), so the LoD is NaN and the point
/// not significant.
pub fn student_t95(dof: usize) -> f64 {
    #[rustfmt::skip]
    const TABLE: [f64; 30] = [
        12.70620474, 4.30265273, 3.18244631, 2.77644511, 2.57058184, 2.44691185, 2.36462425,
        2.30600414, 2.26215716, 2.22813885, 2.20098516, 2.17881283, 2.16036866, 2.14478669,
        2.13144955, 2.11990530, 2.10981558, 2.10092204, 2.09302405, 2.08596345, 2.07961384,
        2.07387307, 2.06865761, 2.06389856, 2.05953855, 2.05552944, 2.05183052, 2.04840714,
        2.04522964, 2.04227246,
    ];
    match dof {
        0 => f64::NAN,
        1..=30 => TABLE[dof - 1],
        _ => {
            let (z, v) = (1.959963984540054f64, dof as f64);
            let g1 = (z.powi(3) + z) / 4.0;
            let g2 = (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / 96.0;
            let g3 = (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z) / 384.0;
            z + g1 / v + g2 / (v * v) + g3 / (v * v * v)
        }
    }
}

/// Largest leverage of the axis in a quadric fit (t(0, 0)'s variance in units of the residual
/// variance, (XᵀX)⁻¹₀₀); beyond it the fit is a plane. Ten to twenty points whose spread
/// leaves the quadric's six terms poorly pinned at the axis (a strip beside it, a ring)
/// extrapolate: 1 = no better than a single point, where a plane through 12 points spread
/// over a disc has about 0.1. On the 300k synth cases (seeds 11-34) this raised IoU from
/// 0.903 to 0.914 on average at the same RMS (docs/ACCURACY.md, step 5).
const MAX_LEVERAGE: f64 = 1.0;

/// A quadric (6 terms) needs at least this many points: 4 residual degrees of freedom to
/// estimate the scatter from.
pub(super) const QUADRIC_MIN_POINTS: usize = 10;

/// A plane (3 terms) needs at least this many points (one residual degree of freedom).
const PLANE_MIN_POINTS: usize = 4;

/// σ = 1.4826 × MAD for Gaussian noise (1 / Φ⁻¹(3/4)).
pub(super) const MAD_TO_SD: f64 = 1.4826;

/// Residuals beyond this many robust SDs are trimmed (when more than the noise bound).
const ROBUST_SDS: f64 = 3.0;

/// Terms of the height field a fit through `count` points uses.
fn terms(count: usize) -> usize {
    if count >= QUADRIC_MIN_POINTS {
        6
    } else if count >= PLANE_MIN_POINTS {
        3
    } else {
        1
    }
}

/// The quadric's monomials at a point whose (u, v) are in units of the cylinder radius.
fn basis(p: &Local) -> Vector6<f64> {
    let (u, v) = (p[0], p[1]);
    Vector6::new(1.0, u, v, u * u, u * v, v * v)
}

/// The normal equations over `pts` (scaled) with the first `K` terms (upper triangle and
/// right-hand side; `K` known at compile time, so the loops unroll).
fn normal_equations<const K: usize>(pts: &[Local]) -> (Matrix6<f64>, Vector6<f64>) {
    let mut a = Matrix6::<f64>::zeros();
    let mut b = Vector6::<f64>::zeros();
    for p in pts {
        let x = basis(p);
        for i in 0..K {
            for j in i..K {
                a[(i, j)] += x[i] * x[j];
            }
            b[i] += x[i] * p[2];
        }
    }
    (a, b)
}

/// Solves the normal equations over `pts` (scaled) with `k` terms (1, 3 or 6); None when
/// singular.
fn solve(pts: &[Local], k: usize) -> Option<(Vector6<f64>, f64)> {
    let (mut a, b) = match k {
        6 => normal_equations::<6>(pts),
        3 => normal_equations::<3>(pts),
        _ => normal_equations::<1>(pts),
    };
    // The lower triangle mirrors the upper (the same products, summed in the same order).
    for i in 0..k {
        for j in 0..i {
            a[(i, j)] = a[(j, i)];
        }
    }
    for i in k..6 {
        a[(i, i)] = 1.0;
    }
    let chol = a.cholesky()?;
    let coef = chol.solve(&b);
    let inv00 = chol.solve(&Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0))[0];
    Some((coef, inv00))
}

fn residual(p: &Local, coef: &Vector6<f64>) -> f64 {
    p[2] - basis(p).dot(coef)
}

/// Reusable buffers of [`fit`].
#[derive(Default)]
pub struct FitScratch {
    abs: Vec<f64>,
    scaled: Vec<Local>,
    kept: Vec<Local>,
    refit: Vec<Local>,
}

/// The points of `pts` whose residual from `model` is within
/// `max(trim, 3 × 1.4826 × median |residual|)`, into `out` (`abs`: scratch).
pub(super) fn inliers(
    pts: &[Local],
    trim: f64,
    model: impl Fn(&Local) -> f64,
    abs: &mut Vec<f64>,
    out: &mut Vec<Local>,
) {
    // |residual| per point, then a copy that the median search reorders.
    let n = pts.len();
    abs.clear();
    abs.extend(pts.iter().map(|p| (p[2] - model(p)).abs()));
    abs.extend_from_within(..n);
    let (residuals, order) = abs.split_at_mut(n);
    let mad = *order.select_nth_unstable_by(n / 2, f64::total_cmp).1;
    let limit = trim.max(ROBUST_SDS * MAD_TO_SD * mad);
    out.clear();
    out.extend(
        pts.iter()
            .zip(residuals.iter())
            .filter(|(_, r)| **r <= limit)
            .map(|(p, _)| *p),
    );
}

/// Fits `pts` (at least one); `scale` (the cylinder radius) conditions the system. Robustly:
/// points far from the median value are dropped first (outlier clusters), then points far
/// from the first fit, each time beyond `max(trim, 3 × 1.4826 × median |residual|)`.
/// The residual variance used for the standard error is at least `floor²` (the scan noise:
/// a fit through few points must not claim more precision than the scanner has).
pub fn fit(
    pts: &[Local],
    scale: f64,
    trim: f64,
    floor: f64,
    scratch: &mut FitScratch,
) -> Option<AxisFit> {
    if pts.is_empty() {
        return None;
    }
    let FitScratch {
        abs,
        scaled,
        kept,
        refit,
    } = scratch;
    // (u, v) in units of `scale` once: the monomials stay near 1 (a well-conditioned system).
    scaled.clear();
    scaled.extend(pts.iter().map(|p| [p[0] / scale, p[1] / scale, p[2]]));
    abs.clear();
    abs.extend(pts.iter().map(|p| p[2]));
    let mid = abs.len() / 2;
    let median = *abs.select_nth_unstable_by(mid, f64::total_cmp).1;
    inliers(scaled, trim, |_| median, abs, kept);
    let first = fit_once(kept, floor)?;
    inliers(kept, trim, |p| p[2] - residual(p, &first.0), abs, refit);
    Some(fit_once(refit, floor)?.2)
}

/// One least-squares fit over `pts` (scaled).
fn fit_once(pts: &[Local], floor: f64) -> Option<(Vector6<f64>, f64, AxisFit)> {
    if pts.is_empty() {
        return None;
    }
    let mut k = terms(pts.len());
    let (coef, inv00) = loop {
        match solve(pts, k) {
            Some((c, h)) if k < 6 || h <= MAX_LEVERAGE => break (c, h),
            _ if k == 6 => k = 3,
            _ if k == 3 => k = 1,
            _ => return None,
        }
    };
    let rss: f64 = pts.iter().map(|p| residual(p, &coef).powi(2)).sum();
    let dof = pts.len() as f64 - k as f64;
    let var = rss / dof;
    let sigma = var.sqrt();
    Some((
        coef,
        sigma,
        AxisFit {
            t0: coef[0],
            se: (var.max(floor * floor) * inv00).sqrt(),
            sigma,
            n: pts.len(),
            dof: pts.len() - k,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_quadric_at_the_axis() {
        let pts: Vec<Local> = (0..40)
            .map(|i| {
                let (u, v) = ((i % 7) as f64 * 0.1 - 0.3, (i / 7) as f64 * 0.1 - 0.25);
                [
                    u,
                    v,
                    0.2 + 0.1 * u - 0.3 * v + 2.0 * u * u - u * v + 0.5 * v * v,
                ]
            })
            .collect();
        let f = fit(&pts, 0.4, 0.01, 0.0, &mut FitScratch::default()).unwrap();
        assert!((f.t0 - 0.2).abs() < 1e-12, "{f:?}");
        assert!(f.sigma < 1e-12);
        // Few points: a plane, then a constant.
        let f = fit(&pts[..5], 0.4, 0.01, 0.0, &mut FitScratch::default()).unwrap();
        assert_eq!(f.n, 5);
        let f = fit(&pts[..2], 0.4, 0.01, 0.0, &mut FitScratch::default()).unwrap();
        assert!((f.t0 - (pts[0][2] + pts[1][2]) / 2.0).abs() < 1e-12);
        assert_eq!(f.dof, 1);
    }

    #[test]
    fn student_quantiles_match_scipy() {
        // scipy.stats.t.ppf(0.975, dof), scipy 1.17.1.
        for (dof, want) in [
            (1, 12.70620474),
            (7, 2.36462425),
            (30, 2.04227246),
            (31, 2.03951345),
            (40, 2.02107539),
            (60, 2.00029782),
            (100, 1.98397152),
            (1000, 1.96233908),
        ] {
            let got = student_t95(dof);
            assert!((got - want).abs() < 1e-4, "dof {dof}: {got} against {want}");
        }
        assert!(student_t95(0).is_nan());
    }
}

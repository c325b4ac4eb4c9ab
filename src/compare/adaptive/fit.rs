//! Step 3, fit: the distance at a core point. Its cylinder is gathered and its RWME radius
//! chosen ([`super::radius`]); the point pairs within it are fitted by a quadric height field
//! in the tangent frame ([`super::quadric`]), whose value at the axis is where the scan
//! crosses the normal line. The radius then grows further while the quadric still describes
//! the surface (residual SD within `max_misfit` × noise) and every fit's interval
//! t0 ± gamma·se so far intersects (intersection of confidence intervals, ICI). The LoD is
//! Student's t at the fit's residual degrees of freedom times its standard error, plus the
//! registration term.
use nalgebra::{Point3, Vector3};

use super::context::Context;
use super::quadric::{fit, student_t95, AxisFit, QUADRIC_MIN_POINTS, TRIM_NOISE};
use super::radius::{gather, rwme_radius, Ring, Scratch};
use crate::compare::config::CompareConfig;
use crate::compare::cover::Support;
use crate::compare::deviation::{Deviation, Reason, Z95};

/// Fewest scan points a fit may keep after trimming before the radius grows: as many as a
/// quadric needs. With 6 (a plane through a handful of points) isolated core points where
/// the smallest cylinder held 6-9 scan points beside a sharp edge of femoral_dm read
/// -0.066 to -0.078 mm on a true 0 with a LoD of 0.016-0.027 (false detections, issue 53:
/// seeds 17 and 41, one and two setups); the next radius holds enough points.
const FIT_MIN: usize = QUADRIC_MIN_POINTS;

/// The adaptive result at core point `p` with outward unit normal `n`.
#[inline]
pub(super) fn at(
    prep: &Context,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
    scratch: &mut Scratch,
) -> Deviation {
    at_supported(prep, p, n, cfg, scratch).0
}

/// [`at`], and what its fit stood on (all zero without a fit).
pub(super) fn at_supported(
    prep: &Context,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
    scratch: &mut Scratch,
) -> (Deviation, Support) {
    gather(prep, p, n, scratch);
    let radius = match rwme_radius(prep, scratch, cfg) {
        Ok(radius) => radius,
        Err(missing) => return (missing, Support::default()),
    };
    let radii = &prep.radii[..radius.usable];
    let Scratch {
        rings,
        pairs,
        within,
        fit: fit_scratch,
        ..
    } = scratch;
    let min = cfg.min_points.max(1);
    let mut fit_at = |k: usize| {
        fit(
            &pairs[..within[k]],
            radii[k],
            TRIM_NOISE * prep.noise,
            prep.noise,
            fit_scratch,
        )
    };
    // The fit must keep at least FIT_MIN points after trimming, else the next radius.
    let mut k = radius.k;
    let (r, n_ref, fs) = loop {
        let r = radii[k];
        let (n_ref, n_scan) = (rings[k].count, within[k]);
        let last = k + 1 == radii.len();
        let missing = |reason| {
            (
                Deviation::missing(reason, r, n_ref, n_scan),
                Support::default(),
            )
        };
        if n_ref < min {
            return missing(Reason::FewReference);
        }
        if n_scan < min {
            return missing(Reason::FewScan);
        }
        match fit_at(k) {
            Some(fs) if fs.n >= FIT_MIN || last => break (r, n_ref, fs),
            _ if last => return missing(Reason::FewScan),
            _ => k += 1,
        }
    };
    let grown = Grown { k, r, n_ref, fs };
    let Grown { k, r, n_ref, fs } = grow(prep, cfg, grown, radii, rings, &mut fit_at);
    // Beside a border (a candidate disc the scan does not fill) the fit must stand on enough
    // of its disc's scan points (`cover.rs`); else the scan's border, not a distance.
    let support = Support { kept: fs.n, n_ref };
    if radius.usable < prep.radii.len() && !support.enough(prep.scan_per_reference) {
        return (
            Deviation::missing(Reason::ScanBorder, r, n_ref, within[k]),
            support,
        );
    }
    // The fit's standard error comes from its own residuals: Student's t at their degrees of
    // freedom (a handful of points on a narrow face estimate their scatter poorly).
    let lod = student_t95(fs.dof) * fs.se + Z95 * cfg.registration_error;
    let value = Deviation {
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
    };
    (value.finish(n), support)
}

/// A fit and the radius (index and value) and reference count it was made at.
struct Grown {
    k: usize,
    r: f64,
    n_ref: usize,
    fs: AxisFit,
}

/// The fit `first` grown through the larger of `radii` while the
/// quadric describes the surface (residual SD within `max_misfit` × noise) and every fit's
/// interval t0 ± gamma·se so far intersects (ICI; `gamma` 0: no growth). `rings`: the
/// reference points within each radius.
fn grow(
    prep: &Context,
    cfg: &CompareConfig,
    first: Grown,
    radii: &[f64],
    rings: &[Ring],
    fit_at: &mut impl FnMut(usize) -> Option<AxisFit>,
) -> Grown {
    let a = &cfg.adaptive;
    let gamma = a.gamma;
    let mut best = first;
    let (mut lo, mut hi) = (
        best.fs.t0 - gamma * best.fs.se,
        best.fs.t0 + gamma * best.fs.se,
    );
    // Not `gamma <= 0.0`: a NaN gamma, like 0, grows nothing.
    let growing = gamma > 0.0;
    for j in (best.k + 1..radii.len()).filter(|_| growing) {
        let Some(next) = fit_at(j).filter(|f| f.sigma <= a.max_misfit * prep.noise) else {
            break;
        };
        lo = lo.max(next.t0 - gamma * next.se);
        hi = hi.min(next.t0 + gamma * next.se);
        if lo > hi {
            break;
        }
        best = Grown {
            k: j,
            r: radii[j],
            n_ref: rings[j].count,
            fs: next,
        };
    }
    best
}

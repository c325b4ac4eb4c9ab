//! A peak model in its window: the scan points around a defect's top gathered in a tangent
//! frame (heights = point-pair distances), the model fitted to them ([`super::peak_model`]),
//! and the result a model gives at a core point. Shared by the peak fit, densification and
//! the model fill.
use nalgebra::{Point3, Vector3};

use super::context::{tangent_frame, Context};
use super::peak_model::{fit_peak, PeakFit, PeakScratch, PeakWindow};
use super::quadric::{student_t95, Local};
use crate::compare::config::CompareConfig;
use crate::compare::deviation::{Deviation, Reason, Z95};

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
    pub(super) fn new(origin: Point3<f64>, normal: Vector3<f64>, fit: PeakFit) -> Model {
        let axes = tangent_frame(&normal);
        Model {
            origin,
            normal,
            axes,
            fit,
        }
    }

    /// (u, v) of `x` in the model's tangent frame and its offset along the normal.
    pub(super) fn local(&self, x: &Point3<f64>) -> (f64, f64, f64) {
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
    pub(super) knn: Vec<(f64, u32)>,
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
    prep: &Context,
    origin: &Point3<f64>,
    normal: &Vector3<f64>,
    radius: f64,
    scratch: &mut ModelScratch,
) -> usize {
    let (e1, e2) = tangent_frame(normal);
    scratch.radius = radius;
    let window = &mut scratch.window;
    window.clear();
    prep.scan_pairs(origin, normal, radius, &mut scratch.knn, |_, d, pair| {
        window.push([d.dot(&e1), d.dot(&e2), pair]);
    });
    window.len()
}

/// The peak model (`peakfit.rs`) fitted to the window last gathered into `scratch`
/// ([`gather_window`]), started from the height `start`, with the window's expectations for
/// the caller's guard; None when the fit does not converge.
pub(super) fn fit_window(
    prep: &Context,
    start: f64,
    cfg: &CompareConfig,
    scratch: &mut ModelScratch,
) -> Option<(PeakFit, PeakWindow)> {
    let w = PeakWindow {
        radius: scratch.radius,
        noise: prep.model_noise,
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
        uncertainty: student_t95(fit.dof()) * se + Z95 * cfg.registration_error,
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

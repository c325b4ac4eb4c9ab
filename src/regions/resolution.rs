//! Coverage that means resolution: a core point counts toward the verdict only where the
//! comparison could have seen the smallest repairable defect there (docs/ALGORITHMS.md,
//! "Coverage and resolution"). A core point is *resolved* when
//! 1. it got a distance;
//! 2. its cylinder radius is at most [`MAX_RESOLVING_RADIUS_MM`] (a wider cylinder averages a
//!    defect of [`SMALLEST_DEFECT_MM`] away with the surface around it: a sparse scan makes
//!    the adaptive radius grow);
//! 3. its level of detection (LoD95) is at most the tolerance (a larger LoD cannot tell a
//!    defect at the tolerance from noise: a large `--registration-error` does this).
//!
//! A resolved core point vouches for at most [`MAX_SHARE_MM2`] of area (a disc of the
//! smallest defect's width): between sparser core points (a `--core` file of a few points) a
//! defect is unseen. The coverage is the resolved area over the area to inspect.
use serde::{Deserialize, Serialize};

use crate::compare::Deviations;

/// Width (FWHM) of the smallest defect the verdict must be able to see, mm: the demo's and
/// the closed loop's planted defects are 2-4 mm wide (synth's default range reaches 0.4 mm,
/// which the compliant 6 mm ball cannot grind on its own: its contact patch at the 2 mm
/// preload is about 7 mm across).
pub const SMALLEST_DEFECT_MM: f64 = 2.0;

/// Largest cylinder radius that resolves a defect of [`SMALLEST_DEFECT_MM`], mm: twice its
/// width. At full density the adaptive radii are 0.6-2.9 mm (femoral_dm synth case, 150k
/// scan points: 1.78 mm at the median and the 95th percentile); the 3,000-point (1 %) scan
/// of issue 52 used 12.8 mm cylinders, which flatten a 2 mm bump below any tolerance.
pub const MAX_RESOLVING_RADIUS_MM: f64 = 2.0 * SMALLEST_DEFECT_MM;

/// Most area one core point vouches for, mm²: a disc as wide as the smallest defect
/// (π × 1 mm²). The default core points (a sample of the reference about 0.5 mm apart) own
/// about 0.25 mm² each; a `--core` file of 10 points on the femoral part owns ~1,500 mm² each.
pub const MAX_SHARE_MM2: f64 = std::f64::consts::PI * SMALLEST_DEFECT_MM * SMALLEST_DEFECT_MM / 4.0;

/// Where the area to inspect is not resolved, each a share of that area (0..1).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Shortfall {
    /// No distance (a hole, the scan's border, too few points).
    pub unmeasured: f64,
    /// Measured with a cylinder wider than [`MAX_RESOLVING_RADIUS_MM`] (the scan too sparse).
    pub wide_cylinder: f64,
    /// Measured with a LoD95 above the tolerance (noise or registration error too large).
    pub lod_above_tolerance: f64,
    /// Area beyond [`MAX_SHARE_MM2`] per core point (the core points too sparse).
    pub sparse_core: f64,
}

impl Shortfall {
    /// The reasons in words, largest first (the unmeasured share always, the others when
    /// above 0.05 % of the area).
    pub fn describe(&self) -> String {
        let mut parts = [
            (self.unmeasured, "not measured".to_string()),
            (
                self.wide_cylinder,
                format!("measured with cylinders wider than {MAX_RESOLVING_RADIUS_MM} mm (a sparse scan)"),
            ),
            (
                self.lod_above_tolerance,
                "with a level of detection above the tolerance".to_string(),
            ),
            (
                self.sparse_core,
                format!("between core points more than {MAX_SHARE_MM2:.3} mm² apart each (too few core points)"),
            ),
        ];
        parts.sort_by(|a, b| b.0.total_cmp(&a.0));
        let words: Vec<String> = parts
            .iter()
            .filter(|(s, w)| *s >= 5e-4 || w == "not measured")
            .map(|(s, w)| format!("{:.1} % {w}", 100.0 * s))
            .collect();
        words.join(", ")
    }
}

/// The resolved share of the area to inspect (`in_area`; None: all; `share`: each core
/// point's area) at `tolerance`, and where the rest went; coverage 0 when the area is empty.
pub fn coverage(
    dev: &Deviations,
    share: &[f64],
    in_area: Option<&[bool]>,
    tolerance: f64,
) -> (f64, Shortfall) {
    let inside = |i: &usize| in_area.is_none_or(|a| a[*i]);
    let (mut total, mut seen) = (0.0, 0.0);
    let mut short = Shortfall::default();
    for i in (0..dev.values.len()).filter(inside) {
        let (v, a) = (&dev.values[i], share[i]);
        total += a;
        let vouched = a.min(MAX_SHARE_MM2);
        if !v.distance.is_finite() {
            short.unmeasured += a;
        } else if v.radius.is_nan() || v.radius > MAX_RESOLVING_RADIUS_MM {
            short.wide_cylinder += a;
        } else if v.uncertainty.is_nan() || v.uncertainty > tolerance {
            short.lod_above_tolerance += a;
        } else {
            seen += vouched;
            short.sparse_core += a - vouched;
        }
    }
    if total <= 0.0 {
        return (0.0, short);
    }
    for s in [
        &mut short.unmeasured,
        &mut short.wide_cylinder,
        &mut short.lod_above_tolerance,
        &mut short.sparse_core,
    ] {
        *s /= total;
    }
    (seen / total, short)
}

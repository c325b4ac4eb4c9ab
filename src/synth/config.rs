//! The synthetic case's settings ([`SynthConfig`], `[synth]`) with their ranges, and the
//! filter that decides where defects may sit.
use std::path::PathBuf;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::femoral::FemoralShape;
use super::limits::{outside, range_outside, MAX_POINTS};
use super::turntable::TurntableConfig;
use crate::cloud::Units;

/// Settings of a synthetic case. Every field has a documented default.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SynthConfig {
    /// Seed of every random choice (default 1).
    pub seed: u64,
    /// A mesh to use instead of the parametric part (default none).
    pub mesh: Option<PathBuf>,
    /// The articular surface of `mesh` on which defects are planted (default: the whole mesh
    /// away from sharp edges).
    pub surface: Option<PathBuf>,
    /// Unit of `mesh` and `surface` (default: refuse files that look like metres).
    pub units: Option<Units>,
    /// Shape of the parametric part.
    pub shape: FemoralShape,
    /// Points in reference.ply (default 400,000).
    pub reference_points: usize,
    /// Surface points in scan.ply before outliers (default 300,000).
    pub scan_points: usize,
    /// Number of defects (default 6).
    pub defects: usize,
    /// Range of |height| of defects, mm (default 0.04..0.5).
    pub height_range: [f64; 2],
    /// Range of widths (FWHM) of defects, mm (default 0.4..3).
    pub width_range: [f64; 2],
    /// Share of pits among defects (default 0.25); the rest are bumps and ridges.
    pub pit_share: f64,
    /// Share of ridges among defects (default 0.25).
    pub ridge_share: f64,
    /// Standard deviation of Gaussian noise on each scan coordinate, mm (default 0.015).
    pub noise: f64,
    /// Outliers as a share of scan points, half scattered and half clustered (default 0.01).
    pub outliers: f64,
    /// Largest translation of the random scan pose, mm (default 60).
    pub max_translation: f64,
    /// Also make turntable range views of the defective part (default none).
    pub turntable: Option<TurntableConfig>,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            seed: 1,
            mesh: None,
            surface: None,
            units: None,
            shape: FemoralShape::default(),
            reference_points: 400_000,
            scan_points: 300_000,
            defects: 6,
            height_range: [0.04, 0.5],
            width_range: [0.4, 3.0],
            pit_share: 0.25,
            ridge_share: 0.25,
            noise: 0.015,
            outliers: 0.01,
            max_translation: 60.0,
            turntable: None,
        }
    }
}

/// Most defects planted (placement tries each against all others).
pub const MAX_DEFECTS: usize = 500;

impl SynthConfig {
    /// Checks every setting against its range and unit before anything is made; the message
    /// names the key in backticks.
    pub fn check(&self) -> std::result::Result<(), String> {
        let n = |v: usize| v as f64;
        let (s, mm, share) = (&self.shape, "mm", "(share)");
        let shape = MAX_SHAPE_MM;
        let table = [
            (
                "reference_points",
                n(self.reference_points),
                1.0,
                n(MAX_POINTS),
                "points",
            ),
            (
                "scan_points",
                n(self.scan_points),
                1.0,
                n(MAX_POINTS),
                "points",
            ),
            ("defects", n(self.defects), 0.0, n(MAX_DEFECTS), "defects"),
            (
                "pit_share",
                self.pit_share,
                0.0,
                1.0 - self.ridge_share,
                share,
            ),
            ("ridge_share", self.ridge_share, 0.0, 1.0, share),
            ("noise", self.noise, 0.0, MAX_NOISE_MM, mm),
            ("outliers", self.outliers, 0.0, MAX_OUTLIER_SHARE, share),
            (
                "max_translation",
                self.max_translation,
                0.0,
                MAX_TRANSLATION_MM,
                mm,
            ),
            ("width", s.width, 1.0, shape, mm),
            ("thickness", s.thickness, 0.1, shape, mm),
            ("notch_half_width", s.notch_half_width, 0.0, shape, mm),
            ("groove_depth", s.groove_depth, 0.0, shape, mm),
            ("groove_sigma", s.groove_sigma, 0.1, shape, mm),
            ("edge_drop", s.edge_drop, 0.0, shape, mm),
            ("edge_band", s.edge_band, 0.1, shape, mm),
            (
                "profile_samples",
                n(s.profile_samples),
                10.0,
                1e5,
                "samples",
            ),
            ("x_step", s.x_step, 0.01, shape, mm),
        ];
        let ranges = [
            ("height_range", self.height_range, 0.0, MAX_DEFECT_HEIGHT_MM),
            (
                "width_range",
                self.width_range,
                MIN_DEFECT_WIDTH_MM,
                MAX_DEFECT_WIDTH_MM,
            ),
        ];
        let pairs = ranges
            .iter()
            .map(|&(key, v, lo, hi)| range_outside(key, v, lo, hi, mm));
        if let Some(m) = table
            .iter()
            .map(|&(key, v, lo, hi, unit)| outside(key, v, lo, hi, unit))
            .chain(pairs)
            .find_map(|m| m)
        {
            return Err(m);
        }
        match &self.turntable {
            Some(t) => t.check(),
            None => Ok(()),
        }
    }
}

/// Tallest planted defect, mm (a defect of a polished part, not a second part).
const MAX_DEFECT_HEIGHT_MM: f64 = 10.0;
/// Narrowest and widest planted defect (FWHM), mm.
const MIN_DEFECT_WIDTH_MM: f64 = 0.05;
/// Widest planted defect (FWHM), mm.
const MAX_DEFECT_WIDTH_MM: f64 = 100.0;
/// Largest scan noise, mm.
const MAX_NOISE_MM: f64 = 5.0;
/// Outlier share of the scan: below one half (the filter needs a majority of surface).
const MAX_OUTLIER_SHARE: f64 = 0.49;
/// Largest translation of the scan's pose, mm.
const MAX_TRANSLATION_MM: f64 = 10_000.0;
/// Largest dimension of the parametric part's shape settings, mm.
const MAX_SHAPE_MM: f64 = 1000.0;

/// Decides whether a defect may sit at a site, e.g. only where the arm can reach: given the
/// site's probes (reference frame, mm), its centre first and then points on the surface
/// around its footprint, each with the surface's own outward normal there.
pub type SiteFilter = dyn Fn(&[SiteProbe]) -> bool + Sync;

/// A point of a candidate defect site (reference frame, mm) with the surface's outward unit
/// normal there.
pub type SiteProbe = (Point3<f64>, Vector3<f64>);

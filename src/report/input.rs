//! What the report is made from ([`ReportInput`], [`RegionMark`], [`Table`]), its settings
//! ([`ReportConfig`]) and what it writes ([`Figure`], [`ReportFiles`]).
use std::path::PathBuf;

use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::provenance;

/// A table for the report.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// Heading above the table.
    pub title: String,
    /// Column names.
    pub header: Vec<String>,
    /// Rows of cells.
    pub rows: Vec<Vec<String>>,
}

/// Settings of the figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReportConfig {
    /// Width of one view panel in pixels (default 520).
    pub panel_px: u32,
    /// Colour range as a multiple of the tolerance when no deviation exceeds it (default 4).
    pub min_range_tolerances: f64,
    /// Histogram bins (default 80).
    pub bins: usize,
}

impl Default for ReportConfig {
    fn default() -> Self {
        ReportConfig {
            panel_px: 520,
            min_range_tolerances: 4.0,
            bins: 80,
        }
    }
}

/// What the report shows. Distances are signed along the outward normal (+ = material in
/// excess); NaN where no distance could be computed.
#[derive(Debug, Clone)]
pub struct ReportInput<'a> {
    /// Page title.
    pub title: String,
    /// Core points (reference frame, mm).
    pub points: &'a [Point3<f64>],
    /// Outward unit normals at the core points.
    pub normals: &'a [Vector3<f64>],
    /// Signed deviation per core point (mm).
    pub distances: &'a [f64],
    /// Uncertainty (LoD95) per core point (mm), read out by the viewer; empty: unknown.
    pub uncertainties: &'a [f64],
    /// Tolerance (mm), marked on the colour bar and histogram.
    pub tolerance: f64,
    /// Key-value lines shown first (verdict, registration summary, ...).
    pub summary: Vec<(String, String)>,
    /// Tables shown after the figures (regions, ...).
    pub tables: Vec<Table>,
    /// Region id per core point (-1: none); empty when there are no regions.
    pub labels: &'a [i64],
    /// The defect regions (ids index `labels`): each gets a close-up and a number on the
    /// overview.
    pub regions: Vec<RegionMark>,
    /// Where the result came from (files, settings, version), shown as its own section.
    pub provenance: Option<&'a provenance::Provenance>,
    /// With an incomplete verdict: the picture of the unmeasured area and what to scan next.
    pub unmeasured: Option<Unmeasured<'a>>,
}

/// The unmeasured area's figure: which core points are in the area to inspect, and the
/// suggested views as its caption.
#[derive(Debug, Clone)]
pub struct Unmeasured<'a> {
    /// Per core point whether it is in the area to inspect (None: all are).
    pub in_area: Option<&'a [bool]>,
    /// The suggested setup and table angles, in words.
    pub suggestion: String,
}

/// A defect region as the figures show it.
#[derive(Debug, Clone)]
pub struct RegionMark {
    /// Region id (the value of its points in [`ReportInput::labels`]).
    pub id: usize,
    /// Mean position of its points, mm (the viewer's label).
    pub centroid: [f64; 3],
    /// Mean outward normal (the close-up looks against it).
    pub normal: Vector3<f64>,
    /// The region's peak distance, mm (regions.json `peak`; NaN: not known, the close-up then
    /// labels its largest member distance).
    pub peak: f64,
    /// One line under its close-up (kind, peak, area...).
    pub caption: String,
}

/// A figure of the page: its file, caption and the region ids labelled on it.
#[derive(Debug, Clone)]
pub struct Figure {
    /// The PNG.
    pub path: PathBuf,
    /// The caption under it.
    pub caption: String,
    /// Region ids numbered or shown on it.
    pub regions: Vec<usize>,
}

/// Files the report wrote.
#[derive(Debug, Clone)]
pub struct ReportFiles {
    /// The page.
    pub html: PathBuf,
    /// The figures: overview, histogram, then one close-up per region.
    pub figures: Vec<PathBuf>,
    /// The page's text as written (a later link is added to it in memory, not read back).
    pub page: String,
}

/// Symmetric colour range: the 99.5th percentile of |distance|, at least
/// `min_range_tolerances` tolerances.
pub fn colour_range(distances: &[f64], tolerance: f64, cfg: &ReportConfig) -> f64 {
    let mut abs: Vec<f64> = distances
        .iter()
        .filter(|d| d.is_finite())
        .map(|d| d.abs())
        .collect();
    abs.sort_by(f64::total_cmp);
    let p = abs
        .get(((abs.len() as f64) * 0.995) as usize)
        .or(abs.last())
        .copied()
        .unwrap_or(0.0);
    p.max(tolerance * cfg.min_range_tolerances).max(1e-6)
}

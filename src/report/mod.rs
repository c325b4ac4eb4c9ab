//! The inspection report: `report.html` with PNG figures beside it (deviation colour map from
//! three views with a colour bar and the tolerance marked, histogram of deviations, tables).
//! Works offline: no scripts, no CDN, a shipped font.
mod colour;
mod font;
mod histogram;
mod html;
mod views;

use std::path::{Path, PathBuf};

use anyhow::Result;
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

pub use colour::diverging;
pub use html::Table;

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
    /// Tolerance (mm), marked on the colour bar and histogram.
    pub tolerance: f64,
    /// Key-value lines shown first (verdict, registration summary, ...).
    pub summary: Vec<(String, String)>,
    /// Tables shown after the figures (regions, ...).
    pub tables: Vec<Table>,
}

/// Files the report wrote.
#[derive(Debug, Clone)]
pub struct ReportFiles {
    /// The page.
    pub html: PathBuf,
    /// The figures.
    pub figures: Vec<PathBuf>,
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

/// Writes report.html and its figures into `dir`.
pub fn write_report(dir: &Path, input: &ReportInput, cfg: &ReportConfig) -> Result<ReportFiles> {
    anyhow::ensure!(
        input.points.len() == input.normals.len() && input.points.len() == input.distances.len(),
        "report: points, normals and distances differ in length"
    );
    std::fs::create_dir_all(dir)?;
    let range = colour_range(input.distances, input.tolerance, cfg);
    let views = dir.join("deviation_views.png");
    views::draw(&views, input, range, cfg)?;
    let hist = dir.join("deviation_histogram.png");
    histogram::draw(&hist, input.distances, input.tolerance, range, cfg)?;
    let figures = vec![views, hist];
    let html = dir.join("report.html");
    html::write(&html, input, &figures)?;
    Ok(ReportFiles { html, figures })
}

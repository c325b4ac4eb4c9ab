//! Histogram of signed deviations with the tolerance band marked.
use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use super::colour::diverging;
use super::font;
use super::input::ReportConfig;

/// Draws the histogram of finite `distances` over [-range, range] into `path`; values beyond
/// the range are counted in the end bins.
pub fn draw(
    path: &Path,
    distances: &[f64],
    tolerance: f64,
    range: f64,
    cfg: &ReportConfig,
) -> Result<()> {
    font::register();
    let bins = cfg.bins.max(4);
    let mut counts = vec![0u64; bins];
    let mut nan = 0usize;
    for &d in distances {
        if !d.is_finite() {
            nan += 1;
            continue;
        }
        let k = (((d + range) / (2.0 * range)) * bins as f64)
            .floor()
            .clamp(0.0, bins as f64 - 1.0) as usize;
        counts[k] += 1;
    }
    let top = counts.iter().copied().max().unwrap_or(1).max(1);
    let root = BitMapBackend::new(path, (900, 420)).into_drawing_area();
    let err = |e: String| anyhow!("{}: drawing failed: {e}", path.display());
    root.fill(&WHITE).map_err(|e| err(format!("{e:?}")))?;
    let caption = format!(
        "signed deviation, mm ({} points, {} without a value; the end bins hold |d| > {:.3})",
        distances.len() - nan,
        nan,
        range
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, (font::FAMILY, 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(70)
        .build_cartesian_2d(-range..range, (0.8f64..top as f64 * 1.5).log_scale())
        .map_err(|e| err(format!("{e:?}")))?;
    chart
        .configure_mesh()
        .x_desc("deviation (mm), + = material in excess")
        .y_desc("points (log scale)")
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style((font::FAMILY, 14))
        .draw()
        .map_err(|e| err(format!("{e:?}")))?;
    let width = 2.0 * range / bins as f64;
    chart
        .draw_series(counts.iter().enumerate().map(|(k, &c)| {
            let x0 = -range + k as f64 * width;
            Rectangle::new(
                [(x0, 0.8), (x0 + width, (c as f64).max(0.8))],
                diverging(x0 + width / 2.0, range).filled(),
            )
        }))
        .map_err(|e| err(format!("{e:?}")))?;
    for t in [-tolerance, tolerance] {
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(t, 0.8), (t, top as f64 * 1.5)],
                BLACK.stroke_width(2),
            )))
            .map_err(|e| err(format!("{e:?}")))?;
    }
    root.present().map_err(|e| err(format!("{e:?}")))?;
    Ok(())
}

//! The overview: the part from standard orthographic views, coloured by signed deviation, with
//! a colour bar and every defect region numbered where it shows. The three classic views
//! (anterior, lateral, distal) come first; further standard views join, most useful first,
//! until every region shows in one of them.
use std::path::Path;

use anyhow::{anyhow, Result};
use nalgebra::Vector3;
use plotters::prelude::*;
use rayon::prelude::*;

use super::font;
use super::input::{RegionMark, ReportConfig, ReportInput};
use super::marks::{self, BAR_W};
use super::raster::{self, Camera, Raster};

pub(super) const TITLE_H: u32 = 40;
/// Panels per row of the overview.
pub(super) const PER_ROW: usize = 3;
/// Least pixels of a region that count as showing it in a view (a 4 × 4 px patch: anything
/// smaller is a speck the reader cannot find).
pub const MIN_REGION_PX: usize = 16;
/// Margin around the part in a panel, px.
const MARGIN_PX: f64 = 24.0;
/// Largest point splat of the overview, px.
const MAX_SPLAT: i64 = 8;
/// The three classic views, always shown.
pub(super) const CLASSIC: usize = 3;

/// A standard view: name, towards the viewer, screen up.
pub(super) type View = (&'static str, [f64; 3], [f64; 3]);

/// The six standard views, the classic three first.
pub(super) const VIEWS: [View; 6] = [
    ("anterior (+y)", [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
    ("lateral (+x)", [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
    ("distal (-z)", [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]),
    ("posterior (-y)", [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]),
    ("medial (-x)", [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
    ("proximal (+z)", [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
];

/// What the overview shows: per panel its name and the region ids numbered on it.
#[derive(Debug, Clone)]
pub struct Overview {
    /// (view name, region ids shown) per panel, in order.
    pub panels: Vec<(String, Vec<usize>)>,
}

/// The standard views at `cfg`'s panel size: the panel side in pixels, one camera per view
/// ([`cameras`]) and each camera's raster of every point (the font registered for the titles).
pub(super) fn view_rasters(
    input: &ReportInput,
    cfg: &ReportConfig,
) -> (usize, Vec<Camera>, Vec<Raster>) {
    font::register();
    let panel = cfg.panel_px.max(100) as usize;
    let cams = cameras(input, panel);
    let rasters = cams
        .par_iter()
        .map(|cam| raster::raster(input, cam, |_| true))
        .collect();
    (panel, cams, rasters)
}

/// One camera per standard view, one scale for all so sizes compare.
pub(super) fn cameras(input: &ReportInput, panel: usize) -> Vec<Camera> {
    let mut cams: Vec<Camera> = VIEWS
        .iter()
        .map(|(_, t, u)| Camera::looking(Vector3::from(*t), Vector3::from(*u), (panel, panel)))
        .collect();
    let (mut span, mut area) = (1e-9f64, 0.0);
    for (k, cam) in cams.iter_mut().enumerate() {
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in input.points {
            let uv = cam.screen(p);
            for k in 0..2 {
                lo[k] = lo[k].min(uv[k]);
                hi[k] = hi[k].max(uv[k]);
            }
        }
        cam.centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        span = span.max((hi[0] - lo[0]).max(hi[1] - lo[1]));
        if k < CLASSIC {
            area += (hi[0] - lo[0]) * (hi[1] - lo[1]);
        }
    }
    let px_per_mm = (panel as f64 - MARGIN_PX) / span;
    // Twice the classic views' boxes: a guess at the surface area (as before six views).
    let spacing = (area * 2.0 / input.points.len().max(1) as f64).sqrt();
    let splat = raster::splat_for(spacing, px_per_mm, MAX_SPLAT);
    for cam in &mut cams {
        cam.px_per_mm = px_per_mm;
        cam.splat = splat;
    }
    cams
}

/// The views to show: the classic three, then greedily the view showing most regions not yet
/// shown (ties: the earlier view), until every region that any view shows is shown.
fn choose(shown: &[Vec<usize>]) -> Vec<usize> {
    let mut chosen: Vec<usize> = (0..CLASSIC).collect();
    let mut seen: Vec<usize> = chosen.iter().flat_map(|&v| shown[v].clone()).collect();
    loop {
        let gain = |v: usize| shown[v].iter().filter(|r| !seen.contains(r)).count();
        let best = (0..shown.len())
            .filter(|v| !chosen.contains(v))
            .max_by_key(|&v| (gain(v), std::cmp::Reverse(v)));
        match best {
            Some(v) if gain(v) > 0 => {
                chosen.push(v);
                seen.extend(shown[v].iter().copied());
            }
            _ => return chosen,
        }
    }
}

/// Renders the overview into `path`: the chosen views in rows of three with a colour bar,
/// regions numbered at the middle of their visible pixels.
pub fn draw(path: &Path, input: &ReportInput, range: f64, cfg: &ReportConfig) -> Result<Overview> {
    font::register();
    let panel = cfg.panel_px.max(100) as usize;
    let cams = cameras(input, panel);
    let ids = input.regions.iter().map(|r| r.id + 1).max().unwrap_or(0);
    let rasters: Vec<Raster> = cams
        .par_iter()
        .map(|cam| raster::raster(input, cam, |_| true))
        .collect();
    let pixels: Vec<Vec<(usize, [f64; 2])>> = rasters
        .iter()
        .map(|r| raster::region_pixels(r, input.labels, ids))
        .collect();
    let shown: Vec<Vec<usize>> = pixels
        .iter()
        .map(|px| {
            let on = |r: &&RegionMark| px[r.id].0 >= MIN_REGION_PX;
            input.regions.iter().filter(on).map(|r| r.id).collect()
        })
        .collect();
    let chosen = choose(&shown);
    let rows = chosen.len().div_ceil(PER_ROW);
    let (w, h) = (
        PER_ROW as u32 * panel as u32 + BAR_W,
        rows as u32 * (panel as u32 + TITLE_H),
    );
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("{}: drawing failed: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let title = TextStyle::from((font::FAMILY, 24).into_font()).color(&BLACK);
    let mut panels = Vec::new();
    for (k, &v) in chosen.iter().enumerate() {
        let x0 = (k % PER_ROW) as i32 * panel as i32;
        let y0 = (k / PER_ROW) as i32 * (panel as i32 + TITLE_H as i32);
        let colours = raster::colours(input, &cams[v], &rasters[v], range);
        marks::panel(&root, (x0, y0 + TITLE_H as i32), &colours, panel).map_err(err)?;
        root.draw_text(VIEWS[v].0, &title, (x0 + 12, y0 + 10))
            .map_err(err)?;
        for &id in &shown[v] {
            let [px, py] = pixels[v][id].1;
            let at = (x0 + px as i32, y0 + TITLE_H as i32 + py as i32);
            marks::badge(&root, at, &id.to_string()).map_err(err)?;
        }
        panels.push((VIEWS[v].0.to_string(), shown[v].clone()));
    }
    let bar = (TITLE_H as i32 + 20, panel as i32 + TITLE_H as i32 - 30);
    marks::colour_bar(
        &root,
        PER_ROW as i32 * panel as i32,
        bar,
        range,
        input.tolerance,
    )
    .map_err(err)?;
    root.present().map_err(err)?;
    Ok(Overview { panels })
}

/// Colour of core points measured, outside the area to inspect, and unmeasured in it.
const MEASURED_GREY: RGBColor = RGBColor(200, 200, 200);
/// Outside the area to inspect: paler, so the area reads as one shape.
const OUTSIDE_GREY: RGBColor = RGBColor(236, 236, 236);
/// Unmeasured in the area to inspect (the colour map's deep red end would read as a defect).
const UNMEASURED_ORANGE: RGBColor = RGBColor(245, 130, 32);
/// Panels of the unmeasured-area figure: the standard views that show most of it.
const UNMEASURED_PANELS: usize = 3;

/// Renders the unmeasured area (orange: core points of the area to inspect without a
/// distance; grey: measured; pale: outside the area) from the standard views that show most
/// of it, in one row, each titled with its share of the unmeasured pixels; returns the
/// chosen views' names. Nothing is drawn (None) when no unmeasured point shows.
pub fn draw_unmeasured(
    path: &Path,
    input: &ReportInput,
    cfg: &ReportConfig,
) -> Result<Option<Vec<String>>> {
    let Some(un) = &input.unmeasured else {
        return Ok(None);
    };
    let inside = |i: usize| un.in_area.is_none_or(|a| a[i]);
    let missing = |i: usize| inside(i) && !input.distances[i].is_finite();
    let (panel, cams, rasters) = view_rasters(input, cfg);
    let count = |r: &Raster| {
        r.idx
            .iter()
            .filter(|&&i| i != raster::NONE && missing(i as usize))
            .count()
    };
    let counts: Vec<usize> = rasters.iter().map(count).collect();
    let total: usize = counts.iter().sum();
    if total == 0 {
        return Ok(None);
    }
    let mut order: Vec<usize> = (0..counts.len()).filter(|&v| counts[v] > 0).collect();
    order.sort_by_key(|&v| std::cmp::Reverse(counts[v]));
    order.truncate(UNMEASURED_PANELS);
    let (w, h) = (order.len() as u32 * panel as u32, panel as u32 + TITLE_H);
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("{}: drawing failed: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let title = TextStyle::from((font::FAMILY, 24).into_font()).color(&BLACK);
    for (k, &v) in order.iter().enumerate() {
        let cam = &cams[v];
        let light = (cam.towards + cam.up * 0.3 + cam.right * 0.2).normalize();
        let colours: Vec<Option<RGBColor>> = rasters[v]
            .idx
            .iter()
            .map(|&i| {
                (i != raster::NONE).then(|| {
                    let i = i as usize;
                    let c = match (inside(i), missing(i)) {
                        (_, true) => UNMEASURED_ORANGE,
                        (true, false) => MEASURED_GREY,
                        (false, _) => OUTSIDE_GREY,
                    };
                    super::colour::shade(c, input.normals[i].dot(&light))
                })
            })
            .collect();
        let x0 = k as i32 * panel as i32;
        marks::panel(&root, (x0, TITLE_H as i32), &colours, panel).map_err(err)?;
        let share = 100.0 * counts[v] as f64 / total as f64;
        let text = format!("{} ({share:.0} %)", VIEWS[v].0);
        root.draw_text(&text, &title, (x0 + 12, 10)).map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(Some(
        order.iter().map(|&v| VIEWS[v].0.to_string()).collect(),
    ))
}

#[cfg(test)]
mod tests {
    use super::choose;

    #[test]
    fn the_classic_views_stay_and_the_view_showing_most_missing_regions_joins() {
        // Regions 0..4: 0 shows anteriorly; 1, 2, 3 only from behind; 3 also from below.
        let shown = vec![vec![0], vec![], vec![], vec![1, 2, 3], vec![], vec![3]];
        assert_eq!(choose(&shown), vec![0, 1, 2, 3]);
        let only_top = vec![vec![], vec![], vec![], vec![], vec![], vec![7]];
        assert_eq!(choose(&only_top), vec![0, 1, 2, 5]);
        assert_eq!(choose(&vec![vec![]; 6]), vec![0, 1, 2]);
    }
}

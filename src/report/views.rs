//! The part from three orthographic views, coloured by signed deviation, with a colour bar.
use std::path::Path;

use anyhow::{anyhow, Result};
use nalgebra::Vector3;
use plotters::prelude::*;
use rayon::prelude::*;

use super::colour::{diverging, shade};
use super::{font, ReportConfig, ReportInput};

/// A view: towards the viewer and screen up.
struct View {
    name: &'static str,
    towards: Vector3<f64>,
    up: Vector3<f64>,
}

const BAR_W: u32 = 150;
const TITLE_H: u32 = 40;

fn views() -> [View; 3] {
    [
        View {
            name: "anterior (+y)",
            towards: Vector3::y(),
            up: Vector3::z(),
        },
        View {
            name: "lateral (+x)",
            towards: Vector3::x(),
            up: Vector3::z(),
        },
        View {
            name: "distal (-z)",
            towards: -Vector3::z(),
            up: Vector3::y(),
        },
    ]
}

/// Renders the three views side by side with a colour bar into `path`.
pub fn draw(path: &Path, input: &ReportInput, range: f64, cfg: &ReportConfig) -> Result<()> {
    font::register();
    let panel = cfg.panel_px.max(100);
    let (w, h) = (3 * panel + BAR_W, panel + TITLE_H);
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("{}: drawing failed: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let views = views();
    let frames: Vec<(Vector3<f64>, Vector3<f64>)> = views
        .iter()
        .map(|v| ((-v.towards).cross(&v.up), v.up))
        .collect();
    // One scale for all panels so sizes compare.
    let extent = |right: &Vector3<f64>, up: &Vector3<f64>| {
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in input.points {
            let uv = [p.coords.dot(right), p.coords.dot(up)];
            for k in 0..2 {
                lo[k] = lo[k].min(uv[k]);
                hi[k] = hi[k].max(uv[k]);
            }
        }
        (lo, hi)
    };
    let boxes: Vec<_> = frames.iter().map(|(r, u)| extent(r, u)).collect();
    let span = boxes
        .iter()
        .map(|(lo, hi)| (hi[0] - lo[0]).max(hi[1] - lo[1]))
        .fold(1e-9, f64::max);
    let px_per_mm = (panel as f64 - 24.0) / span;
    let n = input.points.len().max(1) as f64;
    let area_guess: f64 = boxes
        .iter()
        .map(|(lo, hi)| (hi[0] - lo[0]) * (hi[1] - lo[1]))
        .sum::<f64>()
        * 2.0;
    let splat = ((area_guess / n).sqrt() * px_per_mm * 2.0)
        .ceil()
        .clamp(2.0, 8.0) as i64;
    let title = TextStyle::from((font::FAMILY, 24).into_font()).color(&BLACK);
    let scale = Scale {
        panel: panel as usize,
        px_per_mm,
        splat,
        range,
    };
    // The three panels are rasterised at once; drawing them into the page is serial.
    let panels: Vec<Vec<Option<RGBColor>>> = views
        .par_iter()
        .zip(frames.par_iter())
        .zip(boxes.par_iter())
        .map(|((view, frame), bounds)| raster(input, view, frame, bounds, &scale))
        .collect();
    for (k, (view, colour)) in views.iter().zip(&panels).enumerate() {
        let x0 = k as i32 * panel as i32;
        for (idx, c) in colour.iter().enumerate() {
            if let Some(c) = c {
                let (px, py) = ((idx % scale.panel) as i32, (idx / scale.panel) as i32);
                root.draw_pixel((x0 + px, TITLE_H as i32 + py), c)
                    .map_err(err)?;
            }
        }
        root.draw_text(view.name, &title, (x0 + 12, 10))
            .map_err(err)?;
    }
    colour_bar(&root, 3 * panel as i32, range, input.tolerance).map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}

/// How points map to a panel's pixels.
struct Scale {
    /// Panel side, px.
    panel: usize,
    /// Pixels per mm (one scale for all panels, so sizes compare).
    px_per_mm: f64,
    /// Side of a point's square splat, px.
    splat: i64,
    /// Half-width of the colour scale, mm.
    range: f64,
}

/// One panel's pixels, row-major: the shaded colour of the front-most splat (None where no
/// point faces the viewer), pinholes filled. `frame` is the view's (right, up), `bounds` the
/// points' (lo, hi) in it.
fn raster(
    input: &ReportInput,
    view: &View,
    (right, up): &(Vector3<f64>, Vector3<f64>),
    (lo, hi): &([f64; 2], [f64; 2]),
    scale: &Scale,
) -> Vec<Option<RGBColor>> {
    let (size, px_per_mm, splat) = (scale.panel, scale.px_per_mm, scale.splat);
    let half = size as f64 / 2.0;
    let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let mut depth = vec![f64::MIN; size * size];
    let mut colour: Vec<Option<RGBColor>> = vec![None; size * size];
    let light = (view.towards + up * 0.3 + right * 0.2).normalize();
    for (i, p) in input.points.iter().enumerate() {
        let nrm = input.normals[i];
        if nrm.dot(&view.towards) < 0.0 {
            continue;
        }
        let x = (half + (p.coords.dot(right) - centre[0]) * px_per_mm) as i64;
        let y = (half - (p.coords.dot(up) - centre[1]) * px_per_mm) as i64;
        let d = p.coords.dot(&view.towards);
        let c = shade(diverging(input.distances[i], scale.range), nrm.dot(&light));
        for py in y - splat / 2..=y + splat / 2 {
            for px in x - splat / 2..=x + splat / 2 {
                if px < 0 || py < 0 || px >= size as i64 || py >= size as i64 {
                    continue;
                }
                let idx = py as usize * size + px as usize;
                if d > depth[idx] {
                    depth[idx] = d;
                    colour[idx] = Some(c);
                }
            }
        }
    }
    fill_holes(&mut colour, &mut depth, size);
    colour
}

/// Closes the pinholes a random sample leaves between splats: an empty pixel with at least 5
/// of its 8 neighbours covered takes the colour of the nearest (front-most) of them. Three passes;
/// the outline stays (a pixel outside a straight edge has 3 covered neighbours).
fn fill_holes(colour: &mut [Option<RGBColor>], depth: &mut [f64], size: usize) {
    for _ in 0..3 {
        let (before, depth_before) = (colour.to_vec(), depth.to_vec());
        for y in 1..size.saturating_sub(1) {
            for x in 1..size - 1 {
                let i = y * size + x;
                if before[i].is_some() {
                    continue;
                }
                let covered = [
                    i - size - 1,
                    i - size,
                    i - size + 1,
                    i - 1,
                    i + 1,
                    i + size - 1,
                    i + size,
                    i + size + 1,
                ]
                .into_iter()
                .filter_map(|j| before[j].map(|c| (depth_before[j], c)));
                let (n, front) = covered.fold((0, None), |(n, best), (d, c)| {
                    let nearer = best.is_none_or(|(bd, _)| d > bd);
                    (n + 1, if nearer { Some((d, c)) } else { best })
                });
                if let (true, Some((d, c))) = (n >= 5, front) {
                    colour[i] = Some(c);
                    depth[i] = d;
                }
            }
        }
    }
}

/// A vertical colour bar from -range (bottom) to +range (top), tolerance lines marked.
fn colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    x0: i32,
    range: f64,
    tolerance: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (_, h) = root.dim_in_pixel();
    let (top, bottom) = (TITLE_H as i32 + 20, h as i32 - 30);
    let bar_x = x0 + 20;
    let to_y = |v: f64| bottom - ((v + range) / (2.0 * range) * (bottom - top) as f64) as i32;
    for y in top..=bottom {
        let v = range - 2.0 * range * (y - top) as f64 / (bottom - top) as f64;
        root.draw(&Rectangle::new(
            [(bar_x, y), (bar_x + 24, y + 1)],
            diverging(v, range).filled(),
        ))?;
    }
    root.draw(&Rectangle::new(
        [(bar_x, top), (bar_x + 24, bottom)],
        BLACK.stroke_width(1),
    ))?;
    let label = TextStyle::from((font::FAMILY, 16).into_font()).color(&BLACK);
    for v in [-range, -range / 2.0, 0.0, range / 2.0, range] {
        root.draw(&PathElement::new(
            vec![(bar_x + 24, to_y(v)), (bar_x + 30, to_y(v))],
            BLACK,
        ))?;
        root.draw_text(&format!("{v:+.3}"), &label, (bar_x + 33, to_y(v) - 9))?;
    }
    let tol = TextStyle::from((font::FAMILY, 15).into_font()).color(&BLACK);
    for v in [-tolerance, tolerance] {
        if v.abs() < range {
            root.draw(&PathElement::new(
                vec![(bar_x - 6, to_y(v)), (bar_x + 30, to_y(v))],
                BLACK.stroke_width(2),
            ))?;
        }
    }
    root.draw_text(&format!("tol ±{tolerance}"), &tol, (bar_x - 10, bottom + 8))?;
    root.draw_text("mm", &label, (bar_x, top - 18))?;
    Ok(())
}

//! A close-up per defect region: the surface seen along the region's mean normal, cropped to
//! the region plus a margin, in the report's colour map with the tolerance band on the bar,
//! the region's outline, its peak marked and labelled, and a millimetre scale bar.
use std::path::Path;

use anyhow::{anyhow, Result};
use nalgebra::{Point3, Vector3};
use plotters::prelude::*;

use super::font;
use super::input::{RegionMark, ReportInput};
use super::marks::{self, BAR_W};
use super::raster::{self, Camera, NONE};

/// Side of the close-up's square panel, px.
pub const CLOSE_PX: usize = 420;
const TITLE_H: u32 = 40;
/// Margin around the region: half its size, at least this many mm (so a small region shows
/// its surroundings: the reader sees where it sits).
const MIN_MARGIN_MM: f64 = 2.0;
/// Largest splat of a close-up, px: each pixel shows its nearest point on screen, so a splat
/// only bounds how far a point's colour reaches into a gap of the sampling.
const MAX_SPLAT: i64 = 96;

/// The core points of region `id`, and among them the one with the peak distance.
fn members(input: &ReportInput, id: usize) -> (Vec<usize>, Option<usize>) {
    let mine: Vec<usize> = (0..input.labels.len())
        .filter(|&i| input.labels[i] == id as i64)
        .collect();
    let peak = mine
        .iter()
        .copied()
        .filter(|&i| input.distances[i].is_finite())
        .max_by(|&a, &b| {
            input.distances[a]
                .abs()
                .total_cmp(&input.distances[b].abs())
        });
    (mine, peak)
}

/// The camera along the region's normal, framing its members plus the margin; also the half
/// depth of the slab of points drawn (mm), so far-off surfaces cannot hide the region.
fn frame(input: &ReportInput, region: &RegionMark, mine: &[usize]) -> (Camera, f64) {
    let n = region.normal;
    // Screen up: the world axis least along the normal, made orthogonal to it.
    let hint = [Vector3::z(), Vector3::y(), Vector3::x()]
        .into_iter()
        .min_by(|a, b| a.dot(&n).abs().total_cmp(&b.dot(&n).abs()))
        .unwrap_or(Vector3::z());
    let mut cam = Camera::looking(n, hint, (CLOSE_PX, CLOSE_PX));
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for &i in mine {
        let uv = cam.screen(&input.points[i]);
        for k in 0..2 {
            lo[k] = lo[k].min(uv[k]);
            hi[k] = hi[k].max(uv[k]);
        }
    }
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.0);
    let side = size + 2.0 * (size / 2.0).max(MIN_MARGIN_MM);
    cam.centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    cam.px_per_mm = CLOSE_PX as f64 / side;
    (cam, side)
}

/// What a page draws over a close-up (the plan's tool path), in the reference frame, mm.
#[derive(Debug, Clone, Default)]
pub struct Overlay {
    /// Polylines: points, colour, width px.
    pub lines: Vec<(Vec<Point3<f64>>, RGBColor, u32)>,
    /// Crosses: point, colour.
    pub crosses: Vec<(Point3<f64>, RGBColor)>,
    /// The figure's title (None: "region N: along its normal").
    pub title: Option<String>,
}

/// Renders region `region`'s close-up into `path`; false when the region has no member point
/// (nothing drawn).
pub fn draw(path: &Path, input: &ReportInput, region: &RegionMark, range: f64) -> Result<bool> {
    draw_with(path, input, region, range, &Overlay::default())
}

/// [`draw`] with `overlay` drawn over the surface, under the marks.
pub fn draw_with(
    path: &Path,
    input: &ReportInput,
    region: &RegionMark,
    range: f64,
    overlay: &Overlay,
) -> Result<bool> {
    font::register();
    let (mine, peak) = members(input, region.id);
    if mine.is_empty() {
        return Ok(false);
    }
    let (mut cam, side) = frame(input, region, &mine);
    let c = mine
        .iter()
        .fold(Vector3::zeros(), |a, &i| a + input.points[i].coords)
        / mine.len() as f64;
    let depth0 = c.dot(&cam.towards);
    let view = cam.clone();
    let in_slab = |i: usize| {
        let p = &input.points[i];
        let [u, v] = view.screen(p);
        (p.coords.dot(&view.towards) - depth0).abs() <= side
            && (u - view.centre[0]).abs() <= side / 2.0
            && (v - view.centre[1]).abs() <= side / 2.0
    };
    let facing = |i: usize| input.normals[i].dot(&view.towards) >= 0.0 && in_slab(i);
    let near = (0..input.points.len()).filter(|&i| facing(i)).count();
    // The facing points in the slab cover the window; densified points around a summit make
    // that mean spacing small, so each point reaches twice as far.
    let spacing = side / (near.max(1) as f64).sqrt();
    cam.splat = raster::splat_for(2.0 * spacing, cam.px_per_mm, MAX_SPLAT);
    cam.nearest = true;
    let r = raster::raster(input, &cam, in_slab);
    let colours = raster::colours(input, &cam, &r, range);
    let (w, h) = (CLOSE_PX as u32 + BAR_W, CLOSE_PX as u32 + TITLE_H);
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("{}: drawing failed: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let y0 = TITLE_H as i32;
    marks::panel(&root, (0, y0), &colours, CLOSE_PX).map_err(err)?;
    outline(&root, &r.idx, input.labels, region.id, y0).map_err(err)?;
    // The overlay is clipped to the panel.
    let panel = root
        .clone()
        .shrink((0, y0), (CLOSE_PX as u32, CLOSE_PX as u32));
    let at = |p: &Point3<f64>| {
        let (x, y) = cam.pixel(p);
        (x as i32, y as i32)
    };
    for (line, colour, width) in &overlay.lines {
        let px: Vec<(i32, i32)> = line.iter().map(at).collect();
        panel
            .draw(&PathElement::new(px, colour.stroke_width(*width)))
            .map_err(err)?;
    }
    for (p, colour) in &overlay.crosses {
        panel
            .draw(&Cross::new(at(p), 6, colour.stroke_width(3)))
            .map_err(err)?;
    }
    let title = TextStyle::from((font::FAMILY, 20).into_font()).color(&BLACK);
    let name = (overlay.title.clone())
        .unwrap_or_else(|| format!("region {}: along its normal", region.id));
    root.draw_text(&name, &title, (10, 10)).map_err(err)?;
    if let Some(p) = peak {
        let (x, y) = cam.pixel(&input.points[p]);
        let at = (x as i32, y0 + y as i32);
        root.draw(&Circle::new(at, 9, BLACK.stroke_width(2)))
            .map_err(err)?;
        root.draw(&Cross::new(at, 5, BLACK.stroke_width(2)))
            .map_err(err)?;
        let label = peak_label(region.peak, input.distances[p]);
        let style = TextStyle::from((font::FAMILY, 17).into_font()).color(&BLACK);
        let width = 10 * label.len() as i32;
        let (tx, ty) = ((at.0 + 14).min(CLOSE_PX as i32 - width).max(2), at.1 - 30);
        let back = Rectangle::new([(tx - 3, ty - 2), (tx + width, ty + 20)], WHITE.filled());
        root.draw(&back).map_err(err)?;
        root.draw_text(&label, &style, (tx, ty)).map_err(err)?;
    }
    let bar_y = y0 + CLOSE_PX as i32 - 22;
    marks::scale_bar(&root, (16, bar_y), cam.px_per_mm, CLOSE_PX as f64).map_err(err)?;
    let bar = (TITLE_H as i32 + 20, h as i32 - 30);
    marks::colour_bar(&root, CLOSE_PX as i32, bar, range, input.tolerance).map_err(err)?;
    root.present().map_err(err)?;
    Ok(true)
}

/// Darkens the pixels on the region's border (a region pixel beside a non-region one).
fn outline<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    idx: &[u32],
    labels: &[i64],
    id: usize,
    y0: i32,
) -> marks::DrawResult<DB> {
    let w = CLOSE_PX;
    let inside = |k: usize| idx[k] != NONE && labels[idx[k] as usize] == id as i64;
    for y in 1..w - 1 {
        for x in 1..w - 1 {
            let k = y * w + x;
            if inside(k) && [k - 1, k + 1, k - w, k + w].into_iter().any(|j| !inside(j)) {
                root.draw_pixel((x as i32, y0 + y as i32), &RGBColor(30, 30, 30))?;
            }
        }
    }
    Ok(())
}

/// Agreement below which the region's peak and its summit point's distance read as one number
/// at the label's 4 decimals, mm.
const SAME_PEAK_MM: f64 = 5e-5;

/// The label at the summit point (the member of largest |distance|): the region's peak
/// (regions.json: a fitted peak where a model vouches for one), with the point's own distance
/// beside it when the two differ at 4 decimals; the point's distance alone when the peak is
/// not known (NaN).
fn peak_label(peak: f64, point: f64) -> String {
    if !peak.is_finite() {
        format!("max {point:+.4} mm")
    } else if (peak - point).abs() < SAME_PEAK_MM {
        format!("peak {peak:+.4} mm")
    } else {
        format!("peak {peak:+.4} mm (point {point:+.4})")
    }
}

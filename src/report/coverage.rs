//! The coverage map: the part from the inspection's standard views, each core point in the
//! colour of its class (a page's classes: conform, pit, planned, left out by one rule or
//! another), with a legend under the panels. The three classic views come first; a further
//! view joins for each class the chosen views do not show.
use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

use super::colour::shade;
use super::font;
use super::input::{ReportConfig, ReportInput};
use super::raster::NONE;
use super::views::{view_rasters, CLASSIC, MIN_REGION_PX, PER_ROW, TITLE_H, VIEWS};

/// Height of one legend line, px.
const LEGEND_LINE_PX: u32 = 24;

/// One class of the map: its colour and its legend line.
#[derive(Debug, Clone)]
pub struct Class {
    /// Colour of its points.
    pub colour: RGBColor,
    /// Legend text (name and counts).
    pub label: String,
}

/// The views to show: the classic three, then for each class from `first_shown` on that none
/// of them shows (at least [`MIN_REGION_PX`] pixels) the view showing most of it.
fn choose(pixels: &[Vec<usize>], first_shown: usize) -> Vec<usize> {
    let mut chosen: Vec<usize> = (0..CLASSIC).collect();
    let classes = pixels.first().map_or(0, Vec::len);
    for c in first_shown..classes {
        if chosen.iter().any(|&v| pixels[v][c] >= MIN_REGION_PX) {
            continue;
        }
        let best = (0..pixels.len()).max_by_key(|&v| pixels[v][c]);
        if let Some(v) = best.filter(|&v| pixels[v][c] >= MIN_REGION_PX) {
            if !chosen.contains(&v) {
                chosen.push(v);
            }
        }
    }
    chosen.sort_unstable();
    chosen
}

/// Draws the map of `class` (per core point of `input`, indexing `classes`) into `path`;
/// classes from `first_shown` on each get a view that shows them. Returns the views' names.
pub fn draw(
    path: &Path,
    input: &ReportInput,
    class: &[usize],
    classes: &[Class],
    first_shown: usize,
    cfg: &ReportConfig,
) -> Result<Vec<String>> {
    anyhow::ensure!(
        class.len() == input.points.len() && class.iter().all(|&c| c < classes.len()),
        "coverage map: {} classes for {} points",
        class.len(),
        input.points.len()
    );
    let (panel, cams, rasters) = view_rasters(input, cfg);
    let pixels: Vec<Vec<usize>> = (rasters.iter())
        .map(|r| {
            let mut n = vec![0; classes.len()];
            r.idx
                .iter()
                .filter(|&&i| i != NONE)
                .for_each(|&i| n[class[i as usize]] += 1);
            n
        })
        .collect();
    let chosen = choose(&pixels, first_shown);
    let rows = chosen.len().div_ceil(PER_ROW) as u32;
    let legend_h = LEGEND_LINE_PX * classes.len() as u32 + 16;
    let (w, h) = (
        PER_ROW as u32 * panel as u32,
        rows * (panel as u32 + TITLE_H) + legend_h,
    );
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("{}: drawing failed: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let title = TextStyle::from((font::FAMILY, 24).into_font()).color(&BLACK);
    for (k, &v) in chosen.iter().enumerate() {
        let cam = &cams[v];
        let light = (cam.towards + cam.up * 0.3 + cam.right * 0.2).normalize();
        let colours: Vec<Option<RGBColor>> = (rasters[v].idx.iter())
            .map(|&i| {
                (i != NONE).then(|| {
                    let i = i as usize;
                    shade(classes[class[i]].colour, input.normals[i].dot(&light))
                })
            })
            .collect();
        let x0 = (k % PER_ROW) as i32 * panel as i32;
        let y0 = (k / PER_ROW) as i32 * (panel as i32 + TITLE_H as i32);
        super::marks::panel(&root, (x0, y0 + TITLE_H as i32), &colours, panel).map_err(err)?;
        root.draw_text(VIEWS[v].0, &title, (x0 + 12, y0 + 10))
            .map_err(err)?;
    }
    let text = TextStyle::from((font::FAMILY, 17).into_font()).color(&BLACK);
    let top = (rows * (panel as u32 + TITLE_H)) as i32 + 8;
    for (k, c) in classes.iter().enumerate() {
        let y = top + (k as u32 * LEGEND_LINE_PX) as i32;
        root.draw(&Rectangle::new([(12, y), (30, y + 18)], c.colour.filled()))
            .map_err(err)?;
        root.draw(&Rectangle::new(
            [(12, y), (30, y + 18)],
            BLACK.stroke_width(1),
        ))
        .map_err(err)?;
        root.draw_text(&c.label, &text, (40, y)).map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(chosen.iter().map(|&v| VIEWS[v].0.to_string()).collect())
}

#[cfg(test)]
mod tests {
    use super::choose;

    #[test]
    fn a_class_no_classic_view_shows_brings_the_view_that_shows_most_of_it() {
        // classes: conform, planned, rule A (only from behind), rule B (in the lateral view)
        let mut pixels = vec![vec![500, 40, 0, 0]; 6];
        pixels[1][3] = 20;
        pixels[3][2] = 30;
        pixels[4][2] = 50;
        assert_eq!(choose(&pixels, 1), vec![0, 1, 2, 4]);
        // a class under MIN_REGION_PX pixels everywhere brings no view
        pixels[4][2] = 10;
        pixels[3][2] = 12;
        assert_eq!(choose(&pixels, 1), vec![0, 1, 2]);
    }
}

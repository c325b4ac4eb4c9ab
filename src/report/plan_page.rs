//! `plan.html` beside plan.json: per region a close-up of the part (the inspection's colour
//! map) with the planned tool path over it, grinding passes and in-contact stepovers told
//! apart and unreachable contact points marked; the plan's numbers and durations as tables.
//! Its input is plain geometry, so the report module knows nothing of the planner.
use std::path::{Component, Path, PathBuf};

use anyhow::{Context, Result};
use nalgebra::Point3;
use plotters::style::RGBColor;
use rayon::prelude::*;

use super::closeup::{self, Overlay};
use super::coverage::{self, Class};
use super::html::{self, Layout, LINKS_ID};
use super::input::{colour_range, Figure, RegionMark, ReportConfig, ReportInput};

/// A grinding pass (in contact, at the feed): black, 2 px.
const PASS: (RGBColor, u32) = (RGBColor(0, 0, 0), 2);
/// An in-contact stepover between passes: grey, 1 px.
const LINK: (RGBColor, u32) = (RGBColor(110, 110, 110), 1);
/// An unreachable contact point (left out of the motion): magenta.
const UNREACHABLE: RGBColor = RGBColor(200, 0, 200);

/// A piece of tool path over the part.
#[derive(Debug, Clone)]
pub struct ToolPath {
    /// Region id.
    pub region: usize,
    /// A grinding pass (true) or a stepover between passes (false).
    pub grinding: bool,
    /// Contact points on the surface, reference frame, mm.
    pub points: Vec<Point3<f64>>,
}

/// What plan.html shows.
#[derive(Debug, Clone)]
pub struct PlanPage<'a> {
    /// The part (the inspection's core points), regions, summary, tables and provenance.
    pub surface: ReportInput<'a>,
    /// The tool path.
    pub paths: Vec<ToolPath>,
    /// Contact points left out as unreachable: (region id, surface point).
    pub unreachable: Vec<(usize, Point3<f64>)>,
    /// Links to other pages: (text, relative href).
    pub links: Vec<(String, String)>,
    /// The coverage map: per core point its class (indexing `classes`), the classes, and
    /// the first class that must show in a view (the left-out ones); None: no map.
    pub coverage: Option<CoverageMap>,
    /// The predicted part per region: region id and, per core point in the tool's reach,
    /// (index in `surface.points`, predicted deviation after, Monte Carlo low quantile), mm.
    pub predicted: Vec<PredictedRegion>,
}

/// One region's predicted part: region id and, per core point in the tool's reach, (index in
/// the page's points, predicted deviation after, Monte Carlo low quantile), mm.
pub type PredictedRegion = (usize, Vec<(usize, f64, f64)>);

/// The coverage map of plan.html.
#[derive(Debug, Clone)]
pub struct CoverageMap {
    /// Class per core point.
    pub class: Vec<usize>,
    /// The classes, in legend order.
    pub classes: Vec<Class>,
    /// The first class each of whose points must show in a view.
    pub first_shown: usize,
    /// Caption of the figure.
    pub caption: String,
}

/// The three panels of a region on one colour scale: (file suffix, title, what it shows).
const PANELS: [(&str, &str); 3] = [
    ("before", "deviation before"),
    ("after", "predicted after"),
    ("low", "Monte Carlo low quantile"),
];

/// Draws region `r`'s three panels (deviation before, predicted after, the Monte Carlo's low
/// quantile) on the colour scale `range`, into `{stem}_region_{id}_{suffix}.png`.
fn prediction_panels(
    (dir, stem): (&Path, &str),
    input: &ReportInput,
    r: &RegionMark,
    rows: &[(usize, f64, f64)],
    range: f64,
) -> Result<Vec<Figure>> {
    let mut figures = Vec::new();
    for (k, (suffix, what)) in PANELS.iter().enumerate() {
        let mut distances = input.distances.to_vec();
        for &(i, after, low) in rows {
            distances[i] = [distances[i], after, low][k];
        }
        let shown = ReportInput {
            distances: &distances,
            ..input.clone()
        };
        // the regions.json peak belongs to the part before; after, the largest |value| shows
        let mark = RegionMark {
            peak: if k == 0 { r.peak } else { f64::NAN },
            ..r.clone()
        };
        let overlay = Overlay {
            title: Some(format!("region {}: {what}", r.id)),
            ..Overlay::default()
        };
        let path = dir.join(format!("{stem}_region_{}_{suffix}.png", r.id));
        if closeup::draw_with(&path, &shown, &mark, range, &overlay)? {
            let values = rows
                .iter()
                .map(|row| [input.distances[row.0], row.1, row.2][k]);
            let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                (lo.min(v), hi.max(v))
            });
            figures.push(Figure {
                caption: format!(
                    "region {}: {what}; {lo:+.4} to {hi:+.4} mm over the {} core points in \
                     the tool's reach; colour scale ±{range:.4} mm, tolerance ±{} mm",
                    r.id,
                    rows.len(),
                    input.tolerance
                ),
                path,
                regions: vec![r.id],
            });
        }
    }
    Ok(figures)
}

/// Writes the page `html` and a figure per region beside it; returns the figures.
pub fn write_plan_page(html: &Path, page: &PlanPage, cfg: &ReportConfig) -> Result<Vec<PathBuf>> {
    let input = &page.surface;
    let dir = html.parent().unwrap_or(Path::new("."));
    let stem = html.file_stem().and_then(|s| s.to_str()).unwrap_or("plan");
    let range = colour_range(input.distances, input.tolerance, cfg);
    let figures: Vec<Figure> = input
        .regions
        .par_iter()
        .map(|r| {
            let mut overlay = Overlay::default();
            let (mut passes, mut links) = (0, 0);
            for p in page.paths.iter().filter(|p| p.region == r.id) {
                let (colour, width) = if p.grinding { PASS } else { LINK };
                *(if p.grinding { &mut passes } else { &mut links }) += 1;
                overlay.lines.push((p.points.clone(), colour, width));
            }
            let lost = page.unreachable.iter().filter(|u| u.0 == r.id);
            overlay.crosses = lost.map(|u| (u.1, UNREACHABLE)).collect();
            let path = dir.join(format!("{stem}_region_{}.png", r.id));
            let drawn = closeup::draw_with(&path, input, r, range, &overlay)?;
            let mut figures: Vec<Figure> = drawn
                .then(|| Figure {
                    caption: format!(
                        "region {}: {}; {passes} passes, {links} stepovers, {} unreachable \
                         points",
                        r.id,
                        r.caption,
                        overlay.crosses.len()
                    ),
                    path,
                    regions: vec![r.id],
                })
                .into_iter()
                .collect();
            if let Some((_, rows)) = page.predicted.iter().find(|p| p.0 == r.id) {
                figures.extend(prediction_panels((dir, stem), input, r, rows, range)?);
            }
            Ok(figures)
        })
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    let mut whole = Vec::new();
    if let Some(map) = &page.coverage {
        let path = dir.join(format!("{stem}_coverage.png"));
        let views = coverage::draw(&path, input, &map.class, &map.classes, map.first_shown, cfg)?;
        whole.push(Figure {
            path,
            caption: format!("{}; views: {}", map.caption, views.join(", ")),
            regions: Vec::new(),
        });
    }
    let layout = Layout {
        whole: &whole,
        closeup_title: "per region: the tool path (black: grinding passes; grey: stepovers in \
                        contact; magenta ×: unreachable, left out), then the deviation before, \
                        the predicted part after and the Monte Carlo's low quantile on the same \
                        colour scale",
        closeups: &figures,
        viewer: "",
        links: &page.links,
    };
    html::write(html, input, &layout)?;
    Ok(whole.into_iter().chain(figures).map(|f| f.path).collect())
}

/// `to` relative to the folder `from` (both made absolute), with `/` separators; None when
/// either cannot be resolved.
pub fn relative(from: &Path, to: &Path) -> Option<String> {
    let (from, to) = (from.canonicalize().ok()?, to.canonicalize().ok()?);
    let (a, b): (Vec<Component>, Vec<Component>) =
        (from.components().collect(), to.components().collect());
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut parts: Vec<String> = vec!["..".to_string(); a.len() - common];
    parts.extend(
        b[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    Some(parts.join("/"))
}

/// Links the inspection's page `report` (in the folder `dir`; `held`: its text, see
/// [`add_link`]) to the plan's page `html`, when there is such a report. The link is a
/// convenience: a report it cannot edit (an older one, a read-only folder) is said on stderr
/// and left as it is.
pub fn link_report(report: &Path, held: Option<&str>, dir: &Path, html: &Path) {
    if !report.is_file() {
        return;
    }
    let linked = relative(dir, html).map(|href| add_link(report, held, "grinding plan", &href));
    match linked {
        Some(Ok(true)) => {}
        Some(Err(e)) => eprintln!("plan: notice: {e:#}; not linked to {}", html.display()),
        _ => eprintln!(
            "plan: notice: {} has no links paragraph (an older report); not linked to {}",
            report.display(),
            html.display()
        ),
    }
}

/// Adds a link `text` -> `href` to the links paragraph of the page `report` (once); false
/// when the page has no such paragraph (a report from before 2026-12-02), left as it is.
/// `held`: the page's text when this process wrote it (edited in memory and written, not read
/// back); None: the page is read from `report`.
pub fn add_link(report: &Path, held: Option<&str>, text: &str, href: &str) -> Result<bool> {
    let read;
    let page = match held {
        Some(page) => page,
        None => {
            read = std::fs::read_to_string(report)
                .with_context(|| format!("{}: cannot read", report.display()))?;
            &read
        }
    };
    let anchor = format!("<a href=\"{}\">", html::escape(href));
    if page.contains(&anchor) {
        return Ok(true);
    }
    let marker = format!("<p id=\"{LINKS_ID}\">");
    let Some(at) = page.find(&marker) else {
        return Ok(false);
    };
    let at = at + marker.len();
    let link = format!("{anchor}{}</a> ", html::escape(text));
    let out = format!("{}{link}{}", &page[..at], &page[at..]);
    std::fs::write(report, out).with_context(|| format!("{}: cannot write", report.display()))?;
    Ok(true)
}

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
use super::html::{self, Layout, LINKS_ID};
use super::input::{colour_range, Figure, ReportConfig, ReportInput};

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
            Ok(drawn.then(|| Figure {
                caption: format!(
                    "region {}: {}; {passes} passes, {links} stepovers, {} unreachable points",
                    r.id,
                    r.caption,
                    overlay.crosses.len()
                ),
                path,
                regions: vec![r.id],
            }))
        })
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    let layout = Layout {
        whole: &[],
        closeup_title: "tool path per region (black: grinding passes; grey: stepovers in \
                        contact; magenta ×: unreachable, left out)",
        closeups: &figures,
        viewer: "",
        links: &page.links,
    };
    html::write(html, input, &layout)?;
    Ok(figures.into_iter().map(|f| f.path).collect())
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

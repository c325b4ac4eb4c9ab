//! The loop's figures for cycle.html (issue 50, "show it"): per grind, each planned region's
//! deviation map before it with the measured shift of its removal drawn as an arrow, and the
//! predicted against the achieved removal at the same core points; over the loop, the
//! convergence of the volume above the tolerance, the peak and Preston's k. Plain data in,
//! PNGs and an HTML section out: the loop (`cycle`) hands over what it holds in memory.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Result};
use nalgebra::{Point3, Vector3};
use plotters::prelude::*;

use super::closeup::{self, Overlay};
use super::font;
use super::html::escape;
use super::input::{colour_range, Figure, ReportConfig, ReportInput};

/// Colours of the regions in the scatter, in turn.
const REGION_COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];
/// Side of a chart, px.
const CHART_PX: (u32, u32) = (560, 460);
/// The carried correction's arrow: grey beside the measured shift's black.
const CARRIED: RGBColor = RGBColor(120, 120, 120);
/// Half-angle of the shift arrow's head, radians (30 degrees).
const HEAD_RAD: f64 = std::f64::consts::FRAC_PI_6;

/// What one region's registration measured (`cell::removal_shift`).
#[derive(Debug, Clone)]
pub struct RegionGrind {
    /// Region id (of the inspection before the grind).
    pub region: usize,
    /// The measured shift of the removal from the plan, reference frame, mm.
    pub shift_mm: Vector3<f64>,
    /// Depth scale at that shift (measured = scale x predicted).
    pub scale: f64,
    /// The correction the next plan aims back by there, mm (None: none carried).
    pub carried_mm: Option<Vector3<f64>>,
}

/// One grind as the loop saw it.
#[derive(Debug, Clone)]
pub struct GrindView<'a> {
    /// The iteration whose plan was ground (folder iter-k).
    pub iteration: usize,
    /// The inspection before the grind; its `regions` are the planned regions.
    pub before: ReportInput<'a>,
    /// Per planned region its registration.
    pub shifts: Vec<RegionGrind>,
    /// Per matched core point: region id, predicted removal, achieved removal, mm.
    pub removal: Vec<(usize, f64, f64)>,
}

/// Draws one grind's figures into `dir`: per planned region its map before the grind with the
/// measured shift, then the scatter of predicted against achieved removal.
pub fn draw_grind(dir: &Path, view: &GrindView) -> Result<Vec<Figure>> {
    let input = &view.before;
    let range = colour_range(input.distances, input.tolerance, &ReportConfig::default());
    let k = view.iteration;
    let mut figures = Vec::new();
    for r in &input.regions {
        let shift = view.shifts.iter().find(|s| s.region == r.id);
        let mut overlay = Overlay {
            title: Some(format!("grind {k}, region {}: before", r.id)),
            ..Overlay::default()
        };
        let words = match shift {
            Some(s) => {
                let from = Point3::from(r.centroid);
                overlay.lines = arrow(&from, &r.normal, &s.shift_mm, BLACK);
                let v = |v: &Vector3<f64>| format!("[{:+.2}, {:+.2}, {:+.2}]", v.x, v.y, v.z);
                let carried = s.carried_mm.map_or(String::new(), |c| {
                    overlay.lines.extend(arrow(&from, &r.normal, &c, CARRIED));
                    format!(
                        "; the next plan aims back by {:.2} mm {} (grey)",
                        c.norm(),
                        v(&c)
                    )
                });
                format!(
                    "measured shift {:.2} mm {} (black arrow, from the region's centre), depth \
                     scale {:.3}{carried}",
                    s.shift_mm.norm(),
                    v(&s.shift_mm),
                    s.scale
                )
            }
            None => "no shift measured (no removal registered)".into(),
        };
        let path = dir.join(format!("grind_region_{}.png", r.id));
        if closeup::draw_with(&path, input, r, range, &overlay)? {
            figures.push(Figure {
                path,
                caption: format!("grind {k}, region {}: deviation before; {words}", r.id),
                regions: vec![r.id],
            });
        }
    }
    let path = dir.join("grind_removal.png");
    let n = scatter(&path, k, &view.removal)?;
    figures.push(Figure {
        path,
        caption: format!(
            "grind {k}: removal predicted by the plan (at its k and where it planned it) \
             against the removal achieved (the deviation before less the next inspection's, at \
             the same core point), {n} core points; the diagonal is agreement"
        ),
        regions: view.shifts.iter().map(|s| s.region).collect(),
    });
    Ok(figures)
}

/// The arrow of `shift` from `from` in `colour` (its head's two barbs turned about
/// `normal`), as overlay lines.
fn arrow(
    from: &Point3<f64>,
    normal: &Vector3<f64>,
    shift: &Vector3<f64>,
    colour: RGBColor,
) -> Vec<(Vec<Point3<f64>>, RGBColor, u32)> {
    let tip = from + shift;
    let mut lines = vec![(vec![*from, tip], colour, 3)];
    let len = shift.norm();
    if len > 1e-9 {
        let back = -shift / len;
        let side = normal.cross(&back).normalize();
        for s in [-1.0, 1.0] {
            let barb = (back * HEAD_RAD.cos() + side * s * HEAD_RAD.sin()) * (0.3 * len);
            lines.push((vec![tip, tip + barb], colour, 3));
        }
    }
    lines
}

/// The scatter of (region, predicted, achieved) removal into `path`; returns the points drawn.
fn scatter(path: &Path, k: usize, points: &[(usize, f64, f64)]) -> Result<usize> {
    font::register();
    let err = |e: String| anyhow!("{}: drawing failed: {e}", path.display());
    let top = (points.iter())
        .flat_map(|p| [p.1, p.2])
        .filter(|v| v.is_finite())
        .fold(0.01f64, f64::max)
        * 1.05;
    let low = (points.iter())
        .map(|p| p.2)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::min)
        * 1.05;
    let root = BitMapBackend::new(path, CHART_PX).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(format!("{e:?}")))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("grind {k}: predicted vs achieved removal"),
            (font::FAMILY, 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..top, low..top)
        .map_err(|e| err(format!("{e:?}")))?;
    chart
        .configure_mesh()
        .x_desc("predicted removal, mm")
        .y_desc("achieved removal, mm")
        .label_style((font::FAMILY, 14))
        .draw()
        .map_err(|e| err(format!("{e:?}")))?;
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(0.0, 0.0), (top, top)],
            BLACK.stroke_width(1),
        )))
        .map_err(|e| err(format!("{e:?}")))?;
    let mut regions: Vec<usize> = points.iter().map(|p| p.0).collect();
    regions.sort_unstable();
    regions.dedup();
    for (j, id) in regions.iter().enumerate() {
        let colour = REGION_COLOURS[j % REGION_COLOURS.len()];
        let own = points.iter().filter(|p| p.0 == *id);
        chart
            .draw_series(own.map(|p| Circle::new((p.1, p.2), 3, colour.filled())))
            .map_err(|e| err(format!("{e:?}")))?
            .label(format!("region {id}"))
            .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
    }
    chart
        .configure_series_labels()
        .label_font((font::FAMILY, 14))
        .border_style(BLACK)
        .background_style(WHITE)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| err(format!("{e:?}")))?;
    root.present().map_err(|e| err(format!("{e:?}")))?;
    Ok(points.len())
}

/// The loop's course, one value per inspection (None: not known).
#[derive(Debug, Clone, Default)]
pub struct Convergence {
    /// Excess volume above the tolerance of the repairable regions, mm³.
    pub volume_mm3: Vec<f64>,
    /// Largest peak of a repairable region, mm.
    pub peak_mm: Vec<Option<f64>>,
    /// Preston's k fitted after the grind that followed, mm²/N.
    pub k: Vec<Option<f64>>,
}

/// Draws the convergence plot into `path`: three charts side by side over the iterations.
pub fn draw_convergence(path: &Path, c: &Convergence) -> Result<()> {
    font::register();
    let err = |e: String| anyhow!("{}: drawing failed: {e}", path.display());
    let root = BitMapBackend::new(path, (3 * 400, 360)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(format!("{e:?}")))?;
    let series: [(&str, Vec<Option<f64>>); 3] = [
        (
            "volume above tolerance, mm³",
            c.volume_mm3.iter().map(|v| Some(*v)).collect(),
        ),
        ("peak of a repairable region, mm", c.peak_mm.clone()),
        ("k fitted after the grind, mm²/N", c.k.clone()),
    ];
    let n = series[0].1.len().max(1) as f64;
    for (area, (name, values)) in root.split_evenly((1, 3)).iter().zip(&series) {
        let pts: Vec<(f64, f64)> = (values.iter().enumerate())
            .filter_map(|(i, v)| v.filter(|v| v.is_finite()).map(|v| (i as f64 + 1.0, v)))
            .collect();
        let top = pts.iter().map(|p| p.1).fold(0.0f64, f64::max);
        let top = if top > 0.0 { top * 1.15 } else { 1.0 };
        let mut chart = ChartBuilder::on(area)
            .caption(*name, (font::FAMILY, 16))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(72)
            .build_cartesian_2d(0.5..n + 0.5, 0.0..top)
            .map_err(|e| err(format!("{e:?}")))?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .x_labels(n as usize + 1)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| {
                if top < 1e-3 {
                    format!("{v:.2e}")
                } else {
                    format!("{v:.3}")
                }
            })
            .label_style((font::FAMILY, 13))
            .draw()
            .map_err(|e| err(format!("{e:?}")))?;
        chart
            .draw_series(LineSeries::new(pts.clone(), BLUE.stroke_width(2)))
            .map_err(|e| err(format!("{e:?}")))?;
        chart
            .draw_series(pts.iter().map(|p| Circle::new(*p, 4, BLUE.filled())))
            .map_err(|e| err(format!("{e:?}")))?;
    }
    root.present().map_err(|e| err(format!("{e:?}")))?;
    Ok(())
}

/// The figures' section of cycle.html: the convergence plot, then per grind its figures;
/// image sources relative to `dir` (the page's folder).
pub fn figures_html(dir: &Path, convergence: Option<&Path>, grinds: &[Figure]) -> String {
    let href = |p: &PathBuf| {
        p.strip_prefix(dir)
            .unwrap_or(p)
            .to_string_lossy()
            .replace('\\', "/")
    };
    let mut s = String::from("<style>img{max-width:100%;border:1px solid #ddd}figure{display:inline-block;vertical-align:top;max-width:600px;margin:8px}figcaption{font-size:90%;color:#444}</style>\n");
    let fig = |s: &mut String, p: &PathBuf, caption: &str| {
        let h = escape(&href(p));
        let _ = writeln!(
            s,
            "<figure><img src=\"{h}\" alt=\"{h}\"><figcaption>{}</figcaption></figure>",
            escape(caption)
        );
    };
    if let Some(c) = convergence {
        s += "<h2>convergence</h2>\n";
        fig(
            &mut s,
            &c.to_path_buf(),
            "per inspection: the volume above the tolerance and the largest peak of the \
             repairable regions; k as fitted after the grind that followed it",
        );
    }
    if !grinds.is_empty() {
        s += "<h2>per grind: the map before it, the measured shift, predicted against achieved \
              removal</h2>\n";
    }
    for f in grinds {
        fig(&mut s, &f.path, &f.caption);
    }
    s
}

/// `page` (a [`super::table_page`]) with `section` inserted before its end.
pub fn with_section(page: &str, section: &str) -> String {
    match page.rfind("</body>") {
        Some(at) => format!("{}{section}{}", &page[..at], &page[at..]),
        None => format!("{page}{section}"),
    }
}

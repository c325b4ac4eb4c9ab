//! plan.html from a plan: the tool path per region over the inspection's colour map, reach
//! and durations as tables ([`write_plan_html`]), drawn by [`super::plan_page`]. Reads only
//! fields plan.json already has, so the planner's own files stay untouched.
use std::path::{Path, PathBuf};

use anyhow::Result;
use nalgebra::{Point3, Vector3};

use super::inspection::region_mark;
use super::plan_page::{self, PlanPage, ToolPath};
use super::provenance::Provenance;
use super::{ReportConfig, ReportInput, Table};
use crate::motion::{Plan, Segment, SegmentKind, StrokeKind};
use crate::repair::Inspection;

/// Seconds of the samples `first..=last` at the bus period.
fn seconds(s: &Segment, period: f64) -> f64 {
    (s.last_sample.saturating_sub(s.first_sample)) as f64 * period
}

/// Per region: grinding, approach + retract, reorientation seconds.
fn region_times(plan: &Plan, id: usize) -> [f64; 3] {
    let mut t = [0.0; 3];
    for s in plan.segments.iter().filter(|s| s.region == Some(id)) {
        let k = match s.kind {
            SegmentKind::Grind => 0,
            SegmentKind::Approach | SegmentKind::Retract => 1,
            _ => 2,
        };
        t[k] += seconds(s, plan.period);
    }
    t
}

/// The tables of plan.html: reach and time per region, time per kind of motion.
fn tables(plan: &Plan) -> Vec<Table> {
    let strings = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    let rows = plan
        .reachability
        .regions
        .iter()
        .map(|r| {
            let passes = plan.passes.iter().filter(|p| p.region == r.id);
            let [grind, approach, reorient] = region_times(plan, r.id);
            vec![
                r.id.to_string(),
                r.layers.to_string(),
                passes.count().to_string(),
                r.path_points.to_string(),
                r.unreachable_path_points.to_string(),
                format!("{:.1} %", 100.0 * r.unreachable_share),
                format!("{:.1} %", 100.0 * r.coverage_of_reachable),
                format!("{grind:.2}"),
                format!("{approach:.2}"),
                format!("{reorient:.2}"),
            ]
        })
        .collect();
    let kinds = [
        (
            SegmentKind::Transit,
            "transit (rest to rest, between regions)",
        ),
        (SegmentKind::Approach, "approach"),
        (SegmentKind::Grind, "grinding"),
        (SegmentKind::Retract, "retract"),
        (SegmentKind::Reorient, "reorientation / depth step"),
    ];
    let by_kind = kinds
        .iter()
        .map(|(kind, name)| {
            let segs: Vec<&Segment> = plan.segments.iter().filter(|s| s.kind == *kind).collect();
            let t: f64 = segs.iter().map(|s| seconds(s, plan.period)).sum();
            vec![name.to_string(), segs.len().to_string(), format!("{t:.2}")]
        })
        .collect();
    vec![
        Table {
            title: "reach and time per region".into(),
            header: strings(&[
                "region",
                "layers",
                "pieces of stroke",
                "path points",
                "unreachable path points",
                "area unreachable",
                "reachable area covered",
                "grinding s",
                "approach + retract s",
                "reorientation s",
            ]),
            rows,
        },
        Table {
            title: "time per kind of motion".into(),
            header: strings(&["motion", "segments", "s"]),
            rows: by_kind,
        },
    ]
}

/// Writes plan.html (beside `plan_file`, same stem) with its figures and links the
/// inspection's report.html to it (`report_page`: its text when this process wrote it, see
/// [`plan_page::add_link`]); returns the page.
pub fn write_plan_html(
    plan_file: &Path,
    inspection: &Inspection,
    plan: &Plan,
    provenance: &Provenance,
    report_page: Option<&str>,
) -> Result<PathBuf> {
    let html = plan_file.with_extension("html");
    let pts = &inspection.points;
    let points: Vec<Point3<f64>> = pts.iter().map(|p| p.position).collect();
    let normals: Vec<Vector3<f64>> = pts.iter().map(|p| p.normal).collect();
    let distances: Vec<f64> = pts.iter().map(|p| p.distance).collect();
    let labels: Vec<i64> = pts.iter().map(|p| p.region).collect();
    let planned: Vec<usize> = plan.passes.iter().map(|p| p.region).collect();
    let m = &plan.metrics;
    let mut summary = vec![
        ("plan".to_string(), plan_file.display().to_string()),
        (
            "predicted duration".to_string(),
            format!("{:.2} s", plan.predicted_duration_s),
        ),
        (
            "motion".to_string(),
            format!(
                "{} pieces of stroke, {} path points, {} samples at {} s",
                plan.passes.len(),
                m.path_points,
                m.samples,
                plan.period
            ),
        ),
        (
            "unreachable contact points".to_string(),
            format!(
                "{} (left out; listed in plan.json)",
                plan.reachability.unreachable.len()
            ),
        ),
        (
            "tool".to_string(),
            format!(
                "ball radius {} mm, stepover {:.3} mm, feed {} mm/s",
                plan.tool_radius_mm, plan.stepover_mm, m.feed_mm_s
            ),
        ),
    ];
    if let Some(rem) = &plan.removal {
        summary.push((
            "Monte Carlo tip error".to_string(),
            format!(
                "+-{} mm per axis, from {}",
                rem.tip_error_mm, rem.tip_error_source
            ),
        ));
    }
    let report = inspection.dir.join("report.html");
    let dir = (html.parent())
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let back = report
        .is_file()
        .then(|| plan_page::relative(dir, &report))
        .flatten();
    let page = PlanPage {
        surface: ReportInput {
            title: "polishbot grinding plan".into(),
            points: &points,
            normals: &normals,
            distances: &distances,
            uncertainties: &[],
            tolerance: inspection.tolerance.unwrap_or(0.0),
            summary,
            tables: tables(plan),
            labels: &labels,
            regions: (inspection.regions.iter())
                .filter(|r| planned.contains(&r.id))
                .map(region_mark)
                .collect(),
            provenance: Some(provenance),
            unmeasured: None,
        },
        paths: plan
            .passes
            .iter()
            .map(|p| ToolPath {
                region: p.region,
                grinding: p.kind == StrokeKind::Pass,
                points: p
                    .points
                    .iter()
                    .map(|q| Point3::from(q.surface_mm))
                    .collect(),
            })
            .collect(),
        unreachable: (plan.reachability.unreachable.iter())
            .map(|u| (u.region, Point3::from(u.surface_mm)))
            .collect(),
        links: back
            .iter()
            .map(|b| ("inspection report".to_string(), b.clone()))
            .collect(),
    };
    plan_page::write_plan_page(&html, &page, &ReportConfig::default())?;
    plan_page::link_report(&report, report_page, &inspection.dir, &html);
    Ok(html)
}

//! plan.html from a plan: the tool path per region over the inspection's colour map, reach
//! and durations as tables ([`write_plan_html`]), drawn by [`super::plan_page`]. Reads only
//! fields plan.json already has, so the planner's own files stay untouched.
use std::path::{Path, PathBuf};

use anyhow::Result;
use nalgebra::{Point3, Vector3};

use plotters::style::RGBColor;

use super::coverage::Class;
use super::inspection::region_mark;
use super::plan_page::{self, CoverageMap, PlanPage, PredictedRegion, ToolPath};
use super::plan_reach::{self, PlanCoverage, PLANNED, RULE0};
use super::provenance::Provenance;
use super::{ReportConfig, ReportInput, Table};
use crate::motion::{Plan, Segment, SegmentKind, StrokeKind};
use crate::repair::Inspection;
use crate::spatial::Neighbours;

/// Colours of the coverage map: conform, pit, planned.
const FIXED: [RGBColor; 3] = [
    RGBColor(225, 225, 225),
    RGBColor(110, 150, 200),
    RGBColor(60, 170, 80),
];
/// Colours of the rules that left parts out, in turn (told apart from the fixed three and
/// from each other; a ninth rule takes the first again).
const RULE_COLOURS: [RGBColor; 8] = [
    RGBColor(245, 130, 32),
    RGBColor(200, 0, 200),
    RGBColor(215, 40, 40),
    RGBColor(120, 60, 170),
    RGBColor(150, 90, 40),
    RGBColor(230, 190, 0),
    RGBColor(0, 150, 150),
    RGBColor(60, 60, 60),
];
/// Largest distance between a predicted.csv row and its core point, mm (the rows are the core
/// points themselves: anything farther is not the same point).
const SAME_POINT_MM: f64 = 1e-6;

/// The coverage map's classes with their legend lines, and the table of rules.
fn coverage(reach: &PlanCoverage, inspection: &Inspection) -> (CoverageMap, Table) {
    let count = |c: usize| reach.class.iter().filter(|&&k| k == c).count();
    let mut classes = vec![
        Class {
            colour: FIXED[0],
            label: format!("outside every defect region: {} core points", count(0)),
        },
        Class {
            colour: FIXED[1],
            label: format!("pit, never ground: {} core points", count(1)),
        },
        Class {
            colour: FIXED[PLANNED],
            label: format!(
                "planned: {} core points, {:.2} mm²",
                reach.planned.0, reach.planned.1
            ),
        },
    ];
    classes.extend(reach.rules.iter().enumerate().map(|(k, r)| Class {
        colour: RULE_COLOURS[k % RULE_COLOURS.len()],
        label: format!(
            "left out, {}: {} path points refused, {} core points, {:.2} mm²",
            r.rule, r.path_points, r.core_points, r.area_mm2
        ),
    }));
    let repairable: f64 = (inspection.regions.iter())
        .filter(|r| r.repairable)
        .map(|r| r.area)
        .sum();
    let map = CoverageMap {
        class: reach.class.clone(),
        classes,
        first_shown: RULE0,
        caption: format!(
            "coverage map: {:.2} of {repairable:.2} mm² of repairable area planned \
             (within the footprint of a planned stroke); what is left out in the colour of \
             the rule that refused it",
            reach.planned.1
        ),
    };
    let rows = (reach.rules.iter())
        .map(|r| {
            vec![
                r.rule.clone(),
                r.path_points.to_string(),
                r.core_points.to_string(),
                format!("{:.2}", r.area_mm2),
            ]
        })
        .collect();
    let header = [
        "rule",
        "path points refused",
        "core points left out",
        "area mm²",
    ];
    let table = Table {
        title: "left out by rule (plan.json's unreachable list)".into(),
        header: header.iter().map(|s| s.to_string()).collect(),
        rows,
    };
    (map, table)
}

/// Merges a later piece's `more` rows into `rows`: per core point the lower prediction.
fn lowest_of(rows: &mut Vec<(usize, f64, f64)>, more: Vec<(usize, f64, f64)>) {
    for m in more {
        match rows.iter_mut().find(|r| r.0 == m.0) {
            Some(r) if m.1 < r.1 => *r = m,
            Some(_) => {}
            None => rows.push(m),
        }
    }
}

/// Per predicted region its rows (predicted.csv's, in the order of plan.json's
/// `removal.regions`, `core_points` each) as (core point index, predicted after, low
/// quantile: the prediction less the Monte Carlo's spread); empty when the rows do not add
/// up to the regions' counts (a plan read back from plan.json has no rows).
fn predicted(plan: &Plan, inspection: &Inspection) -> Vec<PredictedRegion> {
    let Some(rem) = &plan.removal else {
        return Vec::new();
    };
    let total: usize = rem.regions.iter().map(|r| r.core_points).sum();
    if total != rem.rows.len() || total == 0 {
        return Vec::new();
    }
    let positions: Vec<Point3<f64>> = inspection.points.iter().map(|p| p.position).collect();
    let index = Neighbours::new(&positions);
    let mut start = 0;
    let mut out = Vec::new();
    for r in &rem.regions {
        let rows = &rem.rows[start..start + r.core_points];
        start += r.core_points;
        let matched = (rows.iter())
            .filter_map(|row| {
                let nb = index.nearest(&Point3::from(row.position))?;
                (nb.dist2 <= SAME_POINT_MM * SAME_POINT_MM).then_some((
                    nb.index,
                    row.residual,
                    row.residual - row.spread_p95,
                ))
            })
            .collect();
        // a region split by table angle has an entry per piece, each piece planned on the
        // part as the earlier ones leave it: a point's prediction is its lowest
        match out.iter_mut().find(|(id, _)| *id == r.region) {
            Some((_, rows)) => lowest_of(rows, matched),
            None => out.push((r.region, matched)),
        }
    }
    out
}

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
    let reach = plan_reach::reach(plan, inspection);
    let (map, rules) = coverage(&reach, inspection);
    let mut all_tables = tables(plan);
    all_tables.insert(0, rules);
    all_tables.insert(1, reach.table.clone());
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
            tables: all_tables,
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
        coverage: Some(map),
        predicted: predicted(plan, inspection),
    };
    plan_page::write_plan_page(&html, &page, &ReportConfig::default())?;
    plan_page::link_report(&report, report_page, &inspection.dir, &html);
    Ok(html)
}

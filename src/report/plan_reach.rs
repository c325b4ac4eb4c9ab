//! What plan.html says about the part the plan leaves out (issue 51, "say what would reach
//! the rest"): every core point of the inspection classed as conform, pit, planned (within the
//! footprint of a planned stroke, as plan.json's `coverage_of_all` counts it) or left out by
//! the rule that refused the nearest left-out contact of its region (plan.json's unreachable
//! list); the rules with their counts, and per left-out region and rule the area, the strokes
//! and the best alternative the plan tried (the turntable's angles, `turntable.regions[].tried`).
//! Reads only what the plan already holds.
use std::collections::BTreeMap;

use nalgebra::Point3;

use super::Table;
use crate::motion::Plan;
use crate::repair::Inspection;
use crate::spatial::Neighbours;

/// Class of a core point outside every region (or in none the plan knows): conform.
pub const CONFORM: usize = 0;
/// Class of a core point of a pit (not repairable: never ground).
pub const PIT: usize = 1;
/// Class of a core point within the footprint of a planned stroke.
pub const PLANNED: usize = 2;
/// First class of a rule: class `RULE0 + k` is left out by `PlanCoverage::rules[k]`.
pub const RULE0: usize = 3;
/// The rule of a repairable region's point that no planned stroke covers and for which
/// plan.json lists no refused contact of its region (a rim the removal planner lifts over, a
/// region it found nothing to remove from).
pub const UNSTATED: &str = "not covered, no contact of its region refused";
/// Step of the densified stroke polylines, as a share of the footprint (0.05, as
/// `motion::check::region_report` densifies them for `coverage_of_all`).
const DENSIFY_SHARE: f64 = 0.05;

/// A rule that refused contacts, with what it left out.
#[derive(Debug, Clone, PartialEq)]
pub struct RuleCount {
    /// The rule: the reason's words before its first number, colon or bracket.
    pub rule: String,
    /// Contact (path) points plan.json lists as refused by it.
    pub path_points: usize,
    /// Core points it leaves out.
    pub core_points: usize,
    /// Area it leaves out, mm² (core points times their region's area per point).
    pub area_mm2: f64,
}

/// The coverage of the part by the plan.
#[derive(Debug, Clone)]
pub struct PlanCoverage {
    /// Class per core point ([`CONFORM`], [`PIT`], [`PLANNED`], `RULE0 + k`).
    pub class: Vec<usize>,
    /// The rules, most path points first ([`UNSTATED`] last when present).
    pub rules: Vec<RuleCount>,
    /// Planned core points and their area, mm².
    pub planned: (usize, f64),
    /// The left-out regions and strokes, one row per region and rule.
    pub table: Table,
}

/// The rule of a reason: its words before the first number, colon or bracket.
pub fn rule_of(reason: &str) -> String {
    reason
        .split(|c: char| c.is_ascii_digit() || c == ':' || c == '(')
        .next()
        .unwrap_or("")
        .trim()
        .to_string()
}

/// The planned strokes of region `id` (where their patches land, `PlannedPoint::landing`)
/// as points at most `DENSIFY_SHARE` footprints apart.
fn dense_strokes(plan: &Plan, id: usize) -> Vec<Point3<f64>> {
    let step = (plan.footprint_mm * DENSIFY_SHARE).max(1e-3);
    let mut dense = Vec::new();
    for pass in plan.passes.iter().filter(|p| p.region == id) {
        let pts: Vec<Point3<f64>> = pass.points.iter().map(|p| p.landing().into()).collect();
        dense.extend(pts.first());
        for w in pts.windows(2) {
            let n = ((w[1] - w[0]).norm() / step).ceil().max(1.0) as usize;
            dense.extend((1..=n).map(|k| w[0] + (w[1] - w[0]) * (k as f64 / n as f64)));
        }
    }
    dense
}

/// Classes the inspection's core points by `plan` and tabulates what is left out.
pub fn reach(plan: &Plan, inspection: &Inspection) -> PlanCoverage {
    let mut names: Vec<String> = Vec::new();
    let mut path_points: BTreeMap<String, usize> = BTreeMap::new();
    for u in &plan.reachability.unreachable {
        *path_points.entry(rule_of(&u.reason)).or_insert(0) += 1;
    }
    let mut class = vec![CONFORM; inspection.points.len()];
    // (region, rule name) -> (core points, area, strokes)
    let mut left: BTreeMap<(usize, String), (usize, f64, usize)> = BTreeMap::new();
    let mut planned = (0, 0.0);
    for region in &inspection.regions {
        let members = inspection.region_points(region.id);
        let per_point = region.area / members.len().max(1) as f64;
        if !region.repairable {
            members.iter().for_each(|&i| class[i] = PIT);
            continue;
        }
        let strokes = Neighbours::new(&dense_strokes(plan, region.id));
        let refused: Vec<_> = (plan.reachability.unreachable.iter())
            .filter(|u| u.region == region.id)
            .collect();
        let at: Vec<Point3<f64>> = refused.iter().map(|u| u.surface_mm.into()).collect();
        let lost = Neighbours::new(&at);
        for &i in &members {
            let p = &inspection.points[i].position;
            let near = |n: &Neighbours| n.nearest(p).map(|nb| (nb.index, nb.dist2.sqrt()));
            if near(&strokes).is_some_and(|(_, d)| d <= plan.footprint_mm) {
                class[i] = PLANNED;
                planned.0 += 1;
                planned.1 += per_point;
                continue;
            }
            let rule =
                near(&lost).map_or(UNSTATED.to_string(), |(k, _)| rule_of(&refused[k].reason));
            let k = names.iter().position(|n| *n == rule).unwrap_or_else(|| {
                names.push(rule.clone());
                names.len() - 1
            });
            class[i] = RULE0 + k;
            let strokes = refused
                .iter()
                .filter(|u| rule_of(&u.reason) == rule)
                .map(|u| (u.layer, u.stroke))
                .collect::<std::collections::BTreeSet<_>>()
                .len();
            let e = left.entry((region.id, rule)).or_insert((0, 0.0, strokes));
            e.0 += 1;
            e.1 += per_point;
        }
    }
    // rules with refused contacts but no core point left out (a stroke left out where its
    // neighbours still cover the region) are listed too
    for name in path_points.keys() {
        if !names.contains(name) {
            names.push(name.clone());
        }
    }
    let mut rules: Vec<RuleCount> = names
        .iter()
        .map(|n| {
            let own = left.iter().filter(|((_, r), _)| r == n);
            let (core_points, area_mm2) = own.fold((0, 0.0), |a, (_, v)| (a.0 + v.0, a.1 + v.1));
            RuleCount {
                rule: n.clone(),
                path_points: path_points.get(n).copied().unwrap_or(0),
                core_points,
                area_mm2,
            }
        })
        .collect();
    // most path points first, the unstated rule last; classes follow the new order
    let mut order: Vec<usize> = (0..rules.len()).collect();
    order.sort_by_key(|&k| {
        (
            rules[k].rule == UNSTATED,
            std::cmp::Reverse(rules[k].path_points),
        )
    });
    let mut new_of = vec![0; rules.len()];
    order
        .iter()
        .enumerate()
        .for_each(|(new, &old)| new_of[old] = new);
    class
        .iter_mut()
        .filter(|c| **c >= RULE0)
        .for_each(|c| *c = RULE0 + new_of[*c - RULE0]);
    rules = order.iter().map(|&k| rules[k].clone()).collect();
    PlanCoverage {
        class,
        rules,
        planned,
        table: left_table(plan, &left),
    }
}

/// The table of left-out regions: per region and rule the area, the core points, the strokes
/// with a refused contact, and the best alternative the plan tried.
fn left_table(plan: &Plan, left: &BTreeMap<(usize, String), (usize, f64, usize)>) -> Table {
    let rows = left
        .iter()
        .map(|((region, rule), (points, area, strokes))| {
            vec![
                region.to_string(),
                format!("{area:.2}"),
                points.to_string(),
                strokes.to_string(),
                rule.clone(),
                best_tried(tool_plan(plan, *region), *region) + &tools_tried(plan, *region),
            ]
        })
        .collect();
    let header = [
        "region",
        "area left out mm²",
        "core points",
        "strokes refused",
        "rule that refused it",
        "best alternative tried",
    ];
    Table {
        title: "left out: regions and strokes the plan does not grind".into(),
        header: header.iter().map(|s| s.to_string()).collect(),
        rows,
    }
}

/// The plan of the library tool `region` is ground with (the plan itself without a library
/// or for its first tool): the one holding the region's table angles.
fn tool_plan(plan: &Plan, region: usize) -> &Plan {
    let holds = |p: &&Plan| p.reachability.regions.iter().any(|r| r.id == region);
    (plan.tools.iter().skip(1))
        .filter(|t| t.regions.contains(&region))
        .find_map(|t| t.plan.as_deref().filter(holds))
        .unwrap_or(plan)
}

/// The tools of the library tried on `region` besides its own, each with what it covered
/// and why not more (empty in a plan without a tool library).
fn tools_tried(plan: &Plan, region: usize) -> String {
    let own = plan.tools.iter().find(|t| t.regions.contains(&region));
    let tried: Vec<String> = (plan.tools.iter())
        .filter_map(|t| {
            let x = t.tried.iter().find(|x| x.region == region)?;
            let why = x
                .refused
                .as_deref()
                .map_or(String::new(), |w| format!(", refused: {w}"));
            Some(format!(
                "tool `{}` (ball {:.1} mm): {:.0} % covered{why}",
                t.tool,
                t.ball_radius_mm,
                100.0 * x.coverage
            ))
        })
        .collect();
    match (own, tried.is_empty()) {
        (None, true) => String::new(),
        (Some(t), true) => format!("; ground with tool `{}`, no other tool tried", t.tool),
        (own, false) => format!(
            "; ground with {}; other tools: {}",
            own.map_or("no tool".to_string(), |t| format!("tool `{}`", t.tool)),
            tried.join("; ")
        ),
    }
}

/// The best other table angle the plan tried for `region`, with what it covered or why it
/// was refused; or what the plan tried when it had nothing else.
fn best_tried(plan: &Plan, region: usize) -> String {
    let Some(table) = &plan.turntable else {
        return "none: the cell has no turntable (one mounting, one arm pose per contact)".into();
    };
    let Some(r) = table.regions.iter().find(|r| r.region == region) else {
        return "none: the region was not grouped on the table".into();
    };
    let others: Vec<_> = (r.tried.iter())
        .filter(|t| (t.angle_deg - r.angle_deg).abs() > 1e-9)
        .collect();
    // the first of the best covered (the angles are tried nearest the planned one first)
    let best = (others.iter()).fold(
        None,
        |best: Option<&&crate::motion::table_file::TriedAngle>, t| match best {
            Some(b) if b.coverage >= t.coverage => Some(b),
            _ => Some(t),
        },
    );
    let planned = format!(
        "planned at table {:.0}° ({:.0} % reachable), {} other angles tried",
        r.angle_deg,
        100.0 * r.reachable_share,
        others.len()
    );
    match best {
        None => format!("{planned}; no other angle tried"),
        Some(t) => match &t.refused {
            Some(why) => format!(
                "{planned}; best other: table {:.0}°, {:.0} % covered, refused: {why}",
                t.angle_deg,
                100.0 * t.coverage
            ),
            None => format!(
                "{planned}; best other: table {:.0}°, {:.0} % covered",
                t.angle_deg,
                100.0 * t.coverage
            ),
        },
    }
}

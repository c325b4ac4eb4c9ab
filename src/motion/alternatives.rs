//! Regions over alternatives (issue 51): the rule shared by the setups of a cell
//! (`setups`) and the tools of its library (`tools`). Every region is planned with the first
//! alternative; a region it leaves short of the table planner's good coverage (or refuses)
//! goes to the next alternative that covers more of it, and the first is planned again
//! without the regions that left. Each alternative past the first keeps its own plan; each
//! records the regions it tried and did not take, with its coverage and the reason.
//!
//! Front function: [`assign`].
use std::collections::BTreeMap;

use super::error::PlanError;
use super::file::{Plan, TriedSetup};
use super::report::RegionReport;
use super::table::{coverage, first_clause, GOOD_COVERAGE};
use crate::repair::{Inspection, RegionInfo};

/// A coverage gain below this counts as none (a region moves to a later alternative only when
/// that covers more of it).
const GAIN_EPS: f64 = 1e-9;

/// What one alternative took.
#[derive(Debug, Clone, Default)]
pub struct Taken {
    /// Regions planned with it.
    pub regions: Vec<usize>,
    /// Regions tried with it and left where they were.
    pub tried: Vec<TriedSetup>,
    /// Its plan (from the second alternative on; the first's is the plan [`assign`] returns).
    pub plan: Option<Box<Plan>>,
}

/// A planner of `inspection`'s regions with alternative `k` (0 first).
pub type PlanWith<'a> = dyn Fn(usize, &Inspection) -> Result<Plan, PlanError> + 'a;

/// `inspection` with the regions `keep` accepts.
fn only(inspection: &Inspection, keep: impl Fn(usize) -> bool) -> Inspection {
    let mut part = inspection.clone();
    part.regions.retain(|r| keep(r.id));
    part
}

/// Plans `inspection` over `count` alternatives (`plan_with`; one: exactly its plan with
/// alternative 0) for the regions `eligible` accepts; returns the first alternative's plan and
/// what each took. Reports are not merged ([`merge_reports`]).
pub fn assign(
    inspection: &Inspection,
    count: usize,
    eligible: &dyn Fn(&RegionInfo) -> bool,
    plan_with: &PlanWith,
) -> Result<(Plan, Vec<Taken>), PlanError> {
    let whole = plan_with(0, inspection)?;
    let mut taken = vec![Taken::default(); count.max(1)];
    if count <= 1 {
        taken[0].regions = whole.reachability.planned_ids();
        return Ok((whole, taken));
    }
    // best coverage so far per planned region, and the alternative holding it
    let mut best: BTreeMap<usize, (usize, f64)> = inspection
        .regions
        .iter()
        .filter(|r| eligible(r))
        .map(|r| (r.id, (0, coverage(Some(&whole), r.id))))
        .collect();
    for (k, took) in taken.iter_mut().enumerate().skip(1) {
        let short: Vec<usize> = best
            .iter()
            .filter(|(_, &(s, c))| s == 0 && c < GOOD_COVERAGE)
            .map(|(&id, _)| id)
            .collect();
        if short.is_empty() {
            break;
        }
        let trial = plan_with(k, &only(inspection, |id| short.contains(&id)));
        let moved = judge(&trial, &short, &mut best, k, &mut took.tried);
        if moved.is_empty() {
            continue;
        }
        let sub = match (trial, moved.len() == short.len()) {
            (Ok(p), true) => p,
            _ => plan_with(k, &only(inspection, |id| moved.contains(&id)))?,
        };
        took.regions = moved;
        took.plan = Some(Box::new(sub));
    }
    let moved: Vec<usize> = best
        .iter()
        .filter(|(_, &(s, _))| s > 0)
        .map(|(&id, _)| id)
        .collect();
    let top = match moved.is_empty() {
        true => None,
        false => Some(plan_with(0, &only(inspection, |id| !moved.contains(&id)))?),
    };
    // regions planned again apart can come out covered less than together (the removal
    // planner's lift-overs, the table angles a group shares): the alternatives are kept only
    // when they plan more of the repairable area than the first alternative alone
    let kept = top.filter(|t| planned_area(t, &taken) + AREA_EPS_MM2 >= planned_area(&whole, &[]));
    if let Some(top) = kept {
        taken[0].regions = top.reachability.planned_ids();
        return Ok((top, taken));
    }
    for t in taken.iter_mut().skip(1) {
        let plan = t.plan.take();
        t.tried.extend(t.regions.drain(..).map(|id| TriedSetup {
            region: id,
            coverage: coverage(plan.as_deref(), id),
            refused: Some(GAVE_BACK.into()),
        }));
    }
    taken[0].regions = whole.reachability.planned_ids();
    Ok((whole, taken))
}

/// Why a region an alternative took went back to the first (its plan over the alternatives
/// planned less of the repairable area than the first alternative's alone).
const GAVE_BACK: &str =
    "the plan over the alternatives planned less of the area than the first alone";

/// Planned area below which two plans count as planning the same, mm^2 (a hundredth of a
/// square millimetre: sums of the same reports in another order).
const AREA_EPS_MM2: f64 = 1e-2;

/// The repairable area `top` (the first alternative's plan) and the plans of `taken` (from
/// the second on, each for the regions it took) plan, mm^2: per region its area times its
/// coverage (`coverage_of_all`).
fn planned_area(top: &Plan, taken: &[Taken]) -> f64 {
    let sum = |p: &Plan, keep: &dyn Fn(usize) -> bool| -> f64 {
        (p.reachability.regions.iter())
            .filter(|r| r.repairable && keep(r.id))
            .map(|r| r.coverage_of_all * r.area_mm2)
            .sum()
    };
    let further: f64 = (taken.iter().skip(1))
        .filter_map(|t| {
            t.plan
                .as_deref()
                .map(|p| sum(p, &|id| t.regions.contains(&id)))
        })
        .sum();
    sum(top, &|_| true) + further
}

/// Which of the `short` regions alternative `k`'s `trial` plan covers better than `best`
/// (updated to it); the others go into `tried` with the trial's coverage and reason.
fn judge(
    trial: &Result<Plan, PlanError>,
    short: &[usize],
    best: &mut BTreeMap<usize, (usize, f64)>,
    k: usize,
    tried: &mut Vec<TriedSetup>,
) -> Vec<usize> {
    let mut moved = Vec::new();
    for &id in short {
        let had = best.get(&id).map_or(0.0, |b| b.1);
        let (c, why) = match trial {
            Err(e) => (0.0, Some(first_clause(&e.to_string()))),
            Ok(p) => {
                let c = coverage(Some(p), id);
                let why = p
                    .reachability
                    .unreachable
                    .iter()
                    .find(|u| u.region == id)
                    .map(|u| first_clause(&u.reason));
                (c, why)
            }
        };
        if c > had + GAIN_EPS {
            best.insert(id, (k, c));
            moved.push(id);
        } else {
            let refused = why.or_else(|| {
                Some(format!(
                    "covers {:.1} % of it, no more than before",
                    100.0 * c
                ))
            });
            tried.push(TriedSetup {
                region: id,
                coverage: c,
                refused,
            });
        }
    }
    moved
}

/// The first alternative's plan `top` reports every region: each region planned with
/// alternative `k` is marked by `mark(report, k)`, and the reports (and points left out) of
/// the regions that moved come from their alternative's plan, in regions.json order.
pub fn merge_reports(
    top: &mut Plan,
    taken: &[Taken],
    inspection: &Inspection,
    mark: &dyn Fn(&mut RegionReport, usize),
) {
    for r in &mut top.reachability.regions {
        mark(r, 0);
    }
    for (k, part) in taken.iter().enumerate().skip(1) {
        let Some(sub) = &part.plan else { continue };
        let of = |id: usize| part.regions.contains(&id);
        for r in sub.reachability.regions.iter().filter(|r| of(r.id)) {
            let mut r = r.clone();
            mark(&mut r, k);
            top.reachability.regions.retain(|x| x.id != r.id);
            top.reachability.regions.push(r);
        }
        let left = sub.reachability.unreachable.iter().filter(|u| of(u.region));
        top.reachability.unreachable.extend(left.cloned());
    }
    let order = |id: usize| inspection.regions.iter().position(|r| r.id == id);
    top.reachability.regions.sort_by_key(|r| order(r.id));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::report::{Metrics, Reachability};

    /// A region of `area` mm^2 (repairable).
    fn region(id: usize, area: f64) -> RegionInfo {
        RegionInfo {
            id,
            centroid: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            area,
            peak: 0.2,
            peak_lower_bound: false,
            mean: 0.1,
            volume: 1.0,
            points: 10,
            repairable: true,
            measured_share: 1.0,
            touches_unmeasured: false,
        }
    }

    /// A plan reporting each of `inspection`'s regions covered as `cover` says.
    fn plan(inspection: &Inspection, cover: impl Fn(usize) -> f64) -> Plan {
        let report = |r: &RegionInfo| RegionReport {
            id: r.id,
            repairable: true,
            peak_mm: r.peak,
            peak_lower_bound: false,
            touches_unmeasured: false,
            area_mm2: r.area,
            layers: 1,
            path_points: 10,
            unreachable_path_points: 0,
            points: 10,
            reachable_points: 10,
            unreachable_share: 0.0,
            coverage_of_reachable: cover(r.id),
            coverage_of_all: cover(r.id),
            setup: None,
            tool: None,
        };
        Plan {
            format: "polishbot-plan".into(),
            version: 1,
            inspection: String::new(),
            period: 0.02,
            joint_names: Vec::new(),
            tool_radius_mm: 3.0,
            stepover_mm: 0.3,
            footprint_mm: 0.6,
            predicted_duration_s: 0.0,
            passes: Vec::new(),
            segments: Vec::new(),
            samples: Vec::new(),
            frames: Vec::new(),
            commands: None,
            compensation: None,
            reachability: Reachability {
                regions: inspection.regions.iter().map(report).collect(),
                ..Reachability::default()
            },
            metrics: Metrics::default(),
            strokes: None,
            removal: None,
            turntable: None,
            setups: Vec::new(),
            tools: Vec::new(),
        }
    }

    /// Two regions short in the first alternative: the second covers region 1 better when
    /// tried with both, but planned again for it alone covers less of it, and the first
    /// planned again without region 1 covers region 0 less: over the alternatives the plan
    /// would plan less of the area than the first alone, which it keeps. Where the plans
    /// apart cover as much as together, region 1 moves.
    #[test]
    fn alternatives_are_kept_only_when_they_plan_more_area() {
        let inspection = Inspection {
            dir: ".".into(),
            tolerance: Some(0.05),
            regions: vec![region(0, 100.0), region(1, 20.0)],
            points: Vec::new(),
            fine: Vec::new(),
        };
        for (alone_gain, moves) in [(false, false), (true, true)] {
            let plan_with = |k: usize, part: &Inspection| -> Result<Plan, PlanError> {
                let both = part.regions.len() == 2;
                Ok(plan(part, |id| match (k, id, both) {
                    (0, 0, true) => 0.9,
                    (0, 0, false) if alone_gain => 0.9,
                    (0, 0, false) => 0.7,
                    (0, 1, _) => 0.5,
                    (_, 1, true) => 0.8,
                    (_, 1, false) if alone_gain => 0.8,
                    (_, 1, false) => 0.1,
                    _ => 0.0,
                }))
            };
            let (top, taken) = assign(&inspection, 2, &|_| true, &plan_with).unwrap();
            let ids: Vec<usize> = top.reachability.regions.iter().map(|r| r.id).collect();
            if moves {
                assert_eq!(taken[1].regions, vec![1]);
                assert_eq!(ids, vec![0]);
            } else {
                assert!(taken[1].regions.is_empty() && taken[1].plan.is_none());
                assert_eq!(ids, vec![0, 1]);
                assert!(taken[1].tried.iter().any(|t| t.region == 1));
            }
        }
    }
}

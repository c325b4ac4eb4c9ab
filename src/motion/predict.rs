//! The part predicted after a removal plan: the time the trajectory really spends on each
//! piece (its presses counted), the removal that makes at every core point in reach, the
//! residual's spread by Monte Carlo and the verdict per region (over-grind at the quantile
//! beyond the tolerance). A region can be checked alone before the program is assembled
//! ([`rehearse`]: its chains pressed in, ground and pressed out as `assemble` splices them),
//! so that a failing region is solved again without assembling the whole program; the
//! assembled program's prediction reuses a region's verdict when it grinds the region exactly
//! as rehearsed. Method: docs/ALGORITHMS.md, "Removal planning".
use std::collections::HashMap;

use nalgebra::{DMatrix, Matrix3, Point3, Vector3};

use super::dwell::{
    cores_landed, cores_near, placed_contacts, pressed_contacts, reference_from_robot, Setup,
};
use super::error::PlanError;
use super::free_motion::{pressed, Assembly};
use super::landing::landing_margins;
use super::program::{PlannedPass, PlannedPoint, Program, Run, Segment, SegmentKind};
use super::trajectory::{JointTrajectory, Move};
use crate::removal::montecarlo::{spread, JointError};
use crate::removal::prediction::{DwellPoint, PredictedRow, RegionPrediction, RemovalReport};
use crate::removal::{self, Influence, Stats};
use crate::repair::Inspection;
use crate::repair::SurfacePoint;
use crate::robot::units::mm;
use crate::robot::{Robot, Workcell};

/// One region's prediction: its report entry and predicted.csv rows, or why it over-grinds.
type Verdict = Result<(RegionPrediction, Vec<PredictedRow>), String>;

/// Largest relative difference between a region's dwell as rehearsed and as assembled for
/// the rehearsal's Monte Carlo to stand for the program's (1e-9): the rehearsal presses in from
/// the exact touching pose, the program from the last sample of its approach, which Ruckig
/// ends within rounding (about 1e-16 rad) of it; a chain left out or ground differently
/// changes the dwell by far more.
const SAME_DWELL_REL: f64 = 1e-9;

/// The Monte Carlo's low quantile and median of the residual per core point, mm.
#[derive(Clone)]
struct Quantiles {
    low: Vec<f64>,
    median: Vec<f64>,
}

/// A region's Monte Carlo and what it was computed from (the pieces' points and dwell).
pub(crate) struct Checked {
    points: Vec<[f64; 3]>,
    dwell: Vec<f64>,
    quantiles: Quantiles,
}

/// Whether two dwell maps are the same up to `SAME_DWELL_REL`.
fn same_dwell(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= SAME_DWELL_REL * x.abs().max(y.abs()))
}

/// The verdicts of the regions checked before assembling, by region id.
pub(crate) type Rehearsed = HashMap<usize, Checked>;

/// The surface points of `pieces`, in order: what identifies how a region is ground.
fn points_of(pieces: &[&PlannedPass]) -> Vec<[f64; 3]> {
    pieces
        .iter()
        .flat_map(|p| p.points.iter().map(|q| q.surface_mm))
        .collect()
}

/// Dwell-equivalent of the press segments per pass index, s: a press moves the ball between
/// touching the surface and the preload, and Preston's removal summed over the contact patch
/// is `k F v` (linear in the force, F = rate x depth), so each bus period of a press counts
/// as `period x depth / preload` of dwell (trapezoid over its samples) at the contact it
/// presses into (the next grinding piece) or out of (the previous one); the depth runs up to
/// the contact's own commanded depth (its pressed offset: the preload, or less where the
/// force was limited, `press_depth`).
fn press_dwell(prog: &Program, robot: &Robot, wc: &Workcell, preload: f64) -> Vec<f64> {
    let mut out = vec![0.0; prog.passes.len()];
    let segs = &prog.segments;
    for (i, seg) in segs.iter().enumerate() {
        if seg.kind != SegmentKind::Press || preload <= 0.0 {
            continue;
        }
        let grind = |j: Option<usize>| {
            j.and_then(|j| segs.get(j))
                .filter(|s| s.kind == SegmentKind::Grind)
                .and_then(|s| s.pass)
        };
        let (pass, point) = match (grind(Some(i + 1)), grind(i.checked_sub(1))) {
            (Some(p), _) => (p, &prog.passes[p].points[0]),
            (None, Some(p)) => (p, &prog.passes[p].points[prog.passes[p].points.len() - 1]),
            (None, None) => continue,
        };
        let normal = wc.direction_from_reference(&Vector3::from(point.normal));
        let contact = Vector3::from(point.tip_m);
        let deepest = (-point.offset_mm).clamp(0.0, preload);
        let depth = |k: usize| {
            let tip = robot.fk(prog.trajectory.sample(k)).position;
            (deepest - mm((tip - contact).dot(&normal))).clamp(0.0, deepest) / preload
        };
        let shares: Vec<f64> = (seg.first_sample..=seg.last_sample).map(depth).collect();
        let sum: f64 = shares.windows(2).map(|w| 0.5 * (w[0] + w[1])).sum();
        out[pass] += sum * prog.trajectory.period;
    }
    out
}

/// Appends a press (a rest-to-rest joint move to `to`) to a rehearsal program.
fn press(prog: &mut Program, to: &[f64], region: usize, cell: &Assembly) -> Result<(), PlanError> {
    let tc = &cell.cfg.trajectory;
    let from = prog.trajectory.last().to_vec();
    let mv = Move::new(&from, to, &cell.limits, tc).map_err(|source| PlanError::Trajectory {
        context: "press move".into(),
        source,
    })?;
    let first = prog.trajectory.len() - 1;
    let steps = prog.trajectory.append_move(&mv);
    prog.cruise.extend(std::iter::repeat_n(false, steps));
    prog.segments.push(Segment {
        kind: SegmentKind::Press,
        region: Some(region),
        pass: None,
        first_sample: first,
        last_sample: first + steps,
    });
    Ok(())
}

/// One region's dwelled `runs` ground as `assemble` will: each chain pressed in from the pose
/// touching the surface above its first contact, ground without stopping (`grind_chain`) and
/// pressed out to the pose touching above its last; returns the pieces with the time the
/// trajectory spends on each (`dwell_s`) and that time plus the dwell-equivalent of the
/// presses. A chain with no touching pose is left out (as `assemble` leaves it out); a chain
/// whose way in or out is not clear is not known here (the assembled program's prediction
/// decides then).
pub(crate) fn rehearse(
    runs: &[Run],
    cell: &Assembly,
    preload: f64,
) -> Result<(Vec<PlannedPass>, Vec<f64>), PlanError> {
    let (mut pieces, mut dwell) = (Vec::new(), Vec::new());
    for run in runs {
        for chain in super::assemble::chains(run.clone()) {
            let first = chain[0].points[0].clone();
            let end = chain[chain.len() - 1].points.last().cloned();
            let region = chain[0].region;
            // the touching pose above a contact, as `enter` and `retract` find it
            let touch = |p: &PlannedPoint| match pressed(p) > 0.0 {
                true => cell.lifted(p, pressed(p)).into_iter().next(),
                false => Some(p.q.clone()),
            };
            let Some(touch_in) = touch(&first) else {
                continue;
            };
            let mut prog = Program {
                trajectory: JointTrajectory::starting_at(&touch_in, cell.cfg.trajectory.period),
                segments: Vec::new(),
                passes: Vec::new(),
                cruise: vec![false],
                slowed: 0,
            };
            if pressed(&first) > 0.0 {
                press(&mut prog, &first.q, region, cell)?;
            }
            prog.grind_chain(chain, cell.robot, cell.cfg)?;
            let end = end.filter(|p| pressed(p) > 0.0);
            if let Some(out) = end.as_ref().and_then(touch) {
                press(&mut prog, &out, region, cell)?;
            }
            let extra = press_dwell(&prog, cell.robot, cell.wc, preload);
            for (piece, e) in prog.passes.into_iter().zip(extra) {
                dwell.push(piece.dwell_s.unwrap_or(0.0) + e);
                pieces.push(piece);
            }
        }
    }
    Ok((pieces, dwell))
}

/// Checks region `id` ground by `pieces` for `dwell` s each (presses counted): the removal at
/// every core point in reach, before/after statistics, the Monte Carlo's spread (`known`
/// when it was drawn for this dwell already); the verdict is an error (the reason) when the
/// low quantile over-grinds beyond the tolerance. Also returns the quantiles.
fn region_verdict(
    pieces: &[&PlannedPass],
    dwell: &[f64],
    (id, allowance_mm): (usize, f64),
    inspection: &Inspection,
    setup: &Setup,
    known: Option<&Quantiles>,
) -> (Verdict, Quantiles) {
    let (tool, robot, config) = (setup.tool, setup.robot, setup.config);
    let back = reference_from_robot(setup.workcell);
    let ball_mm = robot.tool.radius_mm();
    let influence = Influence::new(tool, ball_mm);
    let tolerance = inspection.tolerance.unwrap_or(config.tolerance_mm);
    let placed = placed_contacts(pieces, setup);
    let contacts = pressed_contacts(&placed, inspection, setup, allowance_mm);
    let (idx, nominal) = verdict_points(inspection, setup, (pieces, &contacts), &influence);
    let cores: Vec<(Point3<f64>, Vector3<f64>, f64)> = idx
        .iter()
        .map(|&i| {
            let p = inspection.points[i];
            let d = if p.distance.is_finite() {
                p.distance
            } else {
                0.0
            };
            (p.position, p.normal, d)
        })
        .collect();
    let geometry: Vec<(Point3<f64>, Vector3<f64>)> = cores.iter().map(|c| (c.0, c.1)).collect();
    let reach = removal::influence::Reach::new(&geometry);
    let a = reach.matrix(&influence, &contacts);
    let linear = removal::influence::apply(&a, dwell, cores.len());
    // the pass as the tool grinds it, contact by contact (`removal::sequence`)
    let surface: Vec<SurfacePoint> = idx.iter().map(|&i| inspection.points[i]).collect();
    let ground = (surface.as_slice(), &reach);
    let removed = removal::sequence::in_order(&placed, dwell, tool, &influence, ground);
    let before: Vec<f64> = cores.iter().map(|c| c.2).collect();
    let after: Vec<f64> = before.iter().zip(&removed).map(|(d, r)| d - r).collect();
    let mc = &config.monte_carlo;
    let quantiles = match known {
        Some(q) => q.clone(),
        None => {
            let joints: Vec<JointError> = pieces
                .iter()
                .map(|p| joint_error(robot, &p.points[0].q, &back))
                .collect();
            let spread = spread(tool, ball_mm, &contacts, &joints, dwell, &cores, mc);
            Quantiles {
                low: spread.low(mc.quantile),
                median: spread.low(0.5),
            }
        }
    };
    // the Monte Carlo draws the linear model: its residuals move by what the pass ground in
    // order leaves of the linear removal
    let in_order = |q: &[f64]| -> Vec<f64> {
        q.iter()
            .zip(linear.iter().zip(&removed))
            .map(|(q, (l, r))| q + l - r)
            .collect()
    };
    let (low, median) = (&in_order(&quantiles.low), &in_order(&quantiles.median));
    if let Some(why) = over_grind(low, &before, tolerance, mc.quantile) {
        return (Err(why), quantiles);
    }
    // the report and predicted.csv keep the core points in reach as predicted
    let pick = |v: &[f64]| -> Vec<f64> {
        (v.iter().zip(&nominal))
            .filter(|p| *p.1)
            .map(|p| *p.0)
            .collect()
    };
    let lowest = pick(low).into_iter().fold(f64::INFINITY, f64::min);
    let rows: Vec<PredictedRow> = idx
        .iter()
        .enumerate()
        .filter(|(k, _)| nominal[*k])
        .map(|(k, &i)| {
            let p = inspection.points[i].position;
            PredictedRow {
                position: [p.x, p.y, p.z],
                deviation: before[k],
                residual: after[k],
                spread_p95: median[k] - low[k],
            }
        })
        .collect();
    let area = inspection
        .regions
        .iter()
        .find(|r| r.id == id)
        .map_or(0.0, |r| {
            r.area / inspection.region_points(id).len().max(1) as f64
        });
    let dwell_map = pieces.iter().zip(&contacts).zip(dwell);
    let prediction = RegionPrediction {
        region: id,
        allowance_mm,
        dwell: dwell_map
            .map(|((p, c), t)| DwellPoint {
                surface_mm: [c.point.x, c.point.y, c.point.z],
                dwell_s: *t,
                feed_mm_s: p.feed_mm_s,
            })
            .collect(),
        core_points: rows.len(),
        before: Stats::of(&pick(&before), tolerance, area),
        after: Stats::of(&pick(&after), tolerance, area),
        after_low_p95_mm: if lowest.is_finite() { lowest } else { 0.0 },
    };
    (Ok((prediction, rows)), quantiles)
}

/// The core points a region's verdict checks (inspection indices, in index order) and which
/// of them are in the nominal reach of `contacts` (`cores_near`, the report's): those in reach
/// of a contact landed anywhere within its landing margin (`dwell::cores_landed`), so that the
/// Monte Carlo's draws are checked at the conform rim the dwell solve guards too.
fn verdict_points(
    inspection: &Inspection,
    setup: &Setup,
    (pieces, contacts): (&[&PlannedPass], &[removal::Contact]),
    influence: &Influence,
) -> (Vec<usize>, Vec<bool>) {
    let near = cores_near(inspection, setup.index, contacts, influence);
    let margin = landing_margins(pieces, contacts, &setup.landing_cell());
    let wide = cores_landed(inspection, setup.index, contacts, influence, &margin);
    let nominal = wide.iter().map(|i| near.binary_search(i).is_ok()).collect();
    (wide, nominal)
}

/// Share of the tolerance a core point already below `-tolerance` before grinding (a pit, or
/// a spot an earlier pass over-ground) may lose at the Monte Carlo's quantile (0.1: 0.005 mm at
/// the default 0.05 mm, a third of the scanner's noise, so it cannot be measured as ground):
/// such a point is below the tolerance whatever the plan does, and the plan may grind a bump
/// around it only as long as it does not deepen it.
const ALREADY_LOW_SHARE: f64 = 0.1;

/// Why the residual's low quantile `low` over-grinds, or None: a core point goes below
/// `-tolerance`, or, when it was below already (`before`), loses more than `ALREADY_LOW_SHARE`
/// of the tolerance. The reason names the worst point's residual and its deviation before.
fn over_grind(low: &[f64], before: &[f64], tolerance: f64, quantile: f64) -> Option<String> {
    let floor = |b: f64| (-tolerance).min(b - ALREADY_LOW_SHARE * tolerance);
    let (k, margin) = low
        .iter()
        .zip(before)
        .map(|(l, b)| l - floor(*b))
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    (margin < 0.0).then(|| {
        format!(
            "region left out by the removal planner: the trajectory's dwell over-grinds to \
             {:.3} mm at the {quantile} quantile (a core point at {:.3} mm before), beyond the \
             tolerance {tolerance} mm",
            low[k], before[k]
        )
    })
}

/// Checks one region before assembling (`rehearse`, `region_verdict`) and keeps the verdict
/// in `rehearsed`; returns the reason when it over-grinds.
pub(crate) fn rehearse_region(
    runs: &[Run],
    (id, allowance): (usize, f64),
    cell: &Assembly,
    inspection: &Inspection,
    setup: &Setup,
    rehearsed: &mut Rehearsed,
) -> Result<Option<String>, PlanError> {
    let (pieces, dwell) = rehearse(runs, cell, setup.tool.preload_mm)?;
    let refs: Vec<&PlannedPass> = pieces.iter().collect();
    let (verdict, quantiles) =
        region_verdict(&refs, &dwell, (id, allowance), inspection, setup, None);
    let points = points_of(&refs);
    rehearsed.insert(
        id,
        Checked {
            points,
            dwell,
            quantiles,
        },
    );
    Ok(verdict.err())
}

/// The part predicted after `prog`, and the regions whose Monte Carlo low quantile
/// over-grinds by more than the tolerance (with the reason; the caller leaves them out): per
/// region, the removal of the time the trajectory spends on each piece actually in the
/// program (its presses counted, `press_dwell`), before/after statistics and the spread. A
/// region ground exactly as `rehearsed` (same points, same dwell) takes that verdict.
pub(crate) fn predict(
    prog: &Program,
    inspection: &Inspection,
    allowances: impl IntoIterator<Item = (usize, f64)>,
    setup: &Setup,
    rehearsed: &Rehearsed,
) -> Result<(RemovalReport, Vec<(usize, String)>), PlanError> {
    let tool = setup.tool;
    let tip = removal::montecarlo::tip_error(tool, &setup.config.monte_carlo);
    let mut report = RemovalReport {
        force_n: tool.force_n(),
        preload_mm: tool.preload_mm,
        tolerance_mm: inspection.tolerance.unwrap_or(setup.config.tolerance_mm),
        tip_error_mm: tip.mm,
        tip_error_source: tip.source,
        regions: Vec::new(),
        rows: Vec::new(),
    };
    let press = press_dwell(prog, setup.robot, setup.workcell, tool.preload_mm);
    let mut failed = Vec::new();
    for (id, allowance) in allowances {
        let (index, pieces): (Vec<usize>, Vec<&PlannedPass>) = prog
            .passes
            .iter()
            .enumerate()
            .filter(|(_, p)| p.region == id)
            .unzip();
        let dwell: Vec<f64> = pieces
            .iter()
            .zip(&index)
            .map(|(p, &i)| p.dwell_s.unwrap_or(0.0) + press[i])
            .collect();
        if pieces.is_empty() {
            // every chain was left out by the assembly (each point recorded with the reason):
            // nothing of the region is ground, so it is not reported as planned
            continue;
        }
        let known = rehearsed
            .get(&id)
            .filter(|c| same_dwell(&c.dwell, &dwell) && c.points == points_of(&pieces))
            .map(|c| &c.quantiles);
        let verdict = region_verdict(&pieces, &dwell, (id, allowance), inspection, setup, known);
        match verdict.0 {
            Ok((prediction, rows)) => {
                report.regions.push(RegionPrediction {
                    allowance_mm: allowance,
                    ..prediction
                });
                report.rows.extend(rows);
            }
            Err(reason) => failed.push((id, reason)),
        }
    }
    Ok((report, failed))
}

/// How the joints of a piece's first pose move the tip (mm/rad, reference frame) and each
/// servo's half raw count (rad), as `robot/resolution.rs` quantises them.
fn joint_error(robot: &Robot, q: &[f64], back: &Matrix3<f64>) -> JointError {
    let jac = robot.jacobian(q);
    let position = mm(jac.rows(0, 3).into_owned());
    let sensitivity: DMatrix<f64> = DMatrix::from_fn(3, robot.dof(), |r, c| {
        (0..3).map(|k| back[(r, k)] * position[(k, c)]).sum()
    });
    let half_count = robot
        .joints
        .iter()
        .map(|joint| {
            robot
                .servos
                .servos
                .iter()
                .find(|s| s.id == joint.servo_id)
                .map_or(0.0, |s| 0.5 / s.counts_per_degree().to_degrees())
        })
        .collect();
    JointError {
        sensitivity,
        half_count,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_already_below_the_tolerance_may_not_be_deepened_beyond_a_tenth_of_it() {
        let tol = 0.05;
        // above the tolerance: -0.049 passes, -0.051 fails
        assert!(over_grind(&[-0.049], &[0.1], tol, 0.05).is_none());
        assert!(over_grind(&[-0.051], &[0.1], tol, 0.05).is_some());
        // already at -0.2 (a pit): may lose 0.005 mm, not 0.006
        assert!(over_grind(&[-0.2049], &[-0.2], tol, 0.05).is_none());
        let why = over_grind(&[0.0, -0.206], &[0.1, -0.2], tol, 0.05).unwrap();
        assert!(why.contains("-0.206") && why.contains("-0.200"), "{why}");
    }
}

//! Room for the compliance correction at every contact (issue 50, "compensate what repeats"):
//! when the plan compensates the arm's compliance, a stroke whose joints come nearer their
//! limits than the correction needs is solved again at another in-plane tilt of its tool axis
//! (one tilt for the whole stroke, within the axis cone around the normal, the ball's roll
//! left free), the tilt nearest the one the stroke had, with every joint at least
//! [`LIMIT_MARGIN_RAD`] inside its limits. A stroke no tilt gives that margin keeps its
//! answer; the compensation then carries only the share of its correction that fits
//! (`compensate::commands`). Method: docs/ALGORITHMS.md, "Compliance compensation".
use super::program::{in_plane, plane_frames, Resolved, Restroke, Solved};
use super::PlanConfig;
use crate::robot::IkTarget;
use crate::robot::Robot;
use nalgebra::Vector3;

/// How far inside its limits every joint of a grinding contact is kept when the plan
/// compensates, rad (0.05, 2.9 degrees): the largest correction the model makes on the
/// documented arm is 0.024 rad (measured on the demo-like part, the wrist pitch: half a 0.5
/// degree gear band, 0.0044 rad, the bending of the arm's weight and the 2 N contact force on
/// 110-120 N m/rad joints, and the absorbed workcell offset), the smoothing holds a
/// neighbouring contact's correction over the press and approach, and the IK's own
/// `limit_margin` (0.01 rad) keeps the splines between contacts inside; 0.05 leaves the
/// correction room twice over.
pub const LIMIT_MARGIN_RAD: f64 = 0.05;

/// Steps of the tilt search, rad (1 degree: a stroke's joints move under 0.02 rad a step, so
/// a tilt with margin is not stepped over where the margin holds over a degree or more).
const TILT_STEP_RAD: f64 = 0.017_453_292_519_943_295;

/// The margin the plan keeps for the compensation: [`LIMIT_MARGIN_RAD`] when `cfg`
/// compensates and `robot` has a `[compliance]` table, else None (the plan is planned as
/// without compensation).
pub fn wanted(robot: &Robot, cfg: &PlanConfig) -> Option<f64> {
    (cfg.compensate_compliance && robot.servos.compliance.is_some()).then_some(LIMIT_MARGIN_RAD)
}

/// The least distance of any joint of the solved points from its limits, rad (infinite when
/// none is solved).
pub fn least_margin(robot: &Robot, solved: &[Solved]) -> f64 {
    solved
        .iter()
        .filter_map(|s| s.as_ref().ok())
        .flat_map(|(q, _)| {
            q.iter()
                .zip(&robot.joints)
                .map(|(v, j)| (v - j.lower).min(j.upper - v))
        })
        .fold(f64::INFINITY, f64::min)
}

/// The stroke `s` with every joint `margin` inside its limits: `chosen` (its tilt, rad, and
/// answers; None: the first answers, untilted) when it already is, else the stroke solved
/// again at the tilt nearest `chosen`'s that gives the margin, keeps every point reached
/// before, and holds the tool at least as far from each normal as `chosen` did up to
/// `min_tilt` (removal mode's hold); `chosen` when no tilt within the axis cone does.
pub fn keep(
    s: &Restroke,
    chosen: Option<(f64, Resolved)>,
    min_tilt: Option<f64>,
    margin: f64,
) -> Option<(f64, Resolved)> {
    let (from, solved) = match &chosen {
        Some((d, (out, _))) => (*d, out.as_slice()),
        None => (0.0, s.first),
    };
    if least_margin(s.robot, solved) >= margin {
        return chosen;
    }
    let frames = plane_frames(s);
    // each point's angle between the tool axis and its inward normal at tilt d
    let nearest_normal = |d: f64| {
        frames
            .iter()
            .map(|(a, b)| (a * d.cos() + b * d.sin()).clamp(-1.0, 1.0).acos())
            .fold(f64::INFINITY, f64::min)
    };
    let need = min_tilt.map(|m| m.min(nearest_normal(from)) - 1e-9);
    let max = s.cfg.ik.max_axis_miss_deg.to_radians();
    let steps = (max / TILT_STEP_RAD).floor() as i64;
    let mut tilts: Vec<f64> = (-steps..=steps)
        .map(|k| from + k as f64 * TILT_STEP_RAD)
        .filter(|d| d.abs() <= max)
        .collect();
    tilts.sort_by(|a, b| (a - from).abs().total_cmp(&(b - from).abs()));
    let reached = solved.iter().filter(|r| r.is_ok()).count();
    tilts
        .into_iter()
        .filter(|&d| need.is_none_or(|m| nearest_normal(d) >= m))
        .find_map(|d| {
            let r = solve_tilted(s, d, margin)?;
            let ok = r.0.iter().filter(|x| x.is_ok()).count() >= reached
                && least_margin(s.robot, &r.0) >= margin - 1e-9;
            ok.then_some((d, r))
        })
        .or(chosen)
}

/// The stroke `s` solved again with every solved point of its first answers tilted by `delta`
/// rad in the arm plane (exact IK, chained from its start, every joint `margin` rad inside its
/// limits): the answers and the last pose, or None when a point becomes unreachable or its
/// axis leaves the cone of its requested axis or normal.
pub(super) fn solve_tilted(s: &Restroke, delta: f64, margin: f64) -> Option<Resolved> {
    let (robot, cfg) = (s.robot, s.cfg);
    let exact = crate::robot::IkConfig {
        axis_search: false,
        limit_margin: margin,
        ..cfg.ik.clone()
    };
    let max = cfg.ik.max_axis_miss_deg;
    let mut again = s.start.to_vec();
    let mut out = Vec::with_capacity(s.targets.len());
    for ((t, f), n) in s.targets.iter().zip(s.first).zip(s.normals) {
        let Ok((q0, _)) = f else {
            out.push(f.clone());
            continue;
        };
        let (plane, requested) = in_plane(robot, q0, &t.axis);
        let axis = requested * delta.cos() + plane.cross(&requested) * delta.sin();
        let miss = |to: &Vector3<f64>| crate::robot::angle_between(to, &axis).to_degrees();
        if miss(&t.axis) > max || miss(&-n) > max {
            return None;
        }
        let sol = robot.ik(&IkTarget { axis, ..*t }, &again, &exact).ok()?;
        again.clone_from(&sol.q);
        out.push(Ok((sol.q, axis)));
    }
    Some((out, again))
}

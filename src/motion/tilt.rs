//! Solving a stroke: each target by IK, then the whole stroke again at one in-plane tilt of
//! its tool axis (removal mode's hold off the normal, or the largest tilt reach needed), and
//! room for the compliance correction at every contact.
//!
//! Room for the compliance correction at every contact (issue 50, "compensate what repeats"):
//! when the plan compensates the arm's compliance, a stroke whose joints come nearer their
//! limits than the correction needs is solved again at another in-plane tilt of its tool axis
//! (one tilt for the whole stroke, within the axis cone around the normal, the ball's roll
//! left free), the tilt nearest the one the stroke had, with every joint at least
//! [`LIMIT_MARGIN_RAD`] inside its limits. A stroke no tilt gives that margin keeps its
//! answer; the compensation then carries only the share of its correction that fits
//! (`compensate::commands`). Method: docs/ALGORITHMS.md, "Compliance compensation".
use super::config::PlanConfig;
use crate::robot::{IkTarget, Robot};
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

/// Joint angles and the tool axis used for one point, or why it is unreachable.
pub(super) type Solved = Result<(Vec<f64>, Vector3<f64>), String>;

/// A stroke solved again: every point's answer and the last pose.
pub(super) type Resolved = (Vec<Solved>, Vec<f64>);

/// Which way a held tilt (removal mode, [`solve_stroke`]) leans first: true tips the tool
/// axis (shank to tip) away from the arm's base, the shank back toward it; the other way is
/// tried when this one leaves a point unreachable. Measured on the demo (docs/ALGORITHMS.md,
/// "Split and splice"), away first -> toward first: the same tilts in four regions of five,
/// 0 unreachable points either way, lowest point after the grind -0.176 -> -0.276 mm,
/// fit-vs-achieved RMS 0.035 -> 0.041 mm.
const LEAN_AWAY_FIRST: bool = true;

/// Halvings of the hold between 0 and `tilt_deg` when the arm cannot hold the whole of it
/// (6: 20 / 64 = 0.3 degrees, a tenth of the least tilt the axis search leaves; each costs
/// one closed-form IK of the stroke, microseconds a point).
const HOLD_BISECTIONS: usize = 6;

/// IK of one stroke's targets, chained from `prev`: joint angles and the tool axis used, or
/// why a point is unreachable. The stroke is then solved again with one in-plane tilt for
/// all its points when every point reachable before stays reachable and within
/// `max_axis_miss_deg` of its own outward normal (`normals`, robot frame): with `min_tilt`
/// (removal mode, rad) the least tilt, leaning each way in turn, that holds every point at
/// least that far from its normal (a ball spinning about the normal does not cut at its pole,
/// and near it the removal follows the axis error by cot(tilt)); otherwise, or when neither
/// way works, where the IK had to tilt the tool (axis search) the largest of its points'
/// tilts (their own smallest tilts differ from point to point and make the joints jitter).
pub(super) fn solve_stroke(
    targets: &[IkTarget],
    normals: &[Vector3<f64>],
    robot: &Robot,
    cfg: &PlanConfig,
    prev: &mut Vec<f64>,
    min_tilt: Option<f64>,
) -> Vec<Solved> {
    let start = prev.clone();
    let (first, reach) = solve_each(targets, robot, cfg, prev);
    if !robot.has_closed_form() {
        return first;
    }
    let stroke = Restroke {
        targets,
        normals,
        first: &first,
        robot,
        cfg,
        start: &start,
        reach,
    };
    let held = min_tilt.and_then(|min| stroke.hold(min));
    let reached = || {
        (reach.abs() >= 1e-9)
            .then(|| stroke.tilted(reach).map(|r| (reach, r)))
            .flatten()
    };
    let chosen = held.or_else(reached);
    let chosen = match wanted(robot, cfg) {
        Some(m) => keep(&stroke, chosen, min_tilt, m),
        None => chosen,
    };
    match chosen {
        Some((_, (out, end))) => {
            *prev = end;
            out
        }
        None => first,
    }
}

/// One stroke's first answers and what solving it again with one tilt needs.
pub(super) struct Restroke<'a> {
    pub(super) targets: &'a [IkTarget],
    pub(super) normals: &'a [Vector3<f64>],
    /// Each point's first answer.
    pub(super) first: &'a [Solved],
    /// The arm.
    pub(super) robot: &'a Robot,
    /// The planner's settings.
    pub(super) cfg: &'a PlanConfig,
    pub(super) start: &'a [f64],
    /// The signed in-plane tilt reach needed (axis search), rad.
    reach: f64,
}

impl Restroke<'_> {
    /// The stroke solved again with `delta` rad of in-plane tilt ([`solve_tilted`]).
    fn tilted(&self, delta: f64) -> Option<Resolved> {
        solve_tilted(self, delta, self.cfg.ik.limit_margin)
    }

    /// The stroke held at least `min` rad from every normal, leaning the preferred way first;
    /// where neither way reaches it, at the largest smaller hold either way reaches (bisected,
    /// [`HOLD_BISECTIONS`]). None when no hold is reached; else the tilt (rad) and answers.
    fn hold(&self, min: f64) -> Option<(f64, Resolved)> {
        let away = away_sign(self.targets, self.first, self.robot)?;
        let frames = plane_frames(self);
        let max = self.cfg.ik.max_axis_miss_deg.to_radians();
        let signs = if LEAN_AWAY_FIRST {
            [away, -away]
        } else {
            [-away, away]
        };
        let attempt = |m: f64, sign: f64| {
            least_tilt(&frames, m, sign, self.reach, max)
                .and_then(|d| self.tilted(d).map(|r| (d, r)))
        };
        if let Some(found) = signs.iter().find_map(|&s| attempt(min, s)) {
            return Some(found);
        }
        let mut best: Option<(f64, (f64, Resolved))> = None;
        for sign in signs {
            let (mut lo, mut hi, mut found) = (0.0, min, None);
            for _ in 0..HOLD_BISECTIONS {
                let mid = 0.5 * (lo + hi);
                match attempt(mid, sign) {
                    Some(f) => (lo, found) = (mid, Some(f)),
                    None => hi = mid,
                }
            }
            if let Some(f) = found.filter(|_| best.as_ref().is_none_or(|b| lo > b.0)) {
                best = Some((lo, f));
            }
        }
        best.map(|b| b.1)
    }
}

/// Each target solved on its own (axis search where the requested axis is out of reach),
/// chained from `prev`; also the signed in-plane tilt of largest size the search needed.
fn solve_each(
    targets: &[IkTarget],
    robot: &Robot,
    cfg: &PlanConfig,
    prev: &mut Vec<f64>,
) -> (Vec<Solved>, f64) {
    let mut reach = 0.0f64;
    let first = targets
        .iter()
        .map(|t| match robot.ik(t, prev, &cfg.ik) {
            Ok(sol) => {
                prev.clone_from(&sol.q);
                let (plane_normal, requested) = in_plane(robot, &sol.q, &t.axis);
                let achieved = robot.fk(&sol.q).axis;
                let tilt = requested
                    .cross(&achieved)
                    .dot(&plane_normal)
                    .atan2(requested.dot(&achieved));
                if tilt.abs() > reach.abs() {
                    reach = tilt;
                }
                Ok((sol.q, t.axis.normalize()))
            }
            Err(e) => Err(e.to_string()),
        })
        .collect();
    (first, reach)
}

/// The sign of the in-plane tilt that tips the tool axis away from the base, from the
/// stroke's first solved point (None when none is solved or it stands over the base axis).
fn away_sign(targets: &[IkTarget], first: &[Solved], robot: &Robot) -> Option<f64> {
    let (t, q) = targets
        .iter()
        .zip(first)
        .find_map(|(t, f)| f.as_ref().ok().map(|(q, _)| (t, q)))?;
    let radial = Vector3::new(t.position.x, t.position.y, 0.0).try_normalize(1e-9)?;
    let (n, requested) = in_plane(robot, q, &t.axis);
    Some(if n.cross(&requested).dot(&radial) >= 0.0 {
        1.0
    } else {
        -1.0
    })
}

/// Per solved point, its inward normal in the arm plane's coordinates of the tilt: `(A, B)`
/// with the tool axis tilted by delta at `A cos delta + B sin delta` (cosine of its angle from
/// the inward normal).
pub(super) fn plane_frames(s: &Restroke) -> Vec<(f64, f64)> {
    let each = s.targets.iter().zip(s.normals).zip(s.first);
    each.filter_map(|((t, n), f)| {
        let (q, _) = f.as_ref().ok()?;
        let (plane, r) = in_plane(s.robot, q, &t.axis);
        let inward = -n.normalize();
        Some((r.dot(&inward), plane.cross(&r).dot(&inward)))
    })
    .collect()
}

/// The least tilt of sign `sign` (from `reach`, the tilt reach needs, when it leans that
/// way) that holds every point of `frames` ([`plane_frames`]) at least `min` rad from its
/// inward normal, or None past `max` rad. A point's angle is acos(R cos(delta - phi)); where
/// it is under `min` the tilt moves to phi + beta, past the interval it forbids.
fn least_tilt(frames: &[(f64, f64)], min: f64, sign: f64, reach: f64, max: f64) -> Option<f64> {
    let mut delta = (sign * reach).max(0.0);
    for _ in 0..=frames.len() {
        let mut moved = false;
        for &(a, b) in frames {
            let (r, phi) = (a.hypot(b * sign), (b * sign).atan2(a));
            if r * (delta - phi).cos() > min.cos() + 1e-12 {
                delta = phi + (min.cos() / r).clamp(-1.0, 1.0).acos();
                moved = true;
            }
        }
        if delta > max {
            return None;
        }
        if !moved {
            return Some(sign * delta);
        }
    }
    None
}

/// The arm plane's normal at `q` (joint 2's axis) and `axis` projected into the plane (unit).
pub(super) fn in_plane(
    robot: &Robot,
    q: &[f64],
    axis: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let (_, axes) = robot.joint_frames(q);
    let n = axes[1].normalize();
    let a = axis.normalize();
    ((n), (a - n * a.dot(&n)).normalize())
}

//! The arm's compliance compensated (issue 50, "compensate what repeats"): where servos.toml
//! has a `[compliance]` table (`calibrate compliance`), the servos are commanded so that the
//! loaded joints sit where the plan wants them. At every grinding sample the load is the arm's
//! weight plus the planned contact force (the tool's preload force along the part's normal the
//! inspection measured under the contact, the direction the compliant tool presses in the
//! removal model), and
//! [`Compliance::command`] gives the servo angles that bend and push the joints (stiffness and
//! gear flank) onto the planned pose; from that the offset the workcell calibration already
//! absorbed is taken away: the calibration touched the fixture with no contact force, so the
//! arm's gravity-only deflection at the poses near the part's origin (a weighted mean over
//! them: the calibration touched there more than once) is in the calibrated part pose
//! (docs/CALIBRATION.md). The correction is held through the press, approach,
//! retract and re-orientation around each contact, faded out over the transits, and smoothed
//! (four moving averages: a cubic B-spline, bounded jerk) so that the commanded trajectory
//! keeps the joints' limits; when no smoothing keeps them the caller leaves the compensation
//! out. Method: docs/ALGORITHMS.md, "Compliance compensation".
use nalgebra::{Matrix3x4, Vector3};

use super::file::MAX_COMMAND_OFFSET_RAD;

use super::program::SegmentKind;
use super::program::{PlannedPass, Segment};
use super::trajectory::JointTrajectory;
use crate::robot::{Compliance, Robot, Workcell};

/// Widths of the moving averages that smooth the correction, samples, tried in turn until the
/// commanded trajectory keeps every limit (15, 30, 60: 0.3, 0.6 and 1.2 s at the 20 ms bus
/// period). Four averages of width W make a cubic B-spline whose jerk on a correction step `d`
/// is `2 d / W^3`: 1.1 rad/s^3 at 0.3 s for a 0.015 rad step (half a 0.5 degree band plus the
/// contact force's and gravity's bending), under the 20 % of the 15 rad/s^3 jerk limit the
/// free motions leave ([`FREE_LIMIT_SHARE`]); measured on the demo's part, the true model's
/// steps needed more than 0.3 s.
pub const SMOOTH_WIDTHS: [usize; 3] = [15, 30, 60];
/// Moving averages in the smoothing (4: a cubic B-spline, continuous acceleration).
const SMOOTH_PASSES: usize = 4;
/// Samples of a transit next to a contact that still hold the contact's correction, in
/// smoothing widths (2: the smoothing reaches half its support, two widths, so the correction
/// is whole from the approach's start on even where approach and press are short).
const HOLD_INTO_TRANSIT: usize = 2;
/// Share of each joint's velocity, acceleration and jerk limit the free motions (transit,
/// approach, press, retract) use when the plan is compensated (0.8): the smoothed correction
/// adds up to 1.1 rad/s^3 of jerk ([`SMOOTH_WIDTHS`]) where those time-optimal moves sit on
/// their limits. Without `[compliance]` they use the whole limit.
pub const FREE_LIMIT_SHARE: f64 = 0.8;

/// What loads the arm at each sample: the program's segments and passes, and the planned
/// contact force, N (0 in rigid mode).
pub struct Loads<'a> {
    /// The program's segments.
    pub segments: &'a [Segment],
    /// The program's passes.
    pub passes: &'a [PlannedPass],
    /// The planned contact force (the tool's preload force), N.
    pub force_n: f64,
}

/// The servo-side commands of a compensated plan and how much of the correction they carry.
pub struct Commanded {
    /// The servo-side joint angles per sample.
    pub traj: JointTrajectory,
    /// Grinding samples whose correction is scaled down to keep a joint's limit (partial
    /// compensation).
    pub partial_samples: usize,
    /// Grinding samples in all.
    pub grinding_samples: usize,
    /// The smallest share of the correction any grinding sample keeps (1: all whole).
    pub least_share: f64,
}

/// The servo-side joint angles to command for the loaded joints `traj` (robot frame) under
/// `loads`, smoothed by the first of [`SMOOTH_WIDTHS`] that `keeps` accepts (else the last
/// one's error), or None when `robot` has no `[compliance]` (the plan commands `traj` itself).
/// The limits hold by construction: with `c` the smoothed correction, each sample keeps the
/// share `s` of it that stays [`RANGE_MARGIN`] inside every joint's limits; `s` is eroded
/// (a running minimum over the smoothing's whole support) and then smoothed the same way, so
/// the smoothed share never exceeds the sample's own and `q + s c` keeps the limits.
pub fn commands<E>(
    traj: &JointTrajectory,
    loads: &Loads,
    robot: &Robot,
    wc: &Workcell,
    keeps: &dyn Fn(&JointTrajectory) -> Result<(), E>,
) -> Option<Result<Commanded, E>> {
    let model = robot.servos.compliance.as_ref()?;
    let n = traj.len();
    let dof = traj.dof;
    let absorbed = absorbed_offset(model, traj, robot, wc);
    let kinds = sample_kinds(loads.segments, n);
    let bench = (model, robot, wc, &absorbed);
    // the gears trail the servos' motion, and the correction is part of that motion: the
    // flanks are taken from the planned motion, then from it with the correction added
    let first = exact_corrections(traj, loads, &kinds, bench, &trailing(traj, None));
    let rough = smoothed(&first, &kinds, dof, SMOOTH_WIDTHS[0]);
    let exact = exact_corrections(traj, loads, &kinds, bench, &trailing(traj, Some(&rough)));
    let mut last = None;
    for width in SMOOTH_WIDTHS {
        let delta = smoothed(&exact, &kinds, dof, width);
        let raw: Vec<f64> = (0..n)
            .map(|i| share_within_range(robot, traj.sample(i), &delta[i * dof..(i + 1) * dof]))
            .collect();
        let mut share = eroded(&raw, SMOOTH_PASSES * (width / 2));
        smooth(&mut share, 1, n, width);
        let mut out = traj.clone();
        for (i, (o, d)) in out.positions.iter_mut().zip(&delta).enumerate() {
            *o += share[i / dof] * d;
        }
        match keeps(&out) {
            Ok(()) => {
                let grinding: Vec<f64> = (0..n)
                    .filter(|&i| exact[i].is_some())
                    .map(|i| share[i].min(1.0))
                    .collect();
                return Some(Ok(Commanded {
                    traj: out,
                    partial_samples: grinding.iter().filter(|&&s| s < WHOLE_SHARE).count(),
                    grinding_samples: grinding.len(),
                    least_share: grinding.iter().copied().fold(1.0, f64::min),
                }));
            }
            Err(e) => last = Some(Err(e)),
        }
    }
    last
}

/// The model, robot, workcell and absorbed offset a correction is computed on.
type Bench<'a> = (&'a Compliance, &'a Robot, &'a Workcell, &'a Vector3<f64>);

/// The exact correction at each grinding sample of `traj` (None elsewhere, or where
/// [`correction`] finds none), its gears trailing on the flanks `trail` ([`trailing`]).
fn exact_corrections(
    traj: &JointTrajectory,
    loads: &Loads,
    kinds: &[(SegmentKind, Option<usize>)],
    (model, robot, wc, absorbed): Bench,
    trail: &[f64],
) -> Vec<Option<Vec<f64>>> {
    let dof = traj.dof;
    (0..traj.len())
        .map(|i| match kinds[i] {
            (SegmentKind::Grind, Some(pass)) => {
                let q = traj.sample(i);
                let force = contact_force(&loads.passes[pass], robot, wc, q) * loads.force_n;
                let side = &trail[i * dof..(i + 1) * dof];
                correction(model, robot, q, (&force, side), absorbed)
            }
            _ => None,
        })
        .collect()
}

/// The corrections `exact` held around the contacts ([`held`], [`HOLD_INTO_TRANSIT`] widths
/// into the transits), zero within the smoothing's reach of the ends (home stays where it
/// is), and smoothed ([`smooth`]) at `width`: row-major, `dof` a sample.
fn smoothed(
    exact: &[Option<Vec<f64>>],
    kinds: &[(SegmentKind, Option<usize>)],
    dof: usize,
    width: usize,
) -> Vec<f64> {
    let n = exact.len();
    let mut delta = held(exact, kinds, dof, HOLD_INTO_TRANSIT * width);
    let ends = (2 * width * dof).min(delta.len());
    delta[..ends].fill(0.0);
    let len = delta.len();
    delta[len - ends..].fill(0.0);
    smooth(&mut delta, dof, n, width);
    delta
}

/// A joint step under this is a joint held still, rad (1e-9: the trajectory's rounding; a
/// grinding stroke turns the base yaw by about 1e-5 rad a sample).
const STILL_RAD: f64 = 1e-9;

/// Per sample (row-major, `dof` a sample), the flank each joint's gear trails its servo on
/// (`Compliance::deflection_trailing`): -1 after a motion towards larger angles (the output
/// lags the servo by half the band), 1 after one the other way, 0 before the joint first
/// moved. The servos follow `traj` plus the correction `delta` (row-major) when given.
fn trailing(traj: &JointTrajectory, delta: Option<&[f64]>) -> Vec<f64> {
    let dof = traj.dof;
    let at = |i: usize, k: usize| traj.sample(i)[k] + delta.map_or(0.0, |d| d[i * dof + k]);
    let mut side = vec![0.0; dof];
    let mut out = vec![0.0; traj.len() * dof];
    for i in 1..traj.len() {
        for (k, s) in side.iter_mut().enumerate() {
            let step = at(i, k) - at(i - 1, k);
            if step.abs() > STILL_RAD {
                *s = -step.signum();
            }
        }
        out[i * dof..(i + 1) * dof].copy_from_slice(&side);
    }
    out
}

/// A share of the correction at or above this counts as whole (1 - 1e-9: the moving
/// averages of a run of ones round to within a few ulps of one).
const WHOLE_SHARE: f64 = 1.0 - 1e-9;

/// The servo angles minus the planned ones at loaded joints `q` under `force` (N, robot
/// frame, on the tip), the unloaded gears trailing on the flanks `trail`: the loaded tip goes
/// to the planned tip plus `absorbed` (where the calibrated cell's frame has the planned tip),
/// the tool axis kept. None where [`shifted`] finds no such pose near `q` (the sample then
/// holds its neighbours' correction).
fn correction(
    model: &Compliance,
    robot: &Robot,
    q: &[f64],
    (force, trail): (&Vector3<f64>, &[f64]),
    absorbed: &Vector3<f64>,
) -> Option<Vec<f64>> {
    let out = shifted(robot, q, absorbed)?;
    let cmd = model.command_trailing(robot, &out, force, trail);
    Some(cmd.iter().zip(q).map(|(c, a)| c - a).collect())
}

/// How far inside each joint's limits and servo range a corrected sample stays, rad (0.005,
/// 0.29 degrees: over one servo count, 0.24 degrees, and half the IK's `limit_margin` of
/// 0.01 rad, so that a contact the plan puts next to a limit keeps some of its correction).
const RANGE_MARGIN: f64 = 0.005;

/// Share of `run`'s command offset bound ([`MAX_COMMAND_OFFSET_RAD`]) a correction may use
/// (0.99: the bound itself is checked on the smoothed, shared commands, and this keeps them
/// off it by a hundredth).
const OFFSET_KEPT: f64 = 0.99;

/// The largest share `s` in [0, 1] of the correction `c` at joints `q` such that `q + s c`
/// stays [`RANGE_MARGIN`] inside each joint's limits and servo range and within
/// [`OFFSET_KEPT`] of `run`'s offset bound (the least over the joints; 0 for a joint already
/// inside the margin that `c` pushes further out).
fn share_within_range(robot: &Robot, q: &[f64], c: &[f64]) -> f64 {
    c.iter()
        .enumerate()
        .map(|(k, &v)| {
            let j = &robot.joints[k];
            let [slo, shi] = robot
                .servos
                .for_joint(&j.name)
                .map_or([f64::NEG_INFINITY, f64::INFINITY], |s| s.joint_range());
            let room = if v > 0.0 {
                j.upper.min(shi) - RANGE_MARGIN - q[k]
            } else {
                q[k] - j.lower.max(slo) - RANGE_MARGIN
            };
            if v == 0.0 {
                1.0
            } else {
                // and within the offset from its sample `run` accepts of a command
                (room.min(OFFSET_KEPT * MAX_COMMAND_OFFSET_RAD) / v.abs()).clamp(0.0, 1.0)
            }
        })
        .fold(1.0, f64::min)
}

/// The running minimum of `x` over `reach` samples on each side.
fn eroded(x: &[f64], reach: usize) -> Vec<f64> {
    (0..x.len())
        .map(|i| {
            let hi = (i + reach + 1).min(x.len());
            x[i.saturating_sub(reach)..hi]
                .iter()
                .copied()
                .fold(1.0, f64::min)
        })
        .collect()
}

/// Gauss-Newton steps of [`shifted`] (3: the shift is millimetres on 100 mm links, so the
/// second step leaves a few micrometres and the third well under one).
const SHIFT_STEPS: usize = 3;
/// Largest tip miss, m, of a [`shifted`] pose that counts as solved (1e-6, against shifts of
/// millimetres).
const SHIFT_MISS_M: f64 = 1e-6;
/// Step of [`shifted`]'s numeric derivative, rad.
const SHIFT_PROBE: f64 = 1e-7;

/// Joint angles near `q` whose tip lies `by` (m, robot frame) from `q`'s: the base yaw and
/// the three pitch joints by Gauss-Newton with the least joint change (the minimum-norm step:
/// the frame the calibration shifted is only translated, and the ball's centre, not its axis,
/// sets the contact; holding the axis too made the DOFBOT fold its pitch joints against each
/// other, 0.05-0.07 rad for a 6 mm shift on the demo-like part, over what `run` accepts), the
/// wrist roll kept; `q` itself where the chain is not the DOFBOT's; None where the step is
/// singular, misses the shifted tip by more than [`SHIFT_MISS_M`] or turns a joint more than
/// `run` accepts of a command ([`MAX_COMMAND_OFFSET_RAD`]).
fn shifted(robot: &Robot, q: &[f64], by: &Vector3<f64>) -> Option<Vec<f64>> {
    if q.len() < 4 || !robot.has_closed_form() {
        return Some(q.to_vec());
    }
    let goal = robot.fk(q).position + by;
    let miss = |x: &[f64]| robot.fk(x).position - goal;
    let mut x = q.to_vec();
    for _ in 0..SHIFT_STEPS {
        let r = miss(&x);
        let mut jac = Matrix3x4::zeros();
        for k in 0..4 {
            let mut y = x.clone();
            y[k] += SHIFT_PROBE;
            jac.set_column(k, &((miss(&y) - r) / SHIFT_PROBE));
        }
        let lambda = (jac * jac.transpose()).lu().solve(&(-r))?;
        let step = jac.transpose() * lambda;
        for k in 0..4 {
            x[k] += step[k];
        }
    }
    let turned = x
        .iter()
        .zip(q)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    (miss(&x).norm() <= SHIFT_MISS_M && turned <= MAX_COMMAND_OFFSET_RAD).then_some(x)
}

/// The unit contact force direction at loaded joints `q` of grinding pass `pass`, robot frame,
/// the way the part pushes the ball: the part's normal the inspection measured under the
/// pass's patch (`contact_normal`, set with its dwell), else the outward nominal normal of its
/// contact nearest the tip. The measured one is what sets the sign of the base yaw's load: on a
/// face looking at the base the nominal normal points near the yaw's axis and its moment is
/// 0.013-0.03 N m, while the part under the ball is yawed -4 to +6 degrees from it (survey
/// case 161); pressed along the nominal normal, the simulated yaw sat on the other flank from
/// the plan's at 5-22 % of the grinding samples and those strokes landed 1.3-2.2 mm across the
/// pass (docs/ALGORITHMS.md, "The base yaw at a contact facing the base").
fn contact_force(pass: &PlannedPass, robot: &Robot, wc: &Workcell, q: &[f64]) -> Vector3<f64> {
    if let Some(n) = pass.contact_normal {
        return wc.direction_from_reference(&Vector3::from(n)).normalize();
    }
    let tip = robot.fk(q).position;
    let nearest = pass.points.iter().min_by(|a, b| {
        let d = |p: &super::program::PlannedPoint| (Vector3::from(p.tip_m) - tip).norm();
        d(a).total_cmp(&d(b))
    });
    nearest.map_or(Vector3::zeros(), |p| {
        wc.direction_from_reference(&Vector3::from(p.normal))
            .normalize()
    })
}

/// Spread of the workcell calibration's touch-offs around the part's origin, m (5 mm): the
/// calibration touches the fixture near the origin more than once, a few millimetres apart, so
/// the offset it absorbed is the mean over those touches, not the offset at one pose; the
/// plan's poses nearest the origin (several nearly tied, their gravity offsets up to 0.7 mm
/// apart on the documented arm) are weighted by `exp(-((d - d_min) / spread)^2)`, which does
/// not jump from one pose to the other on a small change of the trajectory or kinematics.
const TOUCH_SPREAD_M: f64 = 0.005;
/// Weight under which a pose is left out of the absorbed offset's mean (1e-3: beyond 2.6
/// spreads of the nearest pose, a share of the mean far under the model's error).
const TOUCH_MIN_WEIGHT: f64 = 1e-3;

/// The tip offset the workcell calibration absorbed, m (robot frame): the model's
/// gravity-only deflection of the tip, a weighted mean over the samples of `traj` whose tip
/// lies near the part's origin ([`TOUCH_SPREAD_M`]).
fn absorbed_offset(
    model: &Compliance,
    traj: &JointTrajectory,
    robot: &Robot,
    wc: &Workcell,
) -> Vector3<f64> {
    let m = &wc.robot_from_reference;
    let origin = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    let dist: Vec<f64> = (0..traj.len())
        .map(|i| (robot.fk(traj.sample(i)).position - origin).norm())
        .collect();
    let nearest = dist.iter().copied().fold(f64::INFINITY, f64::min);
    let (mut sum, mut weight) = (Vector3::zeros(), 0.0);
    for (i, d) in dist.iter().enumerate() {
        let w = (-((d - nearest) / TOUCH_SPREAD_M).powi(2)).exp();
        if w < TOUCH_MIN_WEIGHT {
            continue;
        }
        let q = traj.sample(i);
        sum += (model.loaded_tip(robot, q, &Vector3::zeros()) - robot.fk(q).position) * w;
        weight += w;
    }
    if weight > 0.0 {
        sum / weight
    } else {
        Vector3::zeros()
    }
}

/// Per sample, the kind of the segment it belongs to (the later one at a joint of two) and
/// its pass; samples of no segment count as transit.
fn sample_kinds(segments: &[Segment], n: usize) -> Vec<(SegmentKind, Option<usize>)> {
    let mut out = vec![(SegmentKind::Transit, None); n];
    for s in segments {
        let last = s.last_sample.min(n.saturating_sub(1));
        for o in out.iter_mut().take(last + 1).skip(s.first_sample) {
            *o = (s.kind, s.pass);
        }
    }
    out
}

/// The correction per sample before smoothing (row-major, `dof` a sample): the exact one at
/// grinding samples, elsewhere the nearest grinding sample's when at most `hold` transit
/// samples lie between, else zero.
fn held(
    exact: &[Option<Vec<f64>>],
    kinds: &[(SegmentKind, Option<usize>)],
    dof: usize,
    hold: usize,
) -> Vec<f64> {
    let n = exact.len();
    // per sample: the nearest grinding sample on one side within reach, and its distance
    let reach = |order: &mut dyn Iterator<Item = usize>| {
        let mut found: Vec<Option<(usize, usize)>> = vec![None; n];
        let mut carry: Option<(usize, usize)> = None;
        for i in order {
            if exact[i].is_some() {
                carry = Some((i, 0));
            } else if let Some((at, transit)) = carry {
                let transit = transit + usize::from(kinds[i].0 == SegmentKind::Transit);
                carry = (transit <= hold).then_some((at, transit));
            }
            found[i] = carry.map(|(at, _)| (at, at.abs_diff(i)));
        }
        found
    };
    let before = reach(&mut (0..n));
    let after = reach(&mut (0..n).rev());
    let mut out = vec![0.0; n * dof];
    for i in 0..n {
        let from = match (before[i], after[i]) {
            (Some(a), Some(b)) => Some(if a.1 <= b.1 { a.0 } else { b.0 }),
            (a, b) => a.or(b).map(|x| x.0),
        };
        if let Some(d) = from.and_then(|j| exact[j].as_ref()) {
            out[i * dof..(i + 1) * dof].copy_from_slice(d);
        }
    }
    out
}

/// [`SMOOTH_PASSES`] centred moving averages of `width` samples (rounded to odd) over each
/// joint of `delta` (`n` samples of `dof`), zero beyond the ends.
fn smooth(delta: &mut [f64], dof: usize, n: usize, width: usize) {
    let half = width / 2;
    let width = (2 * half + 1) as f64;
    for k in 0..dof {
        let mut col: Vec<f64> = (0..n).map(|i| delta[i * dof + k]).collect();
        for _ in 0..SMOOTH_PASSES {
            let mut prefix = vec![0.0; n + 1];
            for i in 0..n {
                prefix[i + 1] = prefix[i] + col[i];
            }
            col = (0..n)
                .map(|i| {
                    let lo = i.saturating_sub(half);
                    let hi = (i + half + 1).min(n);
                    (prefix[hi] - prefix[lo]) / width
                })
                .collect();
        }
        for (i, v) in col.into_iter().enumerate() {
            delta[i * dof + k] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step smoothed by the four averages keeps its level far from the step, is continuous
    /// and its third difference stays under the cubic B-spline's 2 d / W^3 (per sample^3).
    #[test]
    fn smoothing_keeps_levels_and_bounds_the_jerk_of_a_step() {
        let n = 200;
        let d = 0.015;
        let mut delta: Vec<f64> = (0..n).map(|i| if i >= 100 { d } else { 0.0 }).collect();
        // the ends are zero padded: only the middle is looked at
        let width = SMOOTH_WIDTHS[0];
        smooth(&mut delta, 1, n, width);
        assert!(delta[40].abs() < 1e-15, "{}", delta[40]);
        assert!((delta[150] - d).abs() < 1e-15, "{}", delta[150]);
        let w = width as f64;
        let most = (60..140)
            .map(|i| (delta[i + 3] - 3.0 * delta[i + 2] + 3.0 * delta[i + 1] - delta[i]).abs())
            .fold(0.0, f64::max);
        assert!(most <= 2.0 * d / w.powi(3) * 1.05, "{most:e}");
    }

    /// A gear trails on the flank opposite to its servo's last motion: none before the joint
    /// first moves, -1 while and after it turns to larger angles (held still too), 1 once it
    /// turns back; a correction that reverses a held joint counts as its motion.
    #[test]
    fn the_trailing_flank_follows_the_last_motion_of_the_servo() {
        let q = [0.0, 0.0, 0.1, 0.2, 0.2, 0.2, 0.1, 0.1];
        let traj = JointTrajectory {
            period: 0.02,
            dof: 1,
            positions: q.to_vec(),
        };
        let out = trailing(&traj, None);
        assert_eq!(out, [0.0, 0.0, -1.0, -1.0, -1.0, -1.0, 1.0, 1.0]);
        let delta = [0.0, 0.0, 0.0, 0.0, 0.0, -0.05, -0.05, -0.05];
        let out = trailing(&traj, Some(&delta));
        assert_eq!(out, [0.0, 0.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0]);
    }

    /// The correction is held from a grinding sample through the press and approach next to
    /// it and into a transit for at most `hold` samples.
    #[test]
    fn the_correction_is_held_around_contacts_and_fades_over_transits() {
        let n = 100;
        let mut kinds = vec![(SegmentKind::Transit, None); n];
        kinds[60..70].fill((SegmentKind::Approach, None));
        kinds[70..75].fill((SegmentKind::Press, None));
        kinds[75..80].fill((SegmentKind::Grind, Some(0)));
        let exact: Vec<Option<Vec<f64>>> = (0..n)
            .map(|i| (75..80).contains(&i).then(|| vec![i as f64]))
            .collect();
        let hold = 30;
        let out = held(&exact, &kinds, 1, hold);
        assert_eq!(out[77], 77.0);
        assert_eq!(out[62], 75.0, "approach holds the first contact's");
        assert_eq!(out[90], 79.0, "after the last contact, its own");
        assert_eq!(out[60 - hold], 75.0);
        assert_eq!(out[59 - hold], 0.0);
    }
}

//! Removal strokes: a chain of one-contact pieces ground without stopping. The feed over each
//! piece follows its dwell (speed = piece length / dwell, capped by the feed and joint limits);
//! the speed where two pieces meet is the lower of theirs, lowered further where the path
//! acceleration could not reach it; each piece is one Ruckig move on the path coordinate from
//! its entry speed to its exit speed (zero at the chain's ends), and the chain is sampled at the
//! bus period across the pieces. Method: docs/ALGORITHMS.md, "Removal mode of `plan`".
use nalgebra::Vector3;

use super::config::PlanConfig;
use super::error::PlanError;
use super::feed::{path_limits, JointSpline, PathLimits};
use super::program::{max_step, PlannedPass, Program, Segment, SegmentKind};
use super::trajectory::{Limits, Move, TrajectoryConfig, TrajectoryError};
use crate::robot::units::{metres, mm};
use crate::robot::Robot;

/// Share of the path acceleration the speed planning between pieces assumes (0.5): Ruckig's
/// jerk-limited ramps need more distance than a constant acceleration would; a piece whose move
/// still overshoots is planned again with half of it (down to rest-to-rest).
const SPEED_CHANGE_SHARE: f64 = 0.5;

/// Halvings of that share before a chain falls back to stopping at every contact (4: 1/32 of
/// the path acceleration, then rest to rest).
const SPEED_CHANGE_RETRIES: usize = 4;

/// Largest overshoot accepted of a piece's move past its end (or back before its start), m
/// (1e-9: rounding only; the path coordinate must not go back).
const OVERSHOOT_M: f64 = 1e-9;

/// Longest step between two knots of a chain's spline, m (0.5e-3): the rasters step 0.15-0.3
/// mm along a stroke, but a stroke can step farther where its points are sparse, and a natural
/// cubic spline across a step ten times its neighbours' bulges with their curvature times the
/// step squared: with the flank-checked softening (branch issue-50-sflank) tests/flank.rs's
/// demo-like part (region 3, a 1.9 mm step between 0.19 and 0.21 mm ones) had its modelled tip
/// 0.33 mm off its line against `max_path_error_mm` 0.1, and survey case 81 0.164 mm: plans
/// refused.
/// A longer step gets knots on the straight joint line between its ends (their tip strays
/// from the tip's line by about the link length times the joint change squared over 8, under
/// 0.02 mm on such a step).
const KNOT_STEP_M: f64 = 0.5e-3;

/// Arc lengths (m, tool tip) and joint angles of a chain's points, the zero-length steps
/// merged and a step longer than [`KNOT_STEP_M`] cut evenly by knots on the joint line between
/// its ends, and the length of each piece.
pub(crate) fn chain_knots(pieces: &[&PlannedPass]) -> (Vec<f64>, Vec<Vec<f64>>, Vec<f64>) {
    let mut s = vec![0.0];
    let mut q = vec![pieces[0].points[0].q.clone()];
    let mut lengths = Vec::with_capacity(pieces.len());
    for piece in pieces {
        let mut length = 0.0;
        for w in piece.points.windows(2) {
            let d = (Vector3::from(w[1].tip_m) - Vector3::from(w[0].tip_m)).norm();
            if d > 1e-9 {
                let start = s.last().copied().unwrap_or(0.0);
                let cuts = (d / KNOT_STEP_M).ceil() as usize;
                for k in 1..cuts {
                    let f = k as f64 / cuts as f64;
                    s.push(start + d * f);
                    q.push(
                        w[0].q
                            .iter()
                            .zip(&w[1].q)
                            .map(|(a, b)| a + (b - a) * f)
                            .collect(),
                    );
                }
                s.push(start + d);
                q.push(w[1].q.clone());
                length += d;
            }
        }
        lengths.push(length);
    }
    (s, q, lengths)
}

/// The path limits of a removal chain: the fastest feed `removal.feed_max_mm_s`, the path
/// acceleration and jerk, lowered where the joints demand (`path_limits`).
pub(crate) fn chain_limits(spline: &JointSpline, robot: &Robot, cfg: &PlanConfig) -> PathLimits {
    let wanted = PathLimits {
        velocity: metres(cfg.removal.feed_max_mm_s),
        acceleration: cfg.path_acceleration,
        jerk: cfg.path_jerk,
    };
    path_limits(spline, &robot.joints, wanted, cfg.joint_margin)
}

/// Entry speed of every piece and the exit speed of the last (m/s): rest at both ends, the
/// lower of two neighbours' speeds between them, then lowered until `accel` over each piece's
/// length can change one into the next (forward and backward passes).
fn junction_speeds(speed: &[f64], lengths: &[f64], accel: f64) -> Vec<f64> {
    let n = speed.len();
    let mut w = vec![0.0; n + 1];
    for k in 1..n {
        w[k] = speed[k - 1].min(speed[k]);
    }
    for k in 0..n {
        w[k + 1] = w[k + 1].min((w[k] * w[k] + 2.0 * accel * lengths[k]).sqrt());
    }
    for k in (0..n).rev() {
        w[k] = w[k].min((w[k + 1] * w[k + 1] + 2.0 * accel * lengths[k]).sqrt());
    }
    w
}

/// The chain's moves on the path coordinate, one per piece, or None when one of them would
/// overshoot its piece at this `accel`.
fn moves(
    knots: &[f64],
    speed: &[f64],
    lim: &PathLimits,
    accel: f64,
    tc: &TrajectoryConfig,
) -> Result<Option<Vec<Move>>, TrajectoryError> {
    let lengths: Vec<f64> = knots.windows(2).map(|w| w[1] - w[0]).collect();
    let w = junction_speeds(speed, &lengths, accel);
    let path = Limits {
        velocity: vec![lim.velocity],
        acceleration: vec![lim.acceleration],
        jerk: vec![lim.jerk],
    };
    let continuous = TrajectoryConfig {
        discrete_duration: false,
        ..tc.clone()
    };
    let mut out = Vec::with_capacity(speed.len());
    for k in 0..speed.len() {
        let cap = Limits {
            velocity: vec![speed[k].max(w[k]).max(w[k + 1])],
            ..path.clone()
        };
        let (a, b) = (knots[k], knots[k + 1]);
        let mut mv = Move::through(&[a], &[w[k]], &[b], &[w[k + 1]], &cap, &continuous)?;
        let (lo, hi) = mv.position_range();
        if lo < a - OVERSHOOT_M || hi > b + OVERSHOOT_M {
            return Ok(None);
        }
        out.push(mv);
    }
    Ok(Some(out))
}

impl Program {
    /// Appends a chain of removal pieces (each one contact, `dwell_s` set, every piece starting
    /// where the previous ended) ground without stopping; each piece's `dwell_s` becomes the
    /// time the trajectory spends on it (the last one also holds the rest up to the next whole
    /// bus period) and its `feed_mm_s` the speed planned over it.
    pub(crate) fn grind_chain(
        &mut self,
        chain: Vec<PlannedPass>,
        robot: &Robot,
        cfg: &PlanConfig,
    ) -> Result<(), PlanError> {
        let refs: Vec<&PlannedPass> = chain.iter().collect();
        let (s, q, lengths) = chain_knots(&refs);
        let gap = max_step(&chain[0].points[0].q, self.trajectory.last());
        if gap > 1e-12 {
            return Err(PlanError::Collision(format!(
                "grinding piece in region {} starts {gap:.3e} rad from the arm's pose",
                chain[0].region
            )));
        }
        let spline = JointSpline::new(s, q);
        let lim = chain_limits(&spline, robot, cfg);
        if lim.velocity < metres(cfg.removal.feed_max_mm_s) * (1.0 - 1e-9) {
            self.slowed += 1;
        }
        // the pieces of non-zero length, their knots and wanted speeds
        let moving: Vec<usize> = (0..chain.len()).filter(|&k| lengths[k] > 0.0).collect();
        let mut knots = vec![0.0];
        let mut speed = Vec::with_capacity(moving.len());
        for &k in &moving {
            knots.push(knots.last().copied().unwrap_or(0.0) + lengths[k]);
            let dwell = chain[k].dwell_s.unwrap_or(0.0);
            let v = if dwell > 0.0 {
                lengths[k] / dwell
            } else {
                lim.velocity
            };
            speed.push(v.min(lim.velocity));
        }
        let traj_err = |source| PlanError::Trajectory {
            context: format!("removal stroke in region {}", chain[0].region),
            source,
        };
        let mut accel = SPEED_CHANGE_SHARE * lim.acceleration;
        let mut found = None;
        for _ in 0..=SPEED_CHANGE_RETRIES {
            found = moves(&knots, &speed, &lim, accel, &cfg.trajectory).map_err(traj_err)?;
            if found.is_some() {
                break;
            }
            accel *= 0.5;
        }
        let mvs = match found {
            Some(m) => m,
            None => moves(&knots, &speed, &lim, 0.0, &cfg.trajectory)
                .map_err(traj_err)?
                .ok_or_else(|| {
                    PlanError::Config(format!(
                        "removal stroke in region {}: a rest-to-rest piece overshoots",
                        chain[0].region
                    ))
                })?,
        };
        self.append_chain(chain, &moving, &mvs, &spline, &lim, cfg);
        Ok(())
    }

    /// Samples `mvs` (the moves of the pieces `moving` of `chain`) at the bus period along
    /// `spline` and records one grinding segment per piece.
    fn append_chain(
        &mut self,
        mut chain: Vec<PlannedPass>,
        moving: &[usize],
        mvs: &[Move],
        spline: &JointSpline,
        lim: &PathLimits,
        cfg: &PlanConfig,
    ) {
        let period = cfg.trajectory.period;
        let mut starts = vec![0.0; chain.len() + 1];
        let mut durations = vec![0.0; chain.len()];
        for (&k, mv) in moving.iter().zip(mvs) {
            durations[k] = mv.duration();
        }
        for k in 0..chain.len() {
            starts[k + 1] = starts[k] + durations[k];
        }
        let total = starts[chain.len()];
        let steps = (total / period - 1e-9).ceil().max(0.0) as usize;
        let dof = chain[0].points[0].q.len();
        let (mut pos, mut vel) = ([0.0], [0.0]);
        let mut cursor = 0;
        let first = self.trajectory.len() - 1;
        for j in 1..=steps {
            let t = j as f64 * period;
            while cursor + 1 < mvs.len() && t >= starts[moving[cursor] + 1] {
                cursor += 1;
            }
            let s = match mvs.get(cursor) {
                Some(mv) => {
                    mv.state_at(t - starts[moving[cursor]], &mut pos, &mut vel);
                    pos[0]
                }
                None => spline.length(),
            };
            let mut q = vec![0.0; dof];
            spline.eval(s, &mut q);
            self.trajectory.push(&q);
        }
        self.cruise.extend(std::iter::repeat_n(false, steps));
        // the rest up to the whole period is spent pressed on the last contact
        durations[chain.len() - 1] += steps as f64 * period - total;
        let n = chain.len();
        for (k, mut piece) in chain.drain(..).enumerate() {
            let lo = ((starts[k] / period + 1e-9).floor() as usize).min(steps);
            let hi = match k + 1 == n {
                true => steps,
                false => ((starts[k + 1] / period - 1e-9).ceil().max(0.0) as usize).min(steps),
            };
            let length = piece
                .points
                .windows(2)
                .map(|w| (Vector3::from(w[1].tip_m) - Vector3::from(w[0].tip_m)).norm());
            let length: f64 = length.sum();
            piece.feed_mm_s = match durations[k] > 0.0 {
                true => mm(length / durations[k]).min(mm(lim.velocity)),
                false => 0.0,
            };
            piece.dwell_s = Some(durations[k]);
            self.segments.push(Segment {
                kind: SegmentKind::Grind,
                region: Some(piece.region),
                pass: Some(self.passes.len()),
                first_sample: first + lo,
                last_sample: first + hi.max(lo),
            });
            self.passes.push(piece);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::program::PlannedPoint;
    use crate::motion::raster::StrokeKind;

    /// Rest at both ends; between pieces the lower speed, lowered where the acceleration over
    /// a piece cannot reach it (by hand: sqrt(2 a L)).
    #[test]
    fn junction_speeds_keep_rest_at_the_ends_and_reachable_changes() {
        let w = junction_speeds(&[0.01, 0.002, 0.01], &[2e-4; 3], 0.025);
        let reach = (2.0 * 0.025 * 2e-4f64).sqrt(); // 0.00316 m/s from rest over one piece
        assert_eq!(w[0], 0.0);
        assert_eq!(w[3], 0.0);
        assert!((w[1] - 0.002).abs() < 1e-15, "{w:?}");
        assert!((w[2] - 0.002).abs() < 1e-15, "{w:?}");
        let fast = junction_speeds(&[0.02, 0.02], &[2e-4; 2], 0.025);
        assert!((fast[1] - reach).abs() < 1e-12, "{fast:?}");
    }

    fn point(x_mm: f64, q: f64) -> PlannedPoint {
        PlannedPoint {
            surface_mm: [x_mm, 0.0, 0.0],
            normal: [0.0, 0.0, 1.0],
            offset_mm: -2.0,
            tip_m: [x_mm * 1e-3, 0.0, 0.0],
            axis: [0.0, 0.0, -1.0],
            q: vec![q, -q],
            landed_mm: None,
        }
    }

    fn piece(points: Vec<PlannedPoint>) -> PlannedPass {
        PlannedPass {
            region: 0,
            layer: 0,
            kind: StrokeKind::Pass,
            feed_mm_s: 1.0,
            dwell_s: Some(1.0),
            contact_normal: None,
            points,
        }
    }

    /// Steps of 0.2, 1.9 and 0.2 mm: the long one is cut into four knots 0.475 mm apart on the
    /// joint line (q 0.1 -> 0.5 in steps of 0.1), its end keeps its own angles, the pieces'
    /// lengths are the tip's; the spline through them stays on that line across the step where
    /// the raw knots' spline bulges (joint 0 at the step's middle: 0.3 on the line).
    #[test]
    fn a_long_step_gets_knots_on_the_joint_line() {
        let a = piece(vec![point(0.0, 0.0), point(0.2, 0.1)]);
        let b = piece(vec![point(0.2, 0.1), point(2.1, 0.5)]);
        let c = piece(vec![point(2.1, 0.5), point(2.3, 0.2)]);
        let (s, q, lengths) = chain_knots(&[&a, &b, &c]);
        assert_eq!(s.len(), 7, "{s:?}");
        for (k, want) in [(2, 0.2), (3, 0.3), (4, 0.4)] {
            assert!((q[k][0] - want).abs() < 1e-12 && (q[k][1] + want).abs() < 1e-12);
        }
        assert_eq!(q[5], vec![0.5, -0.5]);
        assert!((s[5] - 2.1e-3).abs() < 1e-15 && (lengths[1] - 1.9e-3).abs() < 1e-15);
        let mut at = [0.0; 2];
        JointSpline::new(s, q).eval(1.15e-3, &mut at);
        assert!((at[0] - 0.3).abs() < 0.01, "{at:?}");
        let raw = JointSpline::new(
            vec![0.0, 0.2e-3, 2.1e-3, 2.3e-3],
            vec![vec![0.0], vec![0.1], vec![0.5], vec![0.2]],
        );
        let mut bulged = [0.0];
        raw.eval(1.15e-3, &mut bulged);
        assert!((bulged[0] - 0.3).abs() > 0.05, "{bulged:?}");
    }
}

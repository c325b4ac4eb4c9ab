//! From strokes to one continuous joint program: IK along every stroke (split where the arm
//! cannot reach or follow), then transit, approach, grinding and retract moves spliced into a
//! single trajectory sampled at the bus period.
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::aim::Aim;
use super::config::PlanConfig;
use super::error::PlanError;
use super::feed::{path_limits, sample_stroke, JointSpline, PathLimits};
use super::raster::{PathPoint, Stroke, StrokeKind};
pub use super::report::SegmentKind;
use super::report::UnreachablePoint;
use super::tilt::solve_stroke;
use super::trajectory::JointTrajectory;
use crate::robot::units::{metres, mm};
use crate::robot::{IkTarget, Robot, Workcell};

/// A contact point with its tool pose and joint solution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedPoint {
    /// Surface point, reference frame, mm.
    pub surface_mm: [f64; 3],
    /// Outward surface normal, reference frame.
    pub normal: [f64; 3],
    /// Layer height above nominal, mm.
    pub offset_mm: f64,
    /// Tool tip (ball centre), robot frame, m.
    pub tip_m: [f64; 3],
    /// Requested tool axis (shank to tip, against the normal), robot frame.
    pub axis: [f64; 3],
    /// Joint angles, rad.
    pub q: Vec<f64>,
    /// Where the ball's contact patch lands on the nominal surface, reference frame, mm, when
    /// not under `surface_mm`: a spring-loaded spindle pressed `-offset_mm` deep slides it
    /// `depth x tan(tilt)` back toward the shank (`press_depth::land`); what plan.json's
    /// coverage counts as ground. Absent: under `surface_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landed_mm: Option<[f64; 3]>,
}

impl PlannedPoint {
    /// Where the ball's patch lands on the nominal surface, reference frame, mm: `landed_mm`,
    /// else under `surface_mm`.
    pub fn landing(&self) -> [f64; 3] {
        self.landed_mm.unwrap_or(self.surface_mm)
    }
}

/// A reachable piece of a stroke, ground at constant feed from rest to rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlannedPass {
    /// Region id.
    pub region: usize,
    /// Depth layer.
    pub layer: usize,
    /// Pass or link.
    pub kind: StrokeKind,
    /// Cruise speed planned, mm/s (the feed unless the joints need less).
    pub feed_mm_s: f64,
    /// Removal mode: time the trajectory takes over this piece, s (the dwell solved for its
    /// contact, longer where the stroke's speed changes could not follow it; the last piece of
    /// a stroke also holds the rest of its last bus period). Absent in rigid mode.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dwell_s: Option<f64>,
    /// Removal mode: the part's normal under the contact's patch as the inspection measured
    /// it, reference frame (`removal::Contact::normal` after the press: the way the part pushes
    /// the ball, which the compliance compensation loads the arm along). Absent in rigid mode
    /// and before the dwell solve (the points' nominal normal then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact_normal: Option<[f64; 3]>,
    /// The points.
    pub points: Vec<PlannedPoint>,
}

/// A stretch of the sampled trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// What it does.
    pub kind: SegmentKind,
    /// Region, for all but transits.
    pub region: Option<usize>,
    /// Index into `passes`, for grinding.
    pub pass: Option<usize>,
    /// First sample (the previous segment's last one, at rest).
    pub first_sample: usize,
    /// Last sample.
    pub last_sample: usize,
}

/// The assembled program.
#[derive(Debug, Clone)]
pub struct Program {
    /// Joint samples at the bus period.
    pub trajectory: JointTrajectory,
    /// Segments in order.
    pub segments: Vec<Segment>,
    /// Reachable pieces of the strokes.
    pub passes: Vec<PlannedPass>,
    /// Per sample: at cruise speed inside a grinding segment.
    pub cruise: Vec<bool>,
    /// Strokes the joints slowed below the feed.
    pub slowed: usize,
}

use super::collide::Scene;

/// A run: pieces ground one after another without lifting the tool.
pub(crate) type Run = Vec<PlannedPass>;

/// Largest joint difference.
pub(crate) fn max_step(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Tool tip (m) and axis in the robot frame for a contact point, `lift` mm above the contact
/// along the normal; the ball centre sits `reach` mm (radius + contact offset) off it, moved
/// back by the removal shift `aim` measured there (`motion::aim`).
pub(super) fn tool_target(
    p: &PathPoint,
    reach: f64,
    lift: f64,
    wc: &Workcell,
    aim: &Aim,
) -> IkTarget {
    let tip_mm =
        p.surface + p.normal * (p.offset + reach + lift) - aim.shift_at(&p.surface, &p.normal);
    IkTarget {
        position: wc.point_from_reference_mm(&tip_mm).coords,
        axis: -wc.direction_from_reference(&p.normal),
        roll: None,
    }
}

fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Solves every stroke of one region in order from `prev` (with `min_tilt`, removal mode,
/// rad: holding the tool at least that far from the normal where the arm can, see
/// [`solve_stroke`](super::tilt::solve_stroke)); splits into runs where a point is unreachable or
/// the joints would jump more than `max_joint_step`. Returns the runs; records the points left out
/// in `unreachable` and counts jumps.
#[allow(clippy::too_many_arguments)]
pub(crate) fn walk(
    strokes: &[Stroke],
    robot: &Robot,
    wc: &Workcell,
    cfg: &PlanConfig,
    reach: f64,
    scene: &Scene,
    prev: &mut Vec<f64>,
    unreachable: &mut Vec<UnreachablePoint>,
    jumps: &mut usize,
    min_tilt: Option<f64>,
) -> Vec<Run> {
    let mut runs = Vec::new();
    let mut run: Run = Vec::new();
    let mut last_q: Option<Vec<f64>> = None;
    for (si, stroke) in strokes.iter().enumerate() {
        let mut targets: Vec<IkTarget> = stroke
            .points
            .iter()
            .map(|p| tool_target(p, reach, 0.0, wc, &cfg.aim))
            .collect();
        let normals: Vec<Vector3<f64>> = targets.iter().map(|t| -t.axis).collect();
        if let Some(axis) = stroke_axis(&targets, cfg.axis_spread_deg) {
            targets.iter_mut().for_each(|t| t.axis = axis);
        }
        let mut solved = solve_stroke(&targets, &normals, robot, cfg, prev, min_tilt);
        for (sol, p) in solved.iter_mut().zip(&stroke.points) {
            if let Some(why) = misfit(p, reach, scene, &cfg.aim) {
                *sol = Err(why);
            }
        }
        for (sol, n) in solved.iter_mut().zip(&normals) {
            let Ok((q, _)) = sol else { continue };
            let miss = crate::robot::angle_between(&robot.fk(q).axis, &-n).to_degrees();
            if miss > cfg.ik.max_axis_miss_deg {
                *sol = Err(format!(
                    "tool axis {miss:.2} deg from the surface normal (accepted up to {:.2} deg)",
                    cfg.ik.max_axis_miss_deg
                ));
            }
        }
        let mut piece = PlannedPass {
            region: stroke.region,
            layer: stroke.layer,
            kind: stroke.kind,
            feed_mm_s: cfg.feed_mm_s,
            dwell_s: None,
            contact_normal: None,
            points: Vec::new(),
        };
        for (pi, ((p, target), sol)) in stroke.points.iter().zip(&targets).zip(solved).enumerate() {
            let (q, axis) = match sol {
                Ok(found) => found,
                Err(reason) => {
                    unreachable.push(UnreachablePoint {
                        region: stroke.region,
                        layer: stroke.layer,
                        stroke: si,
                        point: pi,
                        surface_mm: [p.surface.x, p.surface.y, p.surface.z],
                        tip_m: arr(&target.position),
                        reason,
                    });
                    close(&mut piece, &mut run, &mut runs, true);
                    last_q = None;
                    continue;
                }
            };
            // within a stroke neighbours must be close; at a stroke's first point (a rest
            // point, reoriented in place about the ball centre) four times that
            let allowed = cfg.max_joint_step * if pi == 0 { 4.0 } else { 1.0 };
            let step = last_q.as_ref().map_or(0.0, |l| max_step(l, &q));
            if step > allowed {
                *jumps += 1;
                close(&mut piece, &mut run, &mut runs, true);
            }
            last_q = Some(q.clone());
            piece.points.push(PlannedPoint {
                surface_mm: [p.surface.x, p.surface.y, p.surface.z],
                normal: arr(&p.normal),
                offset_mm: p.offset,
                tip_m: arr(&target.position),
                axis: arr(&axis),
                q,
                landed_mm: None,
            });
        }
        close(&mut piece, &mut run, &mut runs, false);
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// Why the ball cannot sit on contact `p` (`reach` mm off it along the normal): it would
/// touch a second face of the part or enter it beyond the contact tolerance. A pressed ball
/// (removal mode, negative offset) is placed touching: it stops at the surface and its spring
/// takes the preload. The ball is where it is commanded: moved back by the shift `aim`.
pub(super) fn misfit(p: &PathPoint, reach: f64, scene: &Scene, aim: &Aim) -> Option<String> {
    let centre =
        p.surface + p.normal * (p.offset.max(0.0) + reach) - aim.shift_at(&p.surface, &p.normal);
    if let Some(hit) = scene.second_face(&centre, Some(&p.normal)) {
        return Some(hit.to_string());
    }
    let tol = scene.config().contact_tolerance_mm + scene.config().press_mm;
    let clear = scene.ball_clearance(&centre, -tol);
    (clear < -tol).then(|| {
        format!(
            "tool does not fit: the ball would be {:.3} mm inside the part",
            -clear
        )
    })
}

/// One tool axis for a whole stroke: the mean of its points' axes, when none is more than
/// `spread_deg` from it (a ball burr grinds the same spot at any axis in its cone, and a fixed
/// axis keeps the wrist still along the stroke instead of following the surface's noise).
fn stroke_axis(targets: &[IkTarget], spread_deg: f64) -> Option<Vector3<f64>> {
    let sum: Vector3<f64> = targets.iter().map(|t| t.axis.normalize()).sum();
    let mean = sum.try_normalize(1e-9)?;
    targets
        .iter()
        .all(|t| crate::robot::angle_between(&t.axis, &mean).to_degrees() <= spread_deg)
        .then_some(mean)
}

/// Ends `piece` (adds it to `run` when it has points); with `end_run` also ends the run.
fn close(piece: &mut PlannedPass, run: &mut Run, runs: &mut Vec<Run>, end_run: bool) {
    if !piece.points.is_empty() {
        let next = PlannedPass {
            points: Vec::new(),
            ..piece.clone()
        };
        run.push(std::mem::replace(piece, next));
    }
    if end_run && !run.is_empty() {
        runs.push(std::mem::take(run));
    }
}

/// The program's length at one time (samples, segments, passes and its counters).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Mark {
    samples: usize,
    segments: usize,
    /// Passes.
    pub(crate) passes: usize,
    slowed: usize,
}

impl Program {
    /// Where the program ends now.
    pub(crate) fn mark(&self) -> Mark {
        Mark {
            samples: self.trajectory.len(),
            segments: self.segments.len(),
            passes: self.passes.len(),
            slowed: self.slowed,
        }
    }

    /// The program as it was at `mark`.
    pub(crate) fn back_to(&mut self, mark: Mark) {
        let dof = self.trajectory.dof;
        self.trajectory.positions.truncate(mark.samples * dof);
        self.cruise.truncate(mark.samples);
        self.segments.truncate(mark.segments);
        self.passes.truncate(mark.passes);
        self.slowed = mark.slowed;
    }

    /// Appends one piece ground at constant feed from rest to rest (rigid mode; removal
    /// pieces are ground in chains, `grind_chain`).
    pub(crate) fn grind(
        &mut self,
        mut piece: PlannedPass,
        robot: &Robot,
        cfg: &PlanConfig,
    ) -> Result<(), PlanError> {
        let mut s = vec![0.0];
        let mut q = vec![piece.points[0].q.clone()];
        for w in piece.points.windows(2) {
            let d = (Vector3::from(w[1].tip_m) - Vector3::from(w[0].tip_m)).norm();
            if d > 1e-9 {
                s.push(s.last().copied().unwrap_or(0.0) + d);
                q.push(w[1].q.clone());
            }
        }
        // every piece starts where the trajectory stands (assemble glides or approaches)
        let gap = max_step(&piece.points[0].q, self.trajectory.last());
        if gap > 1e-12 {
            return Err(PlanError::Collision(format!(
                "grinding piece in region {} starts {gap:.3e} rad from the arm's pose",
                piece.region
            )));
        }
        let spline = JointSpline::new(s, q);
        let wanted = PathLimits {
            velocity: metres(piece.feed_mm_s),
            acceleration: cfg.path_acceleration,
            jerk: cfg.path_jerk,
        };
        let lim = path_limits(&spline, &robot.joints, wanted, cfg.joint_margin);
        if lim.velocity < wanted.velocity * (1.0 - 1e-9) {
            self.slowed += 1;
        }
        piece.feed_mm_s = mm(lim.velocity);
        let first = self.trajectory.len() - 1;
        let mut added = 0;
        if spline.length() > 0.0 {
            let (samples, cruise) =
                sample_stroke(&spline, &lim, &cfg.trajectory).map_err(|source| {
                    PlanError::Trajectory {
                        context: format!("grinding stroke in region {}", piece.region),
                        source,
                    }
                })?;
            added = samples.len();
            for sample in &samples {
                self.trajectory.push(sample);
            }
            self.cruise.extend(cruise);
        }
        self.segments.push(Segment {
            kind: SegmentKind::Grind,
            region: Some(piece.region),
            pass: Some(self.passes.len()),
            first_sample: first,
            last_sample: first + added,
        });
        self.passes.push(piece);
        Ok(())
    }
}

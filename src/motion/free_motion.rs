//! Free motions of a program: transits, approaches, presses, retracts and glides, each kept
//! only when every sample is clear. A contact is entered by a transit to a pose above it and an
//! approach down the normal, and left by a retract up the normal; a transit that is not clear
//! as one joint move climbs along the normal to a safe height first, travels there (through
//! home when it must) and comes down along the next normal. Between two pieces of a run the
//! ball glides in task space (a layer step, a turn about the ball centre) when that is short
//! and clear. The splicing of runs that calls these is in `assemble.rs`.
use nalgebra::{Unit, UnitQuaternion, Vector3};

use super::collide::{Allow, Hit, Scene};
use super::compensate::FREE_LIMIT_SHARE;
use super::config::PlanConfig;
use super::error::PlanError;
use super::feed::{path_limits, sample_stroke, JointSpline, PathLimits};
use super::program::{max_step, PlannedPass, PlannedPoint, Program, Segment, SegmentKind};
use super::trajectory::{JointTrajectory, Limits, Move};
use crate::robot::units::{metres, mm};
use crate::robot::{IkTarget, Robot, Workcell};

/// Waypoint spacing of a straight retract, mm (0.25: the joint spline between two IK
/// waypoints this close strays from the line by under a micrometre on the DOFBOT's 100 mm
/// links, far below the 0.1 mm contact tolerance).
const STRAIGHT_STEP_MM: f64 = 0.25;

/// Two retract directions nearer than this are one, degrees (1: the retract height of 5 mm
/// then ends under 0.1 mm apart).
const SAME_DIRECTION_DEG: f64 = 1.0;

/// One rest-to-rest leg of a free motion.
#[derive(Clone)]
pub(super) struct Leg {
    to: Vec<f64>,
    kind: SegmentKind,
    region: Option<usize>,
    allow: Allow,
}

/// What assembling needs besides the program.
pub(super) struct Assembly<'a> {
    pub(super) robot: &'a Robot,
    pub(super) wc: &'a Workcell,
    pub(super) cfg: &'a PlanConfig,
    pub(super) scene: &'a Scene<'a>,
    pub(super) limits: Limits,
}

/// Bands of the base yaw's backlash the way down onto a contact turns the yaw through
/// (`Assembly::yaw_set`; 1.5: the whole band, and half a band more for the fitted band's
/// error, the shipped table's 0.438 degree against the documented arm's 0.5).
const SET_BANDS: f64 = 1.5;

/// The joints' limits for free motions: the whole limit, or [`FREE_LIMIT_SHARE`] of it when
/// the plan compensates the arm's compliance (`compensate_compliance` and a `[compliance]`
/// table: the smoothed correction adds to these moves).
fn free_limits(robot: &Robot, cfg: &PlanConfig) -> Limits {
    let mut limits = Limits::from_joints(&robot.joints);
    if cfg.compensate_compliance && robot.servos.compliance.is_some() {
        for v in limits
            .velocity
            .iter_mut()
            .chain(&mut limits.acceleration)
            .chain(&mut limits.jerk)
        {
            *v *= FREE_LIMIT_SHARE;
        }
    }
    limits
}

impl<'a> Assembly<'a> {
    /// The cell of `robot` in `wc` with `cfg`'s settings and the part's `scene`.
    pub(super) fn new(
        robot: &'a Robot,
        wc: &'a Workcell,
        cfg: &'a PlanConfig,
        scene: &'a Scene<'a>,
    ) -> Self {
        Assembly {
            robot,
            wc,
            cfg,
            scene,
            limits: free_limits(robot, cfg),
        }
    }

    /// Joint solutions with the ball `lift` mm above contact `p` along its normal, same axis:
    /// at `lift`, then halved twice (the arm may not reach the full height).
    pub(super) fn lifted(&self, p: &PlannedPoint, lift: f64) -> Vec<Vec<f64>> {
        let up = self.wc.direction_from_reference(&Vector3::from(p.normal));
        (0..3)
            .filter_map(|k| {
                let target = IkTarget {
                    position: Vector3::from(p.tip_m) + up * metres(lift / f64::from(1 << k)),
                    axis: Vector3::from(p.axis),
                    roll: None,
                };
                self.robot.ik(&target, &p.q, &self.cfg.ik).ok().map(|s| s.q)
            })
            .collect()
    }

    /// The base yaw turn, rad, the way down onto `piece` starts from (issue 50, build item 2:
    /// "every contact is approached so that each joint sits on the same flank"): the approach
    /// then turns the yaw back by it, and a gear no load holds trails its motion, so the yaw's
    /// gear touches down on the flank the piece's first contact loads it towards
    /// ([`SET_BANDS`] of its band, signed by the contact force's moment about the yaw's axis).
    /// Left to the transit before, the gear can touch down on the other flank, and on a bump
    /// of a face looking at the base both flanks hold themselves: the ball lands half a band
    /// (2.2 mm across the pass at 0.25 m) to one side, where the part's normal turns the
    /// moment's sign (survey case 1, cell 30, grind 1: 24 passes, 12 s of dwell, landed there,
    /// three times the planned removal on a spot). 0 where the plan does not compensate the
    /// arm (no `[compliance]`, or `compensate_compliance` off) or `piece` is not pressed.
    pub(super) fn yaw_set(&self, piece: &PlannedPass) -> f64 {
        let model = match self.cfg.compensate_compliance {
            true => self.robot.servos.compliance.as_ref(),
            false => None,
        };
        let (Some(model), Some(start)) = (model, piece.points.first()) else {
            return 0.0;
        };
        if pressed(start) <= 0.0 || start.q.is_empty() {
            return 0.0;
        }
        let normal = Vector3::from(piece.contact_normal.unwrap_or(start.normal));
        let push = self.wc.direction_from_reference(&normal).normalize();
        let moment = model.torques(self.robot, &start.q, &push)[0];
        let turn = SET_BANDS * model.backlash_deg[0].to_radians();
        match moment == 0.0 {
            true => 0.0,
            false => turn * moment.signum(),
        }
    }

    /// `q` with its base yaw turned by `by` rad, or `q` as it is where that leaves the yaw's
    /// limits.
    fn yaw_turned(&self, mut q: Vec<f64>, by: f64) -> Vec<f64> {
        let Some(yaw) = self.robot.joints.first() else {
            return q;
        };
        if let Some(v) = q.first_mut() {
            if (yaw.lower..=yaw.upper).contains(&(*v + by)) {
                *v += by;
            }
        }
        q
    }

    fn leg(&self, to: &[f64], kind: SegmentKind, region: Option<usize>, allow: Allow) -> Leg {
        Leg {
            to: to.to_vec(),
            kind,
            region,
            allow,
        }
    }
}

/// How far contact `p` is pressed inside the surface, mm (removal mode's preload; 0 in rigid
/// mode, whose layers sit on or above nominal).
pub(super) fn pressed(p: &PlannedPoint) -> f64 {
    (-p.offset_mm).max(0.0)
}

impl Program {
    /// Appends `legs` from the last sample when every sample is clear for its leg; otherwise
    /// leaves the program as it was and returns the first hit.
    fn try_legs(&mut self, legs: &[Leg], cell: &Assembly) -> Result<Option<Hit>, PlanError> {
        let tc = &cell.cfg.trajectory;
        let mut trial = JointTrajectory::starting_at(self.trajectory.last(), tc.period);
        let mut ends = Vec::with_capacity(legs.len());
        for leg in legs {
            let from = trial.last().to_vec();
            let mv = Move::new(&from, &leg.to, &cell.limits, tc).map_err(|source| {
                PlanError::Trajectory {
                    context: format!("{:?} move", leg.kind),
                    source,
                }
            })?;
            trial.append_move(&mv);
            ends.push(trial.len() - 1);
        }
        let mut start = 0;
        let mut sweep = cell.scene.sweep();
        for (leg, &end) in legs.iter().zip(&ends) {
            for i in start + 1..=end {
                if let Some(hit) = sweep.check(cell.robot, trial.sample(i), leg.allow) {
                    return Ok(Some(hit));
                }
            }
            start = end;
        }
        let base = self.trajectory.len() - 1;
        let mut first = 0;
        for (leg, &end) in legs.iter().zip(&ends) {
            for i in first + 1..=end {
                self.trajectory.push(trial.sample(i));
            }
            self.cruise.extend(std::iter::repeat_n(false, end - first));
            self.segments.push(Segment {
                kind: leg.kind,
                region: leg.region,
                pass: None,
                first_sample: base + first,
                last_sample: base + end,
            });
            first = end;
        }
        Ok(None)
    }

    /// From the air (above `left`, or home) down onto contact `p`: a transit to a pose above
    /// it (its base yaw turned by `yaw_set` rad, `Assembly::yaw_set`) and an approach along
    /// its normal, the first clear of: one joint move; climbing to the safe height over
    /// `left`, across, and down over `p`; the same through home. The inner error is why `p`
    /// cannot be entered.
    pub(super) fn enter(
        &mut self,
        left: Option<&PlannedPoint>,
        (p, yaw_set): (&PlannedPoint, f64),
        region: usize,
        cell: &Assembly,
    ) -> Result<Result<(), String>, PlanError> {
        let press = pressed(p);
        let aboves: Vec<Vec<f64>> = (cell.lifted(p, cell.cfg.retract_mm + press).into_iter())
            .map(|q| cell.yaw_turned(q, yaw_set))
            .collect();
        if aboves.is_empty() {
            return Ok(Err("no approach pose above the contact".into()));
        }
        // removal mode: the approach ends with the ball touching the surface (contact rule),
        // the press-in goes on to the preload depth (grinding rule)
        let touch = match press > 0.0 {
            false => None,
            true => match cell.lifted(p, press).into_iter().next() {
                Some(q) => Some(q),
                None => return Ok(Err("no pose touching the surface above the contact".into())),
            },
        };
        let safe = cell.scene.config().safe_lift_mm;
        let up_from: Vec<Vec<f64>> = left
            .and_then(|l| cell.lifted(l, safe).into_iter().next())
            .into_iter()
            .collect();
        let up_to = cell.lifted(p, safe).into_iter().next();
        let mut why = String::from("no collision-free way in");
        for above in &aboves {
            let mut tries = vec![vec![above.clone()]];
            if let Some(ut) = &up_to {
                tries.push([up_from.clone(), vec![ut.clone(), above.clone()]].concat());
            }
            let down: Vec<Vec<f64>> = up_to.iter().cloned().chain([above.clone()]).collect();
            tries.push([up_from.clone(), vec![cell.cfg.home.clone()], down].concat());
            for waypoints in tries {
                let mut legs: Vec<Leg> = waypoints
                    .iter()
                    .map(|q| cell.leg(q, SegmentKind::Transit, None, Allow::Free))
                    .collect();
                match &touch {
                    None => {
                        legs.push(cell.leg(
                            &p.q,
                            SegmentKind::Approach,
                            Some(region),
                            Allow::Contact,
                        ));
                    }
                    Some(t) => {
                        legs.push(cell.leg(t, SegmentKind::Approach, Some(region), Allow::Contact));
                        legs.push(cell.leg(&p.q, SegmentKind::Press, Some(region), Allow::Grind));
                    }
                }
                match self.try_legs(&legs, cell)? {
                    None => return Ok(Ok(())),
                    Some(hit) => why = format!("no collision-free way in: {hit}"),
                }
            }
        }
        Ok(Err(why))
    }

    /// Up the normal off contact `p` (at the retract height, halved when the arm cannot): one
    /// joint move, else straight out in task space (see `straight_out`). The inner error says
    /// why none is clear.
    pub(super) fn retract(
        &mut self,
        p: &PlannedPoint,
        region: usize,
        cell: &Assembly,
    ) -> Result<Result<(), String>, PlanError> {
        let region = Some(region);
        let mut why = String::from("no retract pose above the contact");
        let press = pressed(p);
        // removal mode: out to touching the surface under the grinding rule, then up
        let out: Vec<Leg> = match press > 0.0 {
            false => Vec::new(),
            true => match cell.lifted(p, press).into_iter().next() {
                Some(t) => vec![cell.leg(&t, SegmentKind::Press, region, Allow::Grind)],
                None => Vec::new(),
            },
        };
        for above in cell.lifted(p, cell.cfg.retract_mm + press) {
            let mut legs = out.clone();
            legs.push(cell.leg(&above, SegmentKind::Retract, region, Allow::Contact));
            match self.try_legs(&legs, cell)? {
                None => return Ok(Ok(())),
                Some(hit) => why = hit.to_string(),
            }
        }
        let [x, y, z] = p.surface_mm;
        let failed = |why: String| {
            Ok(Err(format!(
                "retract from ({x:.2}, {y:.2}, {z:.2}) mm: {why}"
            )))
        };
        if let Some(hit) = self.try_legs(&out, cell)? {
            return failed(hit.to_string());
        }
        let up = cell.wc.direction_from_reference(&Vector3::from(p.normal));
        let back = -cell.robot.fk(self.trajectory.last()).axis;
        let mut dirs = vec![up];
        if crate::robot::angle_between(&up, &back).to_degrees() > SAME_DIRECTION_DEG {
            dirs.push(back);
        }
        for dir in dirs {
            match self.straight_out(&dir, region, cell)? {
                None => return Ok(Ok(())),
                Some(w) => why = format!("{why}; straight out: {w}"),
            }
        }
        failed(why)
    }

    /// From the last sample straight along `dir` (robot frame, unit) by the retract height in
    /// task space, the tool axis kept: IK every `STRAIGHT_STEP_MM`, sampled along the joint
    /// spline through them (a joint move between two poses bends the ball's path; near a
    /// second face the bend can dip it in). None when appended; else why not.
    fn straight_out(
        &mut self,
        dir: &Vector3<f64>,
        region: Option<usize>,
        cell: &Assembly,
    ) -> Result<Option<String>, PlanError> {
        let q0 = self.trajectory.last().to_vec();
        let pose = cell.robot.fk(&q0);
        let length = cell.cfg.retract_mm;
        let steps = (length / STRAIGHT_STEP_MM).ceil().max(1.0) as usize;
        let mut qs = vec![q0];
        for k in 1..=steps {
            let target = IkTarget {
                position: pose.position + dir * (metres(length) * k as f64 / steps as f64),
                axis: pose.axis,
                roll: None,
            };
            match cell.robot.ik(&target, &qs[k - 1], &cell.cfg.ik) {
                Ok(sol) => qs.push(sol.q),
                Err(e) => {
                    return Ok(Some(format!(
                        "no pose {:.2} mm out: {e}",
                        length * k as f64 / steps as f64
                    )))
                }
            }
        }
        let Some(samples) = follow(qs, cell) else {
            return Ok(Some("the joints cannot follow the line".into()));
        };
        Ok(self
            .append_checked(&samples, SegmentKind::Retract, region, cell)
            .map(|hit| hit.to_string()))
    }

    /// Appends `samples` (after the last one) as one segment when every one is clear under the
    /// contact rule; else leaves the program as it was and returns the first hit.
    fn append_checked(
        &mut self,
        samples: &[Vec<f64>],
        kind: SegmentKind,
        region: Option<usize>,
        cell: &Assembly,
    ) -> Option<Hit> {
        let mut sweep = cell.scene.sweep();
        if let Some(hit) = samples
            .iter()
            .find_map(|q| sweep.check(cell.robot, q, Allow::Contact))
        {
            return Some(hit);
        }
        let first = self.trajectory.len() - 1;
        for q in samples {
            self.trajectory.push(q);
        }
        self.cruise
            .extend(std::iter::repeat_n(false, samples.len()));
        self.segments.push(Segment {
            kind,
            region,
            pass: None,
            first_sample: first,
            last_sample: first + samples.len(),
        });
        None
    }

    /// Back home from the air above `left`: directly, or after climbing to the safe height
    /// (halved twice when the arm cannot, or when the way from there is not clear). The inner
    /// error says why none is clear.
    pub(super) fn home(
        &mut self,
        left: Option<&PlannedPoint>,
        cell: &Assembly,
    ) -> Result<Result<(), String>, PlanError> {
        let home = cell.leg(&cell.cfg.home, SegmentKind::Transit, None, Allow::Free);
        let mut tries = vec![vec![home.clone()]];
        if let Some(l) = left {
            for up in cell.lifted(l, cell.scene.config().safe_lift_mm) {
                let up = cell.leg(&up, SegmentKind::Transit, None, Allow::Free);
                tries.push(vec![up, home.clone()]);
            }
        }
        let mut why = String::new();
        for legs in tries {
            match self.try_legs(&legs, cell)? {
                None => return Ok(Ok(())),
                Some(hit) => why = hit.to_string(),
            }
        }
        Ok(Err(format!("transit home: {why}")))
    }

    /// Moves the ball from contact `a` to contact `b` in task space (straight line, tool axis
    /// turned about the ball centre) when they are at most `glide_mm` apart, the IK follows
    /// and every sample is clear; returns whether it did.
    pub(super) fn glide(
        &mut self,
        a: &PlannedPoint,
        b: &PlannedPoint,
        region: usize,
        cell: &Assembly,
    ) -> Result<bool, PlanError> {
        let (ta, tb) = (Vector3::from(a.tip_m), Vector3::from(b.tip_m));
        let (ua, ub) = (cell.robot.fk(&a.q).axis, cell.robot.fk(&b.q).axis);
        let last = self.trajectory.last().to_vec();
        if mm((tb - ta).norm()) > cell.scene.config().glide_mm || max_step(&last, &a.q) > 1e-12 {
            return Ok(false);
        }
        let turn =
            UnitQuaternion::rotation_between(&ua, &ub).unwrap_or_else(UnitQuaternion::identity);
        let steps = (turn.angle().to_degrees() / cell.scene.config().turn_step_deg)
            .ceil()
            .max(1.0) as usize;
        let mut qs = vec![a.q.clone()];
        for k in 1..=steps {
            let f = k as f64 / steps as f64;
            let q = if k == steps {
                b.q.clone()
            } else {
                let axis = UnitQuaternion::identity().slerp(&turn, f) * Unit::new_normalize(ua);
                let target = IkTarget {
                    position: ta + (tb - ta) * f,
                    axis: axis.into_inner(),
                    roll: None,
                };
                match cell.robot.ik(&target, &qs[k - 1], &cell.cfg.ik) {
                    Ok(sol) => sol.q,
                    Err(_) => return Ok(false),
                }
            };
            qs.push(q);
        }
        let Some(samples) = follow(qs, cell) else {
            return Ok(false);
        };
        Ok(self
            .append_checked(&samples, SegmentKind::Reorient, Some(region), cell)
            .is_none())
    }
}

/// Samples of the joint spline through `qs` (each waypoint's path length its largest joint
/// step from the one before) as fast as the joints allow, rest to rest; None when they cannot
/// follow it.
fn follow(qs: Vec<Vec<f64>>, cell: &Assembly) -> Option<Vec<Vec<f64>>> {
    let mut s = vec![0.0];
    for w in qs.windows(2) {
        let last = s[s.len() - 1];
        s.push(last + max_step(&w[1], &w[0]).max(1e-9));
    }
    let spline = JointSpline::new(s, qs);
    let most = |v: Vec<f64>| v.into_iter().fold(0.0, f64::max);
    let wanted = PathLimits {
        velocity: most(cell.limits.velocity.clone()),
        acceleration: most(cell.limits.acceleration.clone()),
        jerk: most(cell.limits.jerk.clone()),
    };
    let lim = path_limits(&spline, &cell.robot.joints, wanted, cell.cfg.joint_margin);
    sample_stroke(&spline, &lim, &cell.cfg.trajectory)
        .ok()
        .map(|(samples, _)| samples)
}

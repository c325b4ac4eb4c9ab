//! Splicing runs into one program from home back to home: each chain of pieces is reached by
//! a glide from the contact before it (when short and clear) or from the air, and a run or
//! chain whose way in or out is not clear is taken back and left out with the reason. The
//! free motions themselves are in `free_motion.rs`.
use super::collide::{Allow, Scene};
use super::config::PlanConfig;
use super::error::PlanError;
use super::free_motion::{pressed, Assembly};
use super::program::{Mark, PlannedPass, PlannedPoint, Program, Run};
use super::report::UnreachablePoint;
use super::trajectory::JointTrajectory;
use crate::robot::{Robot, Workcell};

/// Splices runs into one program from `home` back to `home`; a run the tool cannot enter
/// without a collision is left out (its points recorded with the reason).
pub(crate) fn assemble(
    runs: Vec<Run>,
    robot: &Robot,
    wc: &Workcell,
    cfg: &PlanConfig,
    scene: &Scene,
    unreachable: &mut Vec<UnreachablePoint>,
) -> Result<Program, PlanError> {
    let cell = Assembly::new(robot, wc, cfg, scene);
    let mut prog = Program {
        trajectory: JointTrajectory::starting_at(&cfg.home, cfg.trajectory.period),
        segments: Vec::new(),
        passes: Vec::new(),
        cruise: vec![false],
        slowed: 0,
    };
    if let Some(hit) = scene.check(robot, &cfg.home, Allow::Free) {
        return Err(PlanError::Config(format!("home pose collides: {hit}")));
    }
    // the contact the tool is on (None: in the air), the last one it left, and the pieces
    // ground since it came down
    let mut at = Where::default();
    for run in runs {
        for mut chain in chains(run) {
            let piece = &chain[0];
            let start = &piece.points[0];
            let before = prog.mark();
            let glided = match &at.on {
                // a pressed ball does not slide to another stroke: it would grind off the plan
                Some(_) if pressed(start) > 0.0 => false,
                Some((on, _)) => prog.glide(on, start, piece.region, &cell)?,
                None => false,
            };
            let ground = match glided {
                true => Ground {
                    mark: before,
                    on: at.on.clone(),
                },
                false => {
                    at.lift_off(&mut prog, &cell, unreachable)?;
                    let mark = prog.mark();
                    let way = (start, cell.yaw_set(piece));
                    if let Err(reason) = prog.enter(at.left.as_ref(), way, piece.region, &cell)? {
                        chain
                            .iter()
                            .for_each(|p| leave_out(p, &reason, unreachable));
                        continue;
                    }
                    at.entered.push((mark, at.left.clone()));
                    Ground { mark, on: None }
                }
            };
            let last = &chain[chain.len() - 1];
            at.on = last.points.last().cloned().map(|p| (p, last.region));
            at.since.push(ground);
            match chain[0].dwell_s.is_some() {
                true => prog.grind_chain(chain, robot, cfg)?,
                false => prog.grind(chain.remove(0), robot, cfg)?,
            }
        }
        at.lift_off(&mut prog, &cell, unreachable)?;
    }
    at.go_home(&mut prog, &cell, unreachable)?;
    Ok(prog)
}

/// Where the program stands: on a contact or in the air, and how it got there.
#[derive(Default)]
struct Where {
    /// The contact the tool is on (None: in the air) and its region.
    on: Option<(PlannedPoint, usize)>,
    /// The contact it last left.
    left: Option<PlannedPoint>,
    /// The pieces ground since it came down, in order.
    since: Vec<Ground>,
    /// Every descent onto the part: the program before it and the contact left then.
    entered: Vec<(Mark, Option<PlannedPoint>)>,
}

/// A piece ground: the program before the move onto it (glide or approach) and the contact
/// the tool was on then.
struct Ground {
    mark: Mark,
    on: Option<(PlannedPoint, usize)>,
}

impl Where {
    /// Takes the tool off the part. When no retract from its contact is clear, the last piece
    /// ground is taken back (with the move onto it) and left out with the reason, and the tool
    /// leaves from where it stood before that piece.
    fn lift_off(
        &mut self,
        prog: &mut Program,
        cell: &Assembly,
        unreachable: &mut Vec<UnreachablePoint>,
    ) -> Result<(), PlanError> {
        while let Some((at, region)) = self.on.take() {
            let why = match prog.retract(&at, region, cell)? {
                Ok(()) => {
                    self.left = Some(at);
                    self.since.clear();
                    return Ok(());
                }
                Err(why) => why,
            };
            let Some(last) = self.since.pop() else {
                return Err(PlanError::Collision(why));
            };
            let reason = format!("no clear retract after it: {why}");
            // a removal chain grinds several pieces in one go: all of them are taken back
            for piece in &prog.passes[last.mark.passes..] {
                leave_out(piece, &reason, unreachable);
            }
            prog.back_to(last.mark);
            if last.on.is_none() {
                // it was a descent from the air: that descent is gone too
                self.entered.pop();
            }
            self.on = last.on;
        }
        Ok(())
    }

    /// Back home from the air. When no way home is clear, the last descent onto the part is
    /// taken back with all it ground (left out with the reason), and the tool goes home from
    /// where it was before it.
    fn go_home(
        &mut self,
        prog: &mut Program,
        cell: &Assembly,
        unreachable: &mut Vec<UnreachablePoint>,
    ) -> Result<(), PlanError> {
        loop {
            let why = match prog.home(self.left.as_ref(), cell)? {
                Ok(()) => return Ok(()),
                Err(why) => why,
            };
            let Some((mark, left)) = self.entered.pop() else {
                return Err(PlanError::Collision(why));
            };
            let reason = format!("no clear way home after it: {why}");
            for piece in &prog.passes[mark.passes..] {
                leave_out(piece, &reason, unreachable);
            }
            prog.back_to(mark);
            self.left = left;
        }
    }
}

/// The run cut into what is ground in one go: in removal mode (pieces with a dwell) each
/// stretch of pieces where the next starts where the last ended (one stroke, ground without
/// stopping), in rigid mode every piece alone.
pub(super) fn chains(run: Run) -> Vec<Vec<PlannedPass>> {
    let mut out: Vec<Vec<PlannedPass>> = Vec::new();
    for piece in run {
        let joins = out.last().and_then(|c| c.last()).is_some_and(|prev| {
            let end = &prev.points[prev.points.len() - 1];
            piece.dwell_s.is_some() && prev.dwell_s.is_some() && end.q == piece.points[0].q
        });
        match (joins, out.last_mut()) {
            (true, Some(chain)) => chain.push(piece),
            _ => out.push(vec![piece]),
        }
    }
    out
}

/// Records every point of `piece` as left out.
pub(crate) fn leave_out(
    piece: &PlannedPass,
    reason: &str,
    unreachable: &mut Vec<UnreachablePoint>,
) {
    for (pi, p) in piece.points.iter().enumerate() {
        unreachable.push(UnreachablePoint {
            region: piece.region,
            layer: piece.layer,
            stroke: usize::MAX,
            point: pi,
            surface_mm: p.surface_mm,
            tip_m: p.tip_m,
            reason: reason.to_string(),
        });
    }
}

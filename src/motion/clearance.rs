//! The collision check of a whole sampled trajectory, by `plan` before it writes a plan and by
//! `run` before the first frame: every sample against the scene, with what its segment allows
//! (transits nothing, approach / retract / re-orientation a touch of the ball, grinding a touch
//! of the ball on one face).
use super::collide::{Allow, CollisionConfig, Scene};
use super::error::PlanError;
use super::file::Plan;
use super::program::{Segment, SegmentKind};
pub use super::report::Collision;
use crate::repair::Inspection;
use crate::robot::{Robot, Workcell};

/// What each of `n` samples may touch, and the segment it belongs to (the later one at a
/// joint): the loosest rule of its segments (where a transit meets an approach the sample is
/// the approach's start and may be near the part).
pub(super) fn allowances(segments: &[Segment], n: usize) -> Vec<(Allow, Option<usize>)> {
    let mut out = vec![(Allow::Free, None); n];
    for (k, s) in segments.iter().enumerate() {
        let last = s.last_sample.min(n.saturating_sub(1));
        for (allow, owner) in out.iter_mut().take(last + 1).skip(s.first_sample) {
            *owner = Some(k);
            *allow = match (*allow, s.kind) {
                (_, SegmentKind::Grind | SegmentKind::Press) | (Allow::Grind, _) => Allow::Grind,
                (_, SegmentKind::Transit) => *allow,
                _ => Allow::Contact,
            };
        }
    }
    out
}

/// Every sample of `samples` checked against `scene`; empty when all are clear.
pub fn check_samples<'q>(
    samples: impl ExactSizeIterator<Item = &'q [f64]>,
    segments: &[Segment],
    robot: &Robot,
    scene: &Scene,
) -> Vec<Collision> {
    let mut out = Vec::new();
    let rules = allowances(segments, samples.len());
    let mut sweep = scene.sweep();
    for (i, (q, &(allow, owner))) in samples.zip(&rules).enumerate() {
        if let Some(hit) = sweep.check(robot, q, allow) {
            let seg = owner.map(|k| &segments[k]);
            out.push(Collision {
                sample: i,
                segment: owner,
                kind: seg.map(|s| s.kind),
                region: seg.and_then(|s| s.region),
                hit,
            });
        }
    }
    out
}

impl Plan {
    /// Re-checks every sample of a loaded plan against the part of `inspection` (the one it
    /// was planned from, read again), placed by `wc`, and `cfg`'s solids.
    pub fn check_clearance(
        &self,
        inspection: &Inspection,
        robot: &Robot,
        wc: &Workcell,
        cfg: &CollisionConfig,
    ) -> Result<(), PlanError> {
        cfg.check(robot.dof()).map_err(PlanError::Config)?;
        // a removal plan presses the ball its preload in where it grinds
        let mut cfg = cfg.clone();
        cfg.press_mm = self.removal.as_ref().map_or(0.0, |r| r.preload_mm);
        let scene = Scene::new(&inspection.points, robot, wc, &cfg);
        let samples = self.samples.iter().map(|s| s.q.as_slice());
        let found = check_samples(samples, &self.segments, robot, &scene);
        if found.is_empty() {
            Ok(())
        } else {
            Err(PlanError::Collides(found))
        }
    }
}

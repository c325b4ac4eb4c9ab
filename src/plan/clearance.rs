//! The collision check of a whole sampled trajectory, by `plan` before it writes a plan and by
//! `run` before the first frame: every sample against the scene, with what its segment allows
//! (transits nothing, approach / retract / re-orientation a touch of the ball, grinding a touch
//! of the ball on one face).
use std::fmt;

use serde::{Deserialize, Serialize};

use super::collide::{Allow, CollisionConfig, Hit, Scene};
use super::program::{Segment, SegmentKind};
use super::{Inspection, Plan, PlanError};
use crate::robot::{Robot, Workcell};

/// One sample too near the part or a solid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Collision {
    /// Sample index.
    pub sample: usize,
    /// Index of the segment it belongs to (the later one at a joint of two).
    pub segment: Option<usize>,
    /// That segment's kind.
    pub kind: Option<SegmentKind>,
    /// That segment's region.
    pub region: Option<usize>,
    /// The colliding pair.
    pub hit: Hit,
}

impl fmt::Display for Collision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "sample {}", self.sample)?;
        if let (Some(s), Some(k)) = (self.segment, self.kind) {
            write!(f, " (segment {s}, {k:?}")?;
            if let Some(r) = self.region {
                write!(f, ", region {r}")?;
            }
            write!(f, ")")?;
        }
        write!(f, ": {}", self.hit)
    }
}

/// What sample `i` may touch: the loosest rule of the segments it belongs to (a sample where
/// a transit meets an approach is the approach's start and may be near the part).
fn allowance(segments: &[Segment], i: usize) -> (Allow, Option<usize>) {
    let mut allow = Allow::Free;
    let mut owner = None;
    for (k, s) in segments.iter().enumerate() {
        if s.first_sample <= i && i <= s.last_sample {
            owner = Some(k);
            allow = match (allow, s.kind) {
                (_, SegmentKind::Grind) | (Allow::Grind, _) => Allow::Grind,
                (_, SegmentKind::Transit) => allow,
                _ => Allow::Contact,
            };
        }
    }
    (allow, owner)
}

/// Every sample of `samples` checked against `scene`; empty when all are clear.
pub fn check_samples<'q>(
    samples: impl Iterator<Item = &'q [f64]>,
    segments: &[Segment],
    robot: &Robot,
    scene: &Scene,
) -> Vec<Collision> {
    let mut out = Vec::new();
    for (i, q) in samples.enumerate() {
        let (allow, owner) = allowance(segments, i);
        if let Some(hit) = scene.check(robot, q, allow) {
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
        let scene = Scene::new(&inspection.points, robot, wc, cfg);
        let samples = self.samples.iter().map(|s| s.q.as_slice());
        let found = check_samples(samples, &self.segments, robot, &scene);
        if found.is_empty() {
            Ok(())
        } else {
            Err(PlanError::Collides(found))
        }
    }
}

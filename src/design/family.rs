//! The designed cell on the part's family (issue 51, "design the cell for the part family"):
//! real implant families come in sizes (about 0.85-1.15 x) and as left and right knees
//! (mirror images). Each member is the part scaled about its centroid (the fixture point the
//! design mounts on the table axis) or mirrored through it, held as the cell holds the part:
//! the centroid on the table centre, every setup's mounting the part's (mirrored with a
//! mirrored part: the left knee on the right knee's fixture turned mirror-wise). A member's
//! coverage is scored as the part's (`eval::score`: the planner's IK and collision model on
//! the final samples), per setup and over the setups together.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use super::eval::{score, Candidate, Context};
use super::part::Part;
use super::setups::Fixturing;

/// The family's members scored besides the part: its sizes at the ends of an implant family
/// (0.85 and 1.15 x; the planners check held-out designs of about that range) and its mirror
/// image (the other knee), as (scale, mirrored).
pub const MEMBERS: [(f64, bool); 3] = [(0.85, false), (1.15, false), (1.0, true)];

/// One member of the family and what the designed cell reaches of it.
#[derive(Debug, Clone, Serialize)]
pub struct FamilyMember {
    /// Scale about the centroid.
    pub scale: f64,
    /// Mirrored through the centroid.
    pub mirrored: bool,
    /// Share of its articular-surface samples setup 1 reaches.
    pub coverage: f64,
    /// Share the setups reach together.
    pub union_coverage: f64,
}

/// Mirrors a vector along the part's first reference axis (any plane through the centroid
/// gives the same shape up to a turn; the mountings are mirrored alike).
fn mirror(v: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(-v.x, v.y, v.z)
}

/// `part` scaled by `scale` about its centroid, mirrored through it when `mirrored`.
pub fn member(part: &Part, scale: f64, mirrored: bool) -> Part {
    let c = part.centroid;
    let dir = |v: &Vector3<f64>| if mirrored { mirror(v) } else { *v };
    let at = |p: &Point3<f64>| c + dir(&(p - c)) * scale;
    let mut points = part.points.clone();
    for p in &mut points {
        p.position = at(&p.position);
        p.normal = dir(&p.normal);
    }
    Part {
        points,
        centroid: c,
        surface: part.surface.iter().map(|(p, n)| (at(p), dir(n))).collect(),
    }
}

/// Scores the cell `first` with the part's setups `fixturings` on each of [`MEMBERS`], on `n`
/// samples with table angles every `step_deg`.
pub fn family(
    ctx: &Context,
    first: &Candidate,
    fixturings: &[Fixturing],
    n: usize,
    step_deg: f64,
) -> Vec<FamilyMember> {
    MEMBERS
        .par_iter()
        .map(|&(scale, mirrored)| {
            let part = member(ctx.part, scale, mirrored);
            let sub = Context {
                part: &part,
                robots: ctx.robots,
                shanks: ctx.shanks,
                plan: ctx.plan,
                servo: ctx.servo.clone(),
            };
            let reached: Vec<Vec<bool>> = fixturings
                .iter()
                .map(|f| {
                    let m = Vector3::from(f.mount);
                    let m = if mirrored { mirror(&m) } else { m };
                    let c = Candidate {
                        mount: m.into(),
                        ..first.clone()
                    };
                    score(&sub, &c, n, step_deg, true).map_or_else(Vec::new, |s| {
                        s.verdicts.iter().map(|v| v.angle_deg.is_some()).collect()
                    })
                })
                .collect();
            let total = n.min(part.surface.len()).max(1);
            let share = |k: usize| {
                let hit = (0..total).filter(|&i| {
                    reached[..k]
                        .iter()
                        .any(|r| r.get(i).copied().unwrap_or(false))
                });
                hit.count() as f64 / total as f64
            };
            FamilyMember {
                scale,
                mirrored,
                coverage: share(1.min(reached.len())),
                union_coverage: share(reached.len()),
            }
        })
        .collect()
}

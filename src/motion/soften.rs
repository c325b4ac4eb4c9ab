//! A gentler contact before a lifted one (issue 50, Build 4: "a smaller influence (lower force
//! or smaller patch)"; issue 51: the share planned). The removal's limits (`removal::cap`: the
//! first grind's cap, the rim guard's budgets under the landing shifts) lift the tool over a
//! contact that, even at its shortest dwell (`piece / fastest feed`), removes more than a
//! point in its reach may lose. Before it is lifted it is commanded shallower: a spring-loaded
//! spindle pressed less deep presses with less force, so its Hertz patch is smaller (less
//! reach) and its pressure lower (less removal per second); but its removal lands farther from
//! its prediction, so its landing margin is at least `landing::SHALLOW_LANDING_MM`.
//! [`softened`] commands the contacts the limits lifted at [`MIN_DEPTH_SHARE`] of the preload
//! (0.5, the gentlest setting the planner commands: the spring still holds the ball on the part
//! through the servos' quantisation; the force halves, the patch's radius and peak pressure
//! fall by `0.5^(1/3)`, 21 %, and the spring's slide halves), ramped into their strokes as
//! `press_depth::DEPTH_SLOPE` asks; the caller walks the strokes again (the arm's joint angles
//! carry the shallower ball to the bus and the simulator) and solves the region again, where
//! the dwell solve, the limits and the Monte Carlo all read the commanded depth
//! (`Contact::depth_mm` -> `force_ratio`). A contact the limits still lift at that depth is
//! lifted.
use std::collections::HashMap;

use super::dwell;
use super::error::{DwellError, PlanError};
use super::press_depth::{ramp_stroke, MIN_DEPTH_SHARE};
use super::program::{PlannedPass, Run};
use super::raster::Stroke;
use super::report::{Reachability, UnreachablePoint};
use crate::repair::{Inspection, RegionInfo};

/// `limited`, the strokes of a region before the aim (`aim::aimed` moved them to `aimed`,
/// point for point, which the walk copied into the pieces' `surface_mm`), with every pressed
/// point of the `lifted` pieces commanded at most `depth` mm deep and the strokes ramped
/// (`press_depth::ramp_stroke`); None when no point got shallower.
pub(crate) fn softened(
    limited: &[Stroke],
    aimed: &[Stroke],
    lifted: &[PlannedPass],
    depth: f64,
) -> Option<Vec<Stroke>> {
    let at: HashMap<[u64; 3], (usize, usize)> = (aimed.iter().enumerate())
        .flat_map(|(si, s)| {
            (s.points.iter().enumerate()).map(move |(pi, p)| {
                let key = [p.surface.x, p.surface.y, p.surface.z].map(f64::to_bits);
                (key, (si, pi))
            })
        })
        .collect();
    let mut out = limited.to_vec();
    let mut changed = false;
    for p in lifted.iter().flat_map(|piece| &piece.points) {
        let Some(&(si, pi)) = at.get(&p.surface_mm.map(f64::to_bits)) else {
            continue;
        };
        let Some(point) = out.get_mut(si).and_then(|s| s.points.get_mut(pi)) else {
            continue;
        };
        if point.offset < -depth {
            point.offset = -depth;
            changed = true;
        }
    }
    if !changed {
        return None;
    }
    out.iter_mut().for_each(ramp_stroke);
    Some(out)
}

/// A region's strokes as walked, its walked runs and their dwell set at the configured
/// allowance (`dwell::set_dwell`).
pub(crate) struct Walked {
    pub(crate) runs: Vec<Run>,
    pub(crate) strokes: Vec<Stroke>,
    pub(crate) dwelled: Result<dwell::Dwelled, DwellError>,
}

/// The pieces of `w` the removal's limits lifted (`dwell::Dwelled::lifted`; every walked
/// piece when they lifted them all, [`DwellError::NothingToGrind`]) and how many one-contact
/// pieces are ground.
fn lifted_and_ground(w: &Walked) -> (Vec<PlannedPass>, usize) {
    match &w.dwelled {
        Ok(d) => (d.lifted.clone(), d.runs.iter().map(Vec::len).sum()),
        Err(DwellError::NothingToGrind { .. }) => (w.runs.iter().flatten().cloned().collect(), 0),
        Err(_) => (Vec::new(), 0),
    }
}

/// What aiming and walking a region's strokes again from its start gives: the aimed strokes,
/// the runs, the pose it ends at, the points it left out and its jumps.
pub(crate) type Rewalk = (
    Vec<Stroke>,
    Vec<Run>,
    Vec<f64>,
    Vec<UnreachablePoint>,
    usize,
);

/// Region `w` walked again with the contacts the removal's limits lifted commanded at
/// [`MIN_DEPTH_SHARE`] of the `preload` ([`softened`] of the region's strokes
/// before the aim, `limited`; `again` aims and walks strokes from the region's start), kept
/// when that grinds more of its one-contact pieces: then the end pose `prev`, the points left
/// out and the jumps of `reachability` (recorded from `mark`, their counts at the region's
/// start) follow the new walk. The contacts softened and still lifted are counted in
/// `reachability`. Without `limited` (a mount along the normal), or when nothing was lifted,
/// `w` comes back as it was.
pub(crate) fn soften_region(
    w: Walked,
    (limited, preload, again): (Option<&[Stroke]>, f64, impl Fn(&[Stroke]) -> Rewalk),
    (region, inspection, ctx): (&RegionInfo, &Inspection, &dwell::Setup),
    (prev, reachability, mark): (&mut Vec<f64>, &mut Reachability, (usize, usize)),
) -> Result<Walked, PlanError> {
    let (lifted, ground) = lifted_and_ground(&w);
    let depth = MIN_DEPTH_SHARE * preload;
    let soft = limited.and_then(|l| softened(l, &w.strokes, &lifted, depth));
    let Some(soft) = soft else {
        reachability.lifted += lifted.len();
        return Ok(w);
    };
    let (strokes, runs, at, lost, jumps) = again(&soft);
    let allowance = ctx.config.allowance_mm;
    let dwelled = match runs.is_empty() {
        true => Err(DwellError::NothingWalked),
        false => dwell::set_dwell(runs.clone(), region, inspection, ctx, allowance)?,
    };
    let kept = Walked {
        runs,
        strokes,
        dwelled,
    };
    let (still, now) = lifted_and_ground(&kept);
    tracing::info!(
        "region {}: {} contacts lifted over by the removal's limits, commanded {depth:.2} mm \
         deep instead: {} still lifted, one-contact pieces ground {ground} -> {now}",
        region.id,
        lifted.len(),
        still.len()
    );
    if now <= ground {
        reachability.lifted += lifted.len();
        return Ok(w);
    }
    reachability.softened += lifted.len().saturating_sub(still.len());
    reachability.lifted += still.len();
    *prev = at;
    reachability.unreachable.truncate(mark.0);
    reachability.unreachable.extend(lost);
    reachability.jumps = mark.1 + jumps;
    Ok(kept)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::program::PlannedPoint;
    use crate::motion::raster::{PathPoint, StrokeKind};
    use nalgebra::{Point3, Vector3};

    fn stroke(xs: &[f64], depth: f64) -> Stroke {
        Stroke {
            region: 0,
            layer: 0,
            kind: StrokeKind::Pass,
            points: (xs.iter())
                .map(|&x| PathPoint {
                    surface: Point3::new(x, 0.0, 0.0),
                    normal: Vector3::z(),
                    offset: -depth,
                })
                .collect(),
        }
    }

    fn piece(xs: &[f64]) -> PlannedPass {
        PlannedPass {
            region: 0,
            layer: 0,
            kind: StrokeKind::Pass,
            feed_mm_s: 1.0,
            dwell_s: None,
            contact_normal: None,
            points: (xs.iter())
                .map(|&x| PlannedPoint {
                    surface_mm: [x, 0.0, 0.0],
                    normal: [0.0, 0.0, 1.0],
                    offset_mm: -2.0,
                    tip_m: [0.0; 3],
                    axis: [0.0, 0.0, -1.0],
                    q: Vec::new(),
                    landed_mm: None,
                })
                .collect(),
        }
    }

    /// Points 1 mm apart at the 2 mm preload, the piece over x = 5..6 lifted: its two points
    /// go to 1 mm, their neighbours ramp back at 0.2 mm per mm, the far ends keep 2 mm; the
    /// aimed strokes (moved 0.3 mm) find the pre-aim points by index.
    #[test]
    fn a_lifted_piece_is_commanded_shallower_and_ramped_into_its_stroke() {
        let xs: Vec<f64> = (0..12).map(f64::from).collect();
        let limited = [stroke(&xs, 2.0)];
        let moved: Vec<f64> = xs.iter().map(|x| x + 0.3).collect();
        let aimed = [stroke(&moved, 2.0)];
        let out = softened(&limited, &aimed, &[piece(&[5.3, 6.3])], 1.0).expect("softened");
        let depth: Vec<f64> = out[0].points.iter().map(|p| -p.offset).collect();
        let want = [2.0, 1.8, 1.6, 1.4, 1.2, 1.0, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0];
        for (got, want) in depth.iter().zip(want) {
            assert!((got - want).abs() < 1e-12, "{depth:?}");
        }
        assert!(out[0]
            .points
            .iter()
            .zip(&limited[0].points)
            .all(|(a, b)| a.surface == b.surface));
        // nothing lifted, or already that shallow: no change
        assert!(softened(&limited, &aimed, &[], 1.0).is_none());
        assert!(softened(&out, &aimed, &[piece(&[5.3, 6.3])], 1.0).is_none());
    }
}

//! How deep a spring-loaded spindle is pressed at each contact (issue 50, "the arm as it
//! is"): tilted by theta from the measured normal, the spindle's spring compresses
//! `depth / cos` and the ball presses with `rate x depth / cos^2` (`removal::press::along_axis`),
//! 2.26 N at the 20 degree hold but 4 N at 45 degrees, more than a servo's share of its rated
//! torque holds (`removal::force`). Where the preload's force would be more than the arm
//! holds at the joint angles a first walk of the raster found, the contact is commanded
//! shallower: the depth at which the force at the start of the pass (the part's whole excess
//! still under the ball) is [`FORCE_HEADROOM`] of the largest force every servo holds along
//! the measured normal. The dwell solve then lengthens the dwell there, since the influence
//! follows the force the contact really has (`Contact::depth_mm` -> `force_ratio`); the
//! planner, its Monte Carlo and the simulator all see the shallower command. A contact that
//! would need less than [`MIN_DEPTH_SHARE`] of the preload keeps that much, and the force
//! check (`dwell::set_dwell`) then leaves its region out naming the joint and the force.
//! Method: docs/ALGORITHMS.md, "The mount's direction".
use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};

use super::dwell::Setup;
use super::program::{PlannedPass, PlannedPoint, Run};
use super::raster::Stroke;
use crate::removal::press::{along_axis, measured_at, MIN_AXIS_COS};
use crate::removal::{force, Contact, Influence};
use crate::repair::Inspection;
use crate::robot::Workcell;

/// Share of the largest force the servos hold that a shallower contact is pressed to (0.9):
/// the depth is found on the first walk's joint angles and axis; the plan's walk holds the
/// aimed point (moved up to `depth x tan(tilt)`, about 1-2 mm) at an axis a degree or so
/// apart, and at 45 degrees of tilt a degree changes `1 / cos^2` by 3.5 % and the joints'
/// lever arms by as much; the force check at the plan's own angles (`dwell::set_dwell`)
/// then still passes.
pub const FORCE_HEADROOM: f64 = 0.9;

/// Least share of the preload a contact is commanded below the surface (0.5, 1 mm of the
/// shipped 2 mm): the spring then still holds the ball on the part through the servos'
/// quantisation (plan.json `resolution_error_max_mm`, up to 0.72 mm of tip error on the
/// DOFBOT) instead of lifting off; a contact whose force is too much even there is left out
/// by the force check with the joint and the force named.
pub const MIN_DEPTH_SHARE: f64 = 0.5;

/// Largest change of the commanded depth along a stroke, mm per mm of stroke (0.2): where
/// the depth stepped from the preload to the limited one between neighbouring contacts (a
/// third of the patch radius apart, 0.2 mm) the stroke's path kinked and the trajectory's
/// tool tip strayed 0.100 mm from it on the femoral case (`max_path_error_mm` 0.1); a ramp
/// of 1 in 5 spreads a 1 mm change over 5 mm of stroke.
pub const DEPTH_SLOPE: f64 = 0.2;

/// `strokes` with each pressed point (negative offset) that the `trial` walk of the same
/// strokes solved commanded at the depth whose force the servos hold ([`depth_for`]), the
/// depths along each stroke then lowered where needed to change by at most [`DEPTH_SLOPE`];
/// points the trial left out, and every point when the tool gives along the normal (no
/// tilt amplifies its force), keep their offsets.
pub(crate) fn limited(
    strokes: &[Stroke],
    trial: &[Run],
    inspection: &Inspection,
    setup: &Setup,
) -> Vec<Stroke> {
    let held: HashMap<[u64; 3], &PlannedPoint> = trial
        .iter()
        .flatten()
        .flat_map(|pass| &pass.points)
        .map(|p| (p.surface_mm.map(f64::to_bits), p))
        .collect();
    let back = super::dwell::reference_from_robot(setup.workcell);
    let mut out = strokes.to_vec();
    if setup.tool.compliance_direction != crate::removal::ComplianceDirection::SpindleAxis {
        return out;
    }
    for stroke in &mut out {
        let mut depths: Vec<f64> = stroke.points.iter().map(|p| -p.offset).collect();
        for (point, d) in stroke.points.iter().zip(&mut depths) {
            let surface_mm = [point.surface.x, point.surface.y, point.surface.z];
            if let (Some(walked), true) = (held.get(&surface_mm.map(f64::to_bits)), *d > 0.0) {
                *d = d.min(depth_for(walked, &back, inspection, setup));
            }
        }
        for (point, d) in stroke.points.iter_mut().zip(depths) {
            if point.offset < 0.0 {
                point.offset = -d;
            }
        }
        ramp_stroke(stroke);
    }
    out
}

/// Lowers the depths of `stroke`'s pressed points (negative offsets) so that they change by
/// at most [`DEPTH_SLOPE`] per mm along it ([`ramped`]); the other points keep theirs.
pub(crate) fn ramp_stroke(stroke: &mut Stroke) {
    let mut depths: Vec<f64> = stroke.points.iter().map(|p| -p.offset).collect();
    let along: Vec<f64> = stroke
        .points
        .windows(2)
        .map(|w| (w[1].surface - w[0].surface).norm())
        .collect();
    ramped(&mut depths, &along);
    for (point, d) in stroke.points.iter_mut().zip(depths) {
        if point.offset < 0.0 {
            point.offset = -d;
        }
    }
}

/// Sets where each pressed point of `passes` (placed by `wc`) lands its patch
/// (`PlannedPoint::landed_mm`) for a spring-loaded spindle: the commanded point less
/// `depth x a_t / cos` along the nominal surface (a the spindle axis held, `a_t` its part
/// along the surface, cos its angle with the inward normal), the inverse of the aim
/// (`aim::aimed`); the coverage (`check::region_report`, plan.html's map) counts the surface
/// where the patches land, not the commanded points. A point tilted past
/// `press::MIN_AXIS_COS` keeps its commanded point.
pub(crate) fn land(passes: &mut [PlannedPass], wc: &Workcell) {
    let back = super::dwell::reference_from_robot(wc);
    for p in passes.iter_mut().flat_map(|pass| pass.points.iter_mut()) {
        let n = Vector3::from(p.normal);
        let Some(a) = (back * Vector3::from(p.axis)).try_normalize(1e-12) else {
            continue;
        };
        let cos = -n.dot(&a);
        if p.offset_mm >= 0.0 || cos < MIN_AXIS_COS {
            continue;
        }
        let landed = Vector3::from(p.surface_mm) - (a + n * cos) * (-p.offset_mm / cos);
        p.landed_mm = Some(landed.into());
    }
}

/// Lowers `depths` (one per point of a stroke, `along[i]` mm between points i and i + 1)
/// until neighbours differ by at most [`DEPTH_SLOPE`] per mm: each depth becomes the least
/// over the stroke of another's plus the slope times their distance (a forward and a
/// backward sweep).
fn ramped(depths: &mut [f64], along: &[f64]) {
    for i in 1..depths.len() {
        depths[i] = depths[i].min(depths[i - 1] + DEPTH_SLOPE * along[i - 1]);
    }
    for i in (0..depths.len().saturating_sub(1)).rev() {
        depths[i] = depths[i].min(depths[i + 1] + DEPTH_SLOPE * along[i]);
    }
}

/// The depth to command the ball below the surface at the walked point `p` (its joint angles
/// and the spindle axis held, robot frame; `back` turns robot-frame directions into the
/// reference frame): the tool's preload when its force at the start of the pass is within
/// [`FORCE_HEADROOM`] of what every servo holds along the measured normal, else the depth
/// whose force is (the force is linear in the depth while the ball touches), at least
/// [`MIN_DEPTH_SHARE`] of the preload.
pub(crate) fn depth_for(
    p: &PlannedPoint,
    back: &Matrix3<f64>,
    inspection: &Inspection,
    setup: &Setup,
) -> f64 {
    let (tool, robot) = (setup.tool, setup.robot);
    let ball = robot.tool.radius_mm();
    let normal = Vector3::from(p.normal);
    let point = nalgebra::Point3::from(p.surface_mm);
    let patch = Influence::new(tool, ball).patch_radius();
    let cores = inspection.points.as_slice();
    let part = measured_at(cores, setup.index, (&point, &normal), patch);
    let spin = (back * Vector3::from(p.axis)).normalize();
    // the force at the start of the pass: nothing removed yet (an allowance above any excess)
    let ratio = |depth_mm: f64| {
        let mut c = Contact {
            point,
            normal,
            // the press reads neither the stroke's direction nor its length
            along: Vector3::zeros(),
            spin,
            length: 0.0,
            force_ratio: 1.0,
            offset: Vector3::zeros(),
            depth_mm,
        };
        along_axis(&mut c, tool, ball, &part, f64::MAX);
        c.force_ratio
    };
    let (full, none) = (ratio(tool.preload_mm), ratio(0.0));
    let push = setup
        .workcell
        .direction_from_reference(&part.normal(&normal));
    let share = setup.config.force_share;
    let held = force::largest_force(robot, &p.q, &push.normalize(), share) * FORCE_HEADROOM;
    let allowed = held / tool.force_n();
    if full <= allowed || full - none <= 1e-12 {
        return tool.preload_mm;
    }
    let depth = tool.preload_mm * (allowed - none) / (full - none);
    depth.clamp(MIN_DEPTH_SHARE * tool.preload_mm, tool.preload_mm)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One shallow point in a row 0.5 mm apart: its neighbours ramp down to it at the slope
    /// (0.1 mm a step), the rest stay; the sweep never deepens a point.
    #[test]
    fn a_shallow_point_ramps_its_neighbours_down_at_the_slope() {
        let mut d = vec![2.0, 2.0, 2.0, 1.0, 2.0, 1.95];
        ramped(&mut d, &[0.5; 5]);
        let want = [1.3, 1.2, 1.1, 1.0, 1.1, 1.2];
        for (got, want) in d.iter().zip(want) {
            assert!((got - want).abs() < 1e-12, "{d:?}");
        }
        let mut flat = vec![2.0; 4];
        ramped(&mut flat, &[0.5; 3]);
        assert_eq!(flat, vec![2.0; 4]);
    }
}

//! Aiming a spring-loaded spindle (issue 50; tool.toml `compliance_direction =
//! "spindle_axis"`): the ball held `preload` below the surface slides back along the tilted
//! spindle axis until it touches, so its patch lands `preload x tan(tilt)` from under the
//! commanded centre, back toward the shank (`removal::press::along_axis`). Each pressed raster
//! point is moved that far the other way along the surface, by the axis the arm holds there
//! on a first walk of the raster, so that the patch lands on the raster's point. The removal
//! model takes the commanded point and the axis the arm really holds at it, so what is left of
//! the offset (the second walk holds a slightly different axis; the part's excess compresses
//! the spring further) is predicted, not ignored. Method: docs/ALGORITHMS.md, "The mount's
//! direction".
use std::collections::HashMap;

use nalgebra::{Matrix3, Vector3};

use super::program::Run;
use super::raster::Stroke;
use super::surface::Surface;

/// Smallest cosine of the held tilt from the surface normal at which a point is aimed (0.17,
/// cos 80 degrees, as `removal::press::MIN_AXIS_COS`): a tool laid flatter is left where the
/// raster put it rather than moved by tan(tilt) without bound.
const MIN_AIM_COS: f64 = 0.17;

/// A raster point's exact coordinates as a key (the walk copies them into `surface_mm`).
fn key(p: [f64; 3]) -> [u64; 3] {
    p.map(f64::to_bits)
}

/// `strokes` with every pressed point (negative offset) moved along the surface by
/// `-offset x a_t / cos`, a the unit spindle axis (shank to tip, reference frame) the `trial`
/// walk of the same strokes held there, `a_t` its part along the surface and cos its angle
/// with the inward normal; the moved point is projected onto `surface` with its normal there.
/// `back` turns robot-frame directions into the reference frame. Points the trial left out
/// stay where they were.
pub(crate) fn aimed(
    strokes: &[Stroke],
    trial: &[Run],
    back: &Matrix3<f64>,
    surface: &Surface,
) -> Vec<Stroke> {
    let held: HashMap<[u64; 3], Vector3<f64>> = trial
        .iter()
        .flatten()
        .flat_map(|pass| &pass.points)
        .map(|p| (key(p.surface_mm), back * Vector3::from(p.axis)))
        .collect();
    let mut out = strokes.to_vec();
    for point in out.iter_mut().flat_map(|s| s.points.iter_mut()) {
        let surface_mm = [point.surface.x, point.surface.y, point.surface.z];
        let Some(axis) = held.get(&key(surface_mm)) else {
            continue;
        };
        let (Some(a), true) = (axis.try_normalize(1e-12), point.offset < 0.0) else {
            continue;
        };
        let n = point.normal;
        let cos = -n.dot(&a);
        if cos < MIN_AIM_COS {
            continue;
        }
        let along_surface = a + n * cos;
        let (moved, normal) =
            surface.project(&(point.surface - along_surface * (point.offset / cos)));
        point.surface = moved;
        point.normal = normal;
    }
    out
}

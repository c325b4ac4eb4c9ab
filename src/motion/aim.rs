//! Where the planner aims each contact (issue 50, "learn where the tool really grinds"): the
//! loop registers each grind's measured removal against its plan (`cell::removal_shift`) and
//! hands the shift it measured to the next plan as an [`Aim`]. A removal planned at x landed
//! at x + s, so the next plan commands the tool at x - s (moved in the contact's tangent
//! plane): the contacts, the dwell and the prediction stay at x (where the removal is wanted),
//! only the tool target the IK solves for moves (`program::tool_target`). The part's
//! placement is not touched, so collisions and `run`'s checks see the commanded tool against
//! the part where it really sits. Before any grind was measured the shift is unknown: the rim
//! guard (`motion::dwell`) then holds every point's budget under landings anywhere within
//! the floor of the landing margin (`motion::landing::UNMEASURED_LANDING_MM`). A cap on what
//! one pass takes off any point, [`Aim::first_pass_share`], stays as a setting (plan.toml
//! `[plan.aim]`); the loop's first plan no longer sets it (docs/ALGORITHMS.md, "The first
//! grind, before any shift is known").
//!
//! The other correction is the model's own, known before any grind: a spring-loaded spindle
//! (tool.toml `compliance_direction = "spindle_axis"`) lands its patch away from the commanded
//! centre; [`aimed`] moves the raster points by it (below). The measured shift is what is left
//! after it.
//!
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

use nalgebra::{Matrix3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::raster::Stroke;
use super::surface::Surface;

/// A region's own measured shift, carried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AimRegion {
    /// Centre of the region the shift was measured on, reference frame, mm.
    pub centre_mm: [f64; 3],
    /// Distance from the centre within which a contact takes this region's shift, mm.
    pub reach_mm: f64,
    /// Where removal landed from where it was commanded, reference frame, mm (the sum of the
    /// shifts carried and measured so far).
    pub shift_mm: [f64; 3],
}

/// The correction the next plan applies: the measured shift of removal from the commanded
/// contact, per region and cell-wide. Empty by default (the planner aims where it grinds).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Aim {
    /// Share of the tolerance one pass takes off any point at most (None, the default:
    /// `removal.max_pass_mm` alone).
    pub first_pass_share: Option<f64>,
    /// The cell-wide shift (the regions' mean, weighted by their points), reference frame,
    /// mm: a contact farther than every region's reach takes it.
    pub common_mm: [f64; 3],
    /// Each measured region's own shift.
    pub regions: Vec<AimRegion>,
    /// How far beyond its plan's predicted footprint the removal of the loop's grinds reached,
    /// the largest over them, mm (`cell::removal_reach`; None: not measured yet). The landing
    /// margin is at least it and at least its floor either way
    /// (`motion::landing::landing_margins`, `motion::landing::UNMEASURED_LANDING_MM`).
    pub reach_mm: Option<f64>,
}

impl Aim {
    /// True when the aim changes nothing (plan.json then does not record it).
    pub fn is_empty(&self) -> bool {
        *self == Aim::default()
    }

    /// The shift removal lands at from a contact at `surface` (outward normal `normal`),
    /// reference frame, mm: the nearest region's within its reach, else the common shift;
    /// moved into the contact's tangent plane.
    pub fn shift_at(&self, surface: &Point3<f64>, normal: &Vector3<f64>) -> Vector3<f64> {
        let near = self
            .regions
            .iter()
            .map(|r| ((Point3::from(r.centre_mm) - surface).norm(), r))
            .filter(|(d, r)| *d <= r.reach_mm)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let s = Vector3::from(near.map_or(self.common_mm, |(_, r)| r.shift_mm));
        let n = normal.try_normalize(1e-12).unwrap_or_else(Vector3::zeros);
        s - n * n.dot(&s)
    }

    /// A point's removal target `target`, mm, capped at the first pass's share of
    /// `tolerance` while no shift is known.
    pub fn cap(&self, target: f64, tolerance: f64) -> f64 {
        self.first_pass_share
            .map_or(target, |s| target.min(s * tolerance))
    }

    /// Checks the values; the message names the key.
    pub fn check(&self) -> Result<(), String> {
        if let Some(s) = self
            .first_pass_share
            .filter(|s| !(0.01..=100.0).contains(s))
        {
            return Err(format!(
                "`aim.first_pass_share` = {s:?} is outside 0.01..=100 (x tolerance)"
            ));
        }
        if let Some(r) = self.reach_mm.filter(|r| !(r.is_finite() && *r >= 0.0)) {
            return Err(format!(
                "`aim.reach_mm` = {r:?} is not a finite distance >= 0 (mm)"
            ));
        }
        let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
        if !finite(&self.common_mm) {
            return Err("`aim.common_mm` is not a finite vector".into());
        }
        match self.regions.iter().position(|r| {
            !(finite(&r.centre_mm) && finite(&r.shift_mm) && r.reach_mm.is_finite())
                || r.reach_mm < 0.0
        }) {
            Some(i) => Err(format!(
                "`aim.regions[{i}]` has a value that is not finite (or a negative reach_mm)"
            )),
            None => Ok(()),
        }
    }
}

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
/// walk of the same strokes held there (each walked point's `surface_mm` and robot-frame axis),
/// `a_t` its part along the surface and cos its angle with the inward normal; the moved point is
/// projected onto `surface` with its normal there. `back` turns robot-frame directions into the
/// reference frame. Points the trial left out stay where they were.
pub(crate) fn aimed(
    strokes: &[Stroke],
    trial: impl IntoIterator<Item = ([f64; 3], [f64; 3])>,
    back: &Matrix3<f64>,
    surface: &Surface,
) -> Vec<Stroke> {
    let held: HashMap<[u64; 3], Vector3<f64>> = trial
        .into_iter()
        .map(|(at, axis)| (key(at), back * Vector3::from(axis)))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_contact_takes_its_region_shift_in_its_tangent_plane_else_the_common_one() {
        let aim = Aim {
            first_pass_share: None,
            common_mm: [1.0, 0.0, 0.0],
            regions: vec![AimRegion {
                centre_mm: [10.0, 0.0, 0.0],
                reach_mm: 3.0,
                shift_mm: [0.0, 2.0, 0.5],
            }],
            reach_mm: None,
        };
        let z = Vector3::z();
        let own = aim.shift_at(&Point3::new(11.0, 1.0, 0.0), &z);
        assert_eq!(own, Vector3::new(0.0, 2.0, 0.0));
        let far = aim.shift_at(&Point3::new(20.0, 0.0, 0.0), &Vector3::x());
        assert_eq!(
            far,
            Vector3::zeros(),
            "the common shift is along this normal"
        );
        let far = aim.shift_at(&Point3::new(20.0, 0.0, 0.0), &z);
        assert_eq!(far, Vector3::new(1.0, 0.0, 0.0));
        let capped = Aim {
            first_pass_share: Some(0.7),
            ..Aim::default()
        };
        assert!(Aim::default().is_empty() && !capped.is_empty());
        assert!((capped.cap(0.25, 0.05) - 0.035).abs() < 1e-12);
        assert_eq!(capped.cap(0.02, 0.05), 0.02);
        assert_eq!(aim.cap(0.25, 0.05), 0.25);
        let bad = Aim {
            common_mm: [f64::NAN, 0.0, 0.0],
            ..Aim::default()
        };
        assert!(bad.check().unwrap_err().contains("aim.common_mm"));
        let bad = Aim {
            reach_mm: Some(-1.0),
            ..Aim::default()
        };
        assert!(bad.check().unwrap_err().contains("aim.reach_mm"));
    }
}

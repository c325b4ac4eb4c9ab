//! The collision model's settings ([`CollisionConfig`]), the cell's fixed solids ([`Solid`],
//! `solids.toml`) and the distances the model measures to them.
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::spatial::Neighbours;

/// Settings of the collision model. Lengths in millimetres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CollisionConfig {
    /// Clearance every body keeps from the part and the solids during free motion, and the
    /// shank and links during grinding, mm (1.0: above the 0.1 mm path error and the tool
    /// tip's servo-resolution error, below the approach height).
    pub margin_mm: f64,
    /// How far the ball may be inside the nominal surface at and next to a contact (grinding,
    /// approach, retract, re-orientation), mm (0.1: the planner's `max_path_error_mm`).
    pub contact_tolerance_mm: f64,
    /// Two reference points inside the ball whose normals are more than this apart mean the
    /// ball touches a second face: the tool does not fit there, degrees (45).
    pub second_face_deg: f64,
    /// Capsule radius of the link after each actuated joint, base to wrist, mm ([30, 20, 20,
    /// 12]): the base turret, the two 40 mm wide servo brackets, the wrist with the tool motor
    /// (24 mm across). The link after the last joint is the tool (tool.toml). Estimates from
    /// the kit's parts: measure the real arm.
    pub link_radius_mm: Vec<f64>,
    /// Height along the surface normal a transit climbs to before it travels, when the
    /// direct move is not clear, mm (30: half the part's smallest extent in the default cell).
    pub safe_lift_mm: f64,
    /// Largest ball-centre move between two pieces of a run made as a straight line at the
    /// contact (a layer step, a turn about the ball centre), mm (0.5: one contact-point
    /// spacing); longer moves lift off, travel and come down again.
    pub glide_mm: f64,
    /// Angle step of the tool axis between the IK waypoints of a turn about the ball centre,
    /// degrees (1: the tip strays under 0.01 mm between waypoints).
    pub turn_step_deg: f64,
    /// Fixed solids of the cell (table, fixture), robot frame; `solids.toml` beside the
    /// workcell file adds its `[[solid]]` entries.
    pub solids: Vec<Solid>,
    /// How much deeper than `contact_tolerance_mm` the ball may be while grinding (and
    /// pressing in or out), mm: the compliant tool's preload in removal mode, set by the
    /// planner from tool.toml and by `run` from plan.json; 0 in rigid mode. Not a user key.
    #[serde(skip)]
    pub press_mm: f64,
}

impl Default for CollisionConfig {
    fn default() -> Self {
        CollisionConfig {
            margin_mm: 1.0,
            contact_tolerance_mm: 0.1,
            second_face_deg: 45.0,
            link_radius_mm: vec![30.0, 20.0, 20.0, 12.0],
            safe_lift_mm: 30.0,
            glide_mm: 0.5,
            turn_step_deg: 1.0,
            press_mm: 0.0,
            solids: Vec::new(),
        }
    }
}

impl CollisionConfig {
    /// Checks the values; names the key at fault.
    pub fn check(&self, dof: usize) -> Result<(), String> {
        let positive = [
            ("margin_mm", self.margin_mm),
            ("second_face_deg", self.second_face_deg),
            ("safe_lift_mm", self.safe_lift_mm),
            ("glide_mm", self.glide_mm),
            ("turn_step_deg", self.turn_step_deg),
        ];
        for (name, v) in positive {
            if !(v > 0.0 && v.is_finite()) {
                return Err(format!(
                    "`collision.{name}` = {v:?} must be finite and above 0"
                ));
            }
        }
        let tolerance = self.contact_tolerance_mm;
        if !(tolerance >= 0.0 && tolerance.is_finite()) {
            return Err(format!(
                "`collision.contact_tolerance_mm` = {tolerance:?} mm must be finite and >= 0"
            ));
        }
        if self.link_radius_mm.len() + 1 != dof {
            return Err(format!(
                "`collision.link_radius_mm` has {} radii, the arm {} links before the tool",
                self.link_radius_mm.len(),
                dof.saturating_sub(1)
            ));
        }
        if self
            .link_radius_mm
            .iter()
            .any(|r| !(*r >= 0.0 && r.is_finite()))
        {
            return Err("`collision.link_radius_mm`: every radius must be finite and >= 0".into());
        }
        for (i, s) in self.solids.iter().enumerate() {
            if !(0..3).all(|k| s.min[k] < s.max[k] && s.min[k].is_finite() && s.max[k].is_finite())
            {
                return Err(format!(
                    "`collision.solids` [{i}] ({}): min must be below max",
                    s.name
                ));
            }
        }
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SolidsFile {
    #[serde(default)]
    solid: Vec<Solid>,
}

/// The `[[solid]]` entries of `solids.toml` beside `workcell` (none when there is no such
/// file).
pub fn solids_beside(workcell: &std::path::Path) -> Result<Vec<Solid>, crate::robot::RobotError> {
    let file = workcell.with_file_name("solids.toml");
    if !file.exists() {
        return Ok(Vec::new());
    }
    solids_of(Some(&crate::robot::FileText::read(&file)?))
}

/// The `[[solid]]` entries of a solids.toml held in memory (none without one: a cell's
/// [`crate::robot::CellFiles::solids`]).
pub fn solids_of(
    file: Option<&crate::robot::FileText>,
) -> Result<Vec<Solid>, crate::robot::RobotError> {
    let Some(file) = file else {
        return Ok(Vec::new());
    };
    let parsed: SolidsFile = crate::robot::error::parse_toml(&file.path, &file.text)?;
    for (i, s) in parsed.solid.iter().enumerate() {
        let ok =
            (0..3).all(|k| s.min[k].is_finite() && s.max[k].is_finite() && s.min[k] < s.max[k]);
        if !ok {
            let msg = "min must be finite and below max on every axis";
            return Err(crate::robot::RobotError::bad(
                &file.path,
                format!("solid[{i}] ({})", s.name),
                msg,
            ));
        }
    }
    Ok(parsed.solid)
}

/// A fixed solid: an axis-aligned box in the robot base frame, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Solid {
    /// Name in messages ("table", "fixture post").
    pub name: String,
    /// Lowest corner, m.
    pub min: [f64; 3],
    /// Highest corner, m.
    pub max: [f64; 3],
}

/// Distance from `p` to the box `lo`..`hi`.
fn point_box_distance(p: &Point3<f64>, lo: &Point3<f64>, hi: &Point3<f64>) -> f64 {
    let d = Vector3::from_fn(|k, _| (lo[k] - p[k]).max(0.0).max(p[k] - hi[k]));
    d.norm()
}

/// Distance from the segment `a`-`b` to a box: the distance to a convex set is convex along
/// the segment, so a golden-section search finds its minimum.
pub(super) fn segment_box_distance(
    a: &Point3<f64>,
    b: &Point3<f64>,
    lo: &Point3<f64>,
    hi: &Point3<f64>,
) -> f64 {
    const ITERATIONS: usize = 60; // 0.618^60: 3e-13 of the segment
    let f = |t: f64| point_box_distance(&(a + (b - a) * t), lo, hi);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x0, mut x1) = (0.0, 1.0);
    for _ in 0..ITERATIONS {
        let (l, r) = (x1 - g * (x1 - x0), x0 + g * (x1 - x0));
        if f(l) <= f(r) {
            x1 = r;
        } else {
            x0 = l;
        }
    }
    f(0.5 * (x0 + x1)).min(f(0.0)).min(f(1.0))
}

/// Median distance from a reference point to its nearest other point, mm, over up to
/// `SAMPLES` points spread over the set.
pub(super) fn spacing(pos: &[Point3<f64>], index: &Neighbours) -> f64 {
    const SAMPLES: usize = 2000;
    let step = (pos.len() / SAMPLES).max(1);
    let mut d: Vec<f64> = pos
        .iter()
        .step_by(step)
        .filter_map(|p| index.knn(p, 2).get(1).map(|n| n.dist2.sqrt()))
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

//! The part turntable: a bus servo (`[turntable]` in `servos.toml`, driven with 0x19 frames)
//! turning the part about an axis of the robot frame (`[turntable]` in `workcell.toml`). The
//! workcell's `robot_from_reference` is the part's pose at table angle 0;
//! [`Turntable::workcell_at`] gives it at any angle. The URDF stays the arm's.
use std::path::Path;

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::Deserialize;

use super::calibration::{less, FileText, Servo, Servos, Workcell};
use super::error::{parse_toml, RobotError};

/// Lowest and highest bus id the 0x19 frame may address (DOFBOT.md: "any bus servo id
/// 1..250"); ids 1..=6 are the arm's.
const BUS_IDS: (u8, u8) = (7, 250);

/// The turntable of a cell.
#[derive(Debug, Clone, PartialEq)]
pub struct Turntable {
    /// Its servo: id, degree and raw ranges, zero offset, direction, `joint_limits` (the table
    /// angle's range, radians), velocity / acceleration / jerk limits of the table angle.
    pub servo: Servo,
    /// Rotation axis in the robot frame (unit); positive angles turn right-handed about it.
    pub axis: Unit<Vector3<f64>>,
    /// A point of the axis in the robot frame, metres.
    pub centre: Point3<f64>,
}

#[derive(Deserialize)]
struct WorkcellTable {
    turntable: Option<TableAxis>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TableAxis {
    axis: [f64; 3],
    centre: [f64; 3],
}

impl Turntable {
    /// The cell's turntable: `None` when neither `servos.toml` nor `workcell.toml` has a
    /// `[turntable]`; an error naming the file and key when only one has, or a value is bad.
    pub fn load(servos_file: &Path, workcell_file: &Path) -> Result<Option<Turntable>, RobotError> {
        Self::parse(
            &FileText::read(servos_file)?,
            &FileText::read(workcell_file)?,
        )
    }

    /// [`Turntable::load`] from servos.toml and workcell.toml held in memory.
    pub fn parse(servos: &FileText, workcell: &FileText) -> Result<Option<Turntable>, RobotError> {
        let (servos_file, workcell_file) = (servos.path.as_path(), workcell.path.as_path());
        let servos = Servos::parse(servos_file, &servos.text)?;
        let table: WorkcellTable = parse_toml(workcell_file, &workcell.text)?;
        let (servo, axis) = match (servos.turntable, table.turntable) {
            (None, None) => return Ok(None),
            (Some(s), Some(a)) => (s, a),
            (None, Some(_)) => {
                let msg = "workcell.toml has a [turntable] but servos.toml has none";
                return Err(RobotError::bad(servos_file, "turntable", msg));
            }
            (Some(_), None) => {
                let msg = "servos.toml has a [turntable] but this workcell has none";
                return Err(RobotError::bad(workcell_file, "turntable", msg));
            }
        };
        check_servo(servos_file, &servo, &servos.servos)?;
        let v = Vector3::from(axis.axis);
        if !(v.iter().all(|x| x.is_finite()) && v.norm() > 1e-9) {
            let msg = "must be a finite non-zero vector";
            return Err(RobotError::bad(workcell_file, "turntable.axis", msg));
        }
        if axis.centre.iter().any(|x| !x.is_finite()) {
            let msg = "must be finite (metres)";
            return Err(RobotError::bad(workcell_file, "turntable.centre", msg));
        }
        Ok(Some(Turntable {
            servo,
            axis: Unit::new_normalize(v),
            centre: Point3::from(axis.centre),
        }))
    }

    /// The table angle's range, radians: the servo's degree range mapped to the table,
    /// narrowed by `joint_limits`.
    pub fn range(&self) -> [f64; 2] {
        let [a, b] = self.servo.joint_range();
        match self.servo.joint_limits {
            Some([lo, hi]) => [a.max(lo), b.min(hi)],
            None => [a, b],
        }
    }

    /// Velocity, acceleration and jerk limits of the table angle (rad/s, /s^2, /s^3).
    pub fn limits(&self) -> [f64; 3] {
        [
            self.servo.velocity.unwrap_or(0.0),
            self.servo.acceleration.unwrap_or(0.0),
            self.servo.jerk.unwrap_or(0.0),
        ]
    }

    /// The rigid motion of the robot frame that turning the table by `angle` (radians) applies
    /// to whatever stands on it.
    pub fn motion(&self, angle: f64) -> Isometry3<f64> {
        let c = self.centre.coords;
        Isometry3::from_parts(Translation3::from(c), UnitQuaternion::identity())
            * Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&self.axis, angle),
            )
            * Isometry3::from_parts(Translation3::from(-c), UnitQuaternion::identity())
    }

    /// The part's placement at table angle `angle` (radians): `base` (the placement at 0)
    /// turned about the axis.
    pub fn workcell_at(&self, base: &Workcell, angle: f64) -> Workcell {
        Workcell {
            robot_from_reference: self.motion(angle).to_homogeneous() * base.robot_from_reference,
        }
    }

    /// The raw count the table servo is sent for table angle `angle` (radians): refused
    /// outside the table's range or the servo's raw range.
    pub fn raw(&self, angle: f64) -> Result<u16, String> {
        let [lo, hi] = self.range();
        if !(angle.is_finite() && angle >= lo - 1e-12 && angle <= hi + 1e-12) {
            return Err(format!(
                "table angle {:.3} deg outside {:.3}..={:.3} deg",
                angle.to_degrees(),
                lo.to_degrees(),
                hi.to_degrees()
            ));
        }
        let scale = self.servo.scale()?;
        let deg = self
            .servo
            .servo_deg(angle)
            .clamp(0.0, self.servo.degree_range[1]);
        scale.raw_from_deg(deg).map_err(|e| e.to_string())
    }

    /// The table angle (radians) of a raw count read back from the table servo.
    pub fn angle_from_raw(&self, raw: u16) -> Result<f64, String> {
        let scale = self.servo.scale()?;
        let deg = scale.deg_from_raw(raw).map_err(|e| e.to_string())?;
        Ok(self.servo.joint_from_deg(deg))
    }
}

/// The table servo's own checks (beyond those of an arm servo's fields): a bus id the arm does
/// not use, limits set and positive, ranges ordered, the raw range inside `raw_accepted`.
fn check_servo(file: &Path, s: &Servo, arm: &[Servo]) -> Result<(), RobotError> {
    let bad = |key: &str, msg: String| Err(RobotError::bad(file, format!("turntable.{key}"), msg));
    if s.id < BUS_IDS.0 || s.id > BUS_IDS.1 || arm.iter().any(|a| a.id == s.id) {
        return bad(
            "id",
            format!(
                "{} must be in {}..={} and not an arm servo's",
                s.id, BUS_IDS.0, BUS_IDS.1
            ),
        );
    }
    if s.joint.is_some() || s.hold_deg.is_some() {
        return bad(
            "joint",
            "the table has no URDF joint and no hold_deg".into(),
        );
    }
    if s.direction != 1 && s.direction != -1 {
        return bad("direction", "must be 1 or -1".into());
    }
    for (key, v) in [
        ("velocity", s.velocity),
        ("acceleration", s.acceleration),
        ("jerk", s.jerk),
    ] {
        if !matches!(v, Some(v) if v > 0.0 && v.is_finite()) {
            return bad(key, "must be set and > 0".into());
        }
    }
    if s.degree_range[0] != 0.0 || !less(s.degree_range[0], s.degree_range[1]) {
        return bad("degree_range", "must be [0, max]".into());
    }
    let [lo, hi] = s.raw_accepted;
    if lo >= hi
        || s.raw_range.iter().any(|r| *r < lo || *r > hi)
        || s.raw_range[0] >= s.raw_range[1]
    {
        return bad(
            "raw_range",
            "must be [min, max] inside raw_accepted [min, max]".into(),
        );
    }
    if let Some([a, b]) = s.joint_limits {
        if !less(a, b) {
            return bad("joint_limits", "must be [lower, upper] radians".into());
        }
    }
    let zero = s.zero_offset_deg;
    if !(zero >= s.degree_range[0] && zero <= s.degree_range[1]) {
        return bad(
            "zero_offset_deg",
            format!("{zero} lies outside degree_range"),
        );
    }
    Ok(())
}

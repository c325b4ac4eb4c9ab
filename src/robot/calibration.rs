//! The calibration files of a cell: `tool.toml`, `servos.toml`, `workcell.toml`
//! (formats documented in the files under `calibration/`).
use std::path::{Path, PathBuf};

use dofbot_protocol::ServoScale;
use nalgebra::{Matrix4, Point3, Vector3};
use serde::Deserialize;

use super::error::{parse_toml, read_text, RobotError};

/// `tool.toml`: the grinding tool on the wrist-roll flange.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tool {
    /// Name of the fixed URDF joint whose origin is set to `tip_offset`.
    pub joint: String,
    /// Tool tip (ball centre) in the flange frame, metres.
    pub tip_offset: [f64; 3],
    /// Tool axis in the flange frame (unit vector from shank to tip).
    pub axis: [f64; 3],
    /// Radius of the burr, metres.
    pub radius: f64,
    /// Radius of the burr's shank (the cylinder from the ball to the flange), metres; absent:
    /// [`Tool::DEFAULT_SHANK_RADIUS`].
    #[serde(default)]
    pub shank_radius: Option<f64>,
    /// Length of the shank from the ball centre towards the flange, metres; absent: the
    /// distance from the ball centre to the flange (`|tip_offset|`).
    #[serde(default)]
    pub shank_length: Option<f64>,
    /// The `[removal]` table: the compliant tool's removal model, typed and checked by its one
    /// reader `removal::ToolModel::from_table` (kept here unparsed: `robot` sits below
    /// `removal`, and this file's other keys stay strict).
    #[serde(default)]
    pub removal: Option<toml::Value>,
}

impl Tool {
    /// Radius of the burr, mm (the planners' unit on the part).
    pub fn radius_mm(&self) -> f64 {
        super::units::mm(self.radius)
    }

    /// Shank radius when tool.toml gives none, metres: 1.6 mm, the 3.2 mm (1/8 inch) shank of
    /// rotary-tool burrs with heads up to 6 mm (the default tool's 6 mm ball).
    pub const DEFAULT_SHANK_RADIUS: f64 = 0.0016;

    /// Shank radius, metres.
    pub fn shank_radius(&self) -> f64 {
        self.shank_radius.unwrap_or(Self::DEFAULT_SHANK_RADIUS)
    }

    /// Shank length from the ball centre towards the flange, metres.
    pub fn shank_length(&self) -> f64 {
        self.shank_length
            .unwrap_or_else(|| Vector3::from(self.tip_offset).norm())
    }

    /// Loads and checks `tool.toml`.
    pub fn load(file: &Path) -> Result<Self, RobotError> {
        FileText::read(file)?.tool()
    }

    /// Parses and checks the text of `tool.toml` (`file`, named in errors).
    pub fn parse(file: &Path, text: &str) -> Result<Self, RobotError> {
        let tool: Tool = parse_toml(file, text)?;
        let n = Vector3::from(tool.axis).norm();
        if n.is_nan() || (n - 1.0).abs() > 1e-9 {
            return Err(RobotError::bad(
                file,
                "axis",
                format!("must be a unit vector (norm {n})"),
            ));
        }
        if !(tool.radius > 0.0 && tool.radius < 0.05) {
            return Err(RobotError::bad(file, "radius", "must be in (0, 0.05) m"));
        }
        if tool
            .tip_offset
            .iter()
            .any(|v| !v.is_finite() || v.abs() > 0.5)
        {
            return Err(RobotError::bad(
                file,
                "tip_offset",
                "must be finite and under 0.5 m",
            ));
        }
        let reach = Vector3::from(tool.tip_offset).norm();
        if reach < tool.radius {
            return Err(RobotError::bad(
                file,
                "tip_offset",
                format!(
                    "the ball centre is {:.4} mm from the flange, less than the ball radius {:.4} mm: \
                     the ball would sit inside the flange (tip_offset is in metres, flange frame)",
                    super::units::mm(reach),
                    tool.radius_mm()
                ),
            ));
        }
        if let Some(r) = tool.shank_radius {
            if !(r > 0.0 && r <= tool.radius) {
                let msg = "must be in (0, radius] m (the shank is no wider than the ball)";
                return Err(RobotError::bad(file, "shank_radius", msg));
            }
        }
        if let Some(l) = tool.shank_length {
            if !(l.is_finite() && (0.0..=0.5).contains(&l)) {
                return Err(RobotError::bad(
                    file,
                    "shank_length",
                    "must be in [0, 0.5] m",
                ));
            }
        }
        Ok(tool)
    }
}

/// A file held in memory: its path (named in messages and recorded in provenance) and its
/// text. The cell's files are read once where a command starts, or written once as outputs
/// (the demo's cell, the loop's refitted tool), and handed on this way: never read back.
#[derive(Debug, Clone, PartialEq)]
pub struct FileText {
    /// Where the text is (or was written).
    pub path: PathBuf,
    /// The file's text.
    pub text: String,
}

/// A tool file held in memory ([`FileText`]): the loop hands the tool it refitted on this way
/// (tool.toml is written as an output and never read back).
pub type ToolText = FileText;

impl FileText {
    /// Reads `file`.
    pub fn read(file: &Path) -> Result<Self, RobotError> {
        Ok(FileText {
            path: file.to_path_buf(),
            text: read_text(file)?,
        })
    }

    /// The text parsed and checked as a tool file ([`Tool::parse`]).
    pub fn tool(&self) -> Result<Tool, RobotError> {
        Tool::parse(&self.path, &self.text)
    }
}

/// One bus servo of `servos.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Servo {
    /// Bus id (1..6 on the DOFBOT).
    pub id: u8,
    /// URDF joint this servo drives; `None` for the gripper.
    #[serde(default)]
    pub joint: Option<String>,
    /// Servo degrees at joint zero.
    #[serde(default = "default_zero_offset")]
    pub zero_offset_deg: f64,
    /// +1 or -1: sign of servo degrees per joint degree.
    #[serde(default = "default_direction")]
    pub direction: i8,
    /// Servo degree range `[min, max]`.
    pub degree_range: [f64; 2],
    /// Raw counts at the ends of `degree_range` (before any inversion), read by the bus side.
    pub raw_range: [u16; 2],
    /// True when raw counts run opposite to servo degrees (Yahboom's servos 2, 3, 4).
    #[serde(default)]
    pub raw_inverted: bool,
    /// Raw counts the servo accepts; a read-back outside is a failed read.
    pub raw_accepted: [u16; 2],
    /// Optional narrower joint limits `[lower, upper]`, radians.
    #[serde(default)]
    pub joint_limits: Option<[f64; 2]>,
    /// Joint velocity limit, rad/s (joint servos only).
    #[serde(default)]
    pub velocity: Option<f64>,
    /// Joint acceleration limit, rad/s^2 (joint servos only).
    #[serde(default)]
    pub acceleration: Option<f64>,
    /// Joint jerk limit, rad/s^3 (joint servos only).
    #[serde(default)]
    pub jerk: Option<f64>,
    /// Servo degrees a servo without a joint (the gripper) is held at.
    #[serde(default)]
    pub hold_deg: Option<f64>,
    /// Rated torque, N m: the removal model's force check keeps the static joint torque of
    /// the contact force within a share of it (joint servos only).
    #[serde(default)]
    pub rated_torque_nm: Option<f64>,
}

fn default_zero_offset() -> f64 {
    90.0
}

fn default_direction() -> i8 {
    1
}

impl Servo {
    /// Servo degrees for joint angle `q` (radians): `zero_offset_deg + direction * q_deg`.
    pub fn servo_deg(&self, q: f64) -> f64 {
        self.zero_offset_deg + f64::from(self.direction) * q.to_degrees()
    }

    /// Joint angle (radians) for servo degrees `deg`: the inverse of [`Servo::servo_deg`].
    pub fn joint_from_deg(&self, deg: f64) -> f64 {
        ((deg - self.zero_offset_deg) * f64::from(self.direction)).to_radians()
    }

    /// Raw counts per servo degree (about 12.2 on the DOFBOT).
    pub fn counts_per_degree(&self) -> f64 {
        let raw = f64::from(self.raw_range[1]) - f64::from(self.raw_range[0]);
        raw.abs() / (self.degree_range[1] - self.degree_range[0])
    }

    /// The servo's angle <-> raw scale on the wire (dofbot-protocol's [`ServoScale`]):
    /// `degree_range` `[0, max]` onto `raw_range`; refused (the message names the servo) when
    /// the range does not start at 0, which the protocol's scale cannot express.
    pub fn scale(&self) -> Result<ServoScale, String> {
        if self.degree_range[0] != 0.0 {
            return Err(format!(
                "servo {}: the bus needs degree_range to start at 0 (got {:?})",
                self.id, self.degree_range[0]
            ));
        }
        Ok(ServoScale {
            id: self.id,
            deg_max: self.degree_range[1],
            raw_min: self.raw_range[0],
            raw_max: self.raw_range[1],
            inverted: self.raw_inverted,
        })
    }

    /// The joint range the servo's degree range allows, `[lower, upper]` radians.
    pub fn joint_range(&self) -> [f64; 2] {
        let a = self.joint_from_deg(self.degree_range[0]);
        let b = self.joint_from_deg(self.degree_range[1]);
        [a.min(b), a.max(b)]
    }
}

/// `servos.toml`: the bus period and every servo.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Servos {
    /// Bus period, seconds (one six-servo frame per period).
    pub period: f64,
    /// The servos, in any order.
    #[serde(rename = "servo")]
    pub servos: Vec<Servo>,
    /// The part turntable's servo (`[turntable]`, bus id 7 on the cell of
    /// `calibration/turntable/`), if the cell has one: see [`super::turntable`].
    #[serde(default)]
    pub turntable: Option<Servo>,
    /// The arm's joint stiffness, backlash and lumped masses (`[compliance]`, written by
    /// `calibrate compliance`); without it the planner commands a rigid arm.
    #[serde(default)]
    pub compliance: Option<Compliance>,
}

impl Servos {
    /// Loads and checks `servos.toml`.
    pub fn load(file: &Path) -> Result<Self, RobotError> {
        Self::parse(file, &read_text(file)?)
    }

    /// Parses and checks the text of `servos.toml` (`file`, named in errors).
    pub fn parse(file: &Path, text: &str) -> Result<Self, RobotError> {
        let s: Servos = parse_toml(file, text)?;
        if let Some((key, why)) = s.compliance.as_ref().and_then(|c| c.problem()) {
            return Err(RobotError::bad(file, key, why));
        }
        if !(s.period > 0.0 && s.period <= 1.0) {
            return Err(RobotError::bad(file, "period", "must be in (0, 1] s"));
        }
        for (i, servo) in s.servos.iter().enumerate() {
            let key = |k: &str| format!("servo[{i}].{k}");
            if s.servos[..i].iter().any(|o| o.id == servo.id) {
                return Err(RobotError::bad(
                    file,
                    key("id"),
                    format!("id {} repeats", servo.id),
                ));
            }
            if servo.direction != 1 && servo.direction != -1 {
                return Err(RobotError::bad(file, key("direction"), "must be 1 or -1"));
            }
            if let Some(t) = servo.rated_torque_nm {
                if !(t > 0.0 && t <= 100.0) {
                    let msg = format!("{t} must be in (0, 100] N m");
                    return Err(RobotError::bad(file, key("rated_torque_nm"), msg));
                }
            }
            if !less(servo.degree_range[0], servo.degree_range[1]) {
                return Err(RobotError::bad(
                    file,
                    key("degree_range"),
                    "must be [min, max]",
                ));
            }
            let [lo, hi] = servo.raw_accepted;
            if servo.raw_range.iter().any(|r| *r < lo || *r > hi) || lo >= hi {
                let msg = "raw_range must lie inside raw_accepted [min, max]";
                return Err(RobotError::bad(file, key("raw_range"), msg));
            }
            if servo.raw_range[0] == servo.raw_range[1] {
                return Err(RobotError::bad(file, key("raw_range"), "ends must differ"));
            }
            if servo.joint.is_some() {
                for (name, v) in [
                    ("velocity", servo.velocity),
                    ("acceleration", servo.acceleration),
                    ("jerk", servo.jerk),
                ] {
                    match v {
                        Some(v) if v > 0.0 && v.is_finite() => {}
                        _ => return Err(RobotError::bad(file, key(name), "must be set and > 0")),
                    }
                }
                if let Some([a, b]) = servo.joint_limits {
                    if !less(a, b) {
                        return Err(RobotError::bad(
                            file,
                            key("joint_limits"),
                            "must be [lower, upper]",
                        ));
                    }
                }
            } else {
                match servo.hold_deg {
                    Some(d) if d >= servo.degree_range[0] && d <= servo.degree_range[1] => {}
                    _ => {
                        let msg = "a servo without a joint needs hold_deg inside degree_range";
                        return Err(RobotError::bad(file, key("hold_deg"), msg));
                    }
                }
            }
        }
        Ok(s)
    }

    /// The servo without a joint (the gripper), if any.
    pub fn gripper(&self) -> Option<&Servo> {
        self.servos.iter().find(|s| s.joint.is_none())
    }

    /// The servo driving URDF joint `joint`.
    pub fn for_joint(&self, joint: &str) -> Option<&Servo> {
        self.servos
            .iter()
            .find(|s| s.joint.as_deref() == Some(joint))
    }
}

/// `workcell.toml`: where the part's reference frame sits in the robot base frame.
///
/// Units: the reference (CAD) frame of the point clouds is in millimetres, the robot in metres.
/// `robot_from_reference` is a rigid transform in metres: it maps a reference-frame point
/// expressed in metres (millimetres / 1000) to the robot base frame. Use
/// [`Workcell::point_from_reference_mm`] and [`Workcell::direction_from_reference`].
#[derive(Debug, Clone, PartialEq)]
pub struct Workcell {
    /// The 4x4 rigid transform, metres.
    pub robot_from_reference: Matrix4<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WorkcellFile {
    robot_from_reference: [[f64; 4]; 4],
    /// The turntable's axis and centre: read by [`super::turntable::Turntable::load`].
    #[serde(default)]
    #[allow(dead_code)]
    turntable: Option<toml::Value>,
}

/// Farthest a workcell may place the part from the robot base, m (5): the DOFBOT reaches
/// about 0.35 m and a turntable sits beside it, so a translation over this is a millimetre
/// value written into the metres file (the probe's 280.0 for 0.28 m planned "0 passes").
pub const MAX_PART_DISTANCE_M: f64 = 5.0;

impl Workcell {
    /// Loads and checks `workcell.toml` (rows of the matrix, last row `[0, 0, 0, 1]`).
    pub fn load(file: &Path) -> Result<Self, RobotError> {
        Self::parse(file, &read_text(file)?)
    }

    /// Parses and checks the text of `workcell.toml` (`file`, named in errors).
    pub fn parse(file: &Path, text: &str) -> Result<Self, RobotError> {
        let raw: WorkcellFile = parse_toml(file, text)?;
        let rows = raw.robot_from_reference;
        let m = Matrix4::from_fn(|r, c| rows[r][c]);
        let key = "robot_from_reference";
        if m.iter().any(|v| !v.is_finite()) {
            return Err(RobotError::bad(file, key, "values must be finite"));
        }
        if (m.fixed_slice::<1, 4>(3, 0) - nalgebra::RowVector4::new(0.0, 0.0, 0.0, 1.0)).norm()
            > 1e-12
        {
            return Err(RobotError::bad(file, key, "last row must be [0, 0, 0, 1]"));
        }
        let r = m.fixed_slice::<3, 3>(0, 0);
        let err = (r.transpose() * r - nalgebra::Matrix3::identity()).norm();
        if err > 1e-6 || r.determinant() < 0.0 {
            let msg = format!(
                "upper-left 3x3 must be a rotation (|R^T R - I| = {err:.2e}, determinant {:.3})",
                r.determinant()
            );
            return Err(RobotError::bad(file, key, msg));
        }
        let far = m.fixed_slice::<3, 1>(0, 3).norm();
        if far > MAX_PART_DISTANCE_M {
            let msg = format!(
                "the part lies {far:.3} m from the robot base, over {MAX_PART_DISTANCE_M} m \
                 (the file is in metres: a value in millimetres?)"
            );
            return Err(RobotError::bad(file, key, msg));
        }
        Ok(Workcell {
            robot_from_reference: m,
        })
    }

    /// A reference-frame point given in millimetres, in the robot base frame (metres).
    pub fn point_from_reference_mm(&self, p_mm: &Point3<f64>) -> Point3<f64> {
        self.robot_from_reference
            .transform_point(&super::units::metres(*p_mm))
    }

    /// A reference-frame direction (unitless), in the robot base frame.
    pub fn direction_from_reference(&self, d: &Vector3<f64>) -> Vector3<f64> {
        self.robot_from_reference.fixed_slice::<3, 3>(0, 0) * d
    }
}

/// `a < b`, false when either is NaN.
/// The arm's joint stiffness, gear backlash and lumped masses (servos.toml `[compliance]`).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Compliance {
    /// Stiffness of each joint (base to wrist roll), N m per rad.
    pub stiffness_nm_rad: [f64; 5],
    /// Full width of each joint's gear dead band, degrees.
    pub backlash_deg: [f64; 5],
    /// The lumped masses, kg (see [`LUMPED_MASSES`]).
    pub masses_kg: [f64; LUMPED_MASSES],
}

/// Range of a joint's stiffness in `[compliance]`, N m/rad (1 to 1e7): the DOFBOT's joints
/// are about 110-120 (5 mm of sag at full reach); under 1 a newton-metre would turn a joint a
/// radian (the probe's 1e-300 was accepted), and `calibrate compliance` writes at most 1e6
/// (its compliance floor, 1e-6 rad/N m) for a joint the touches find rigid.
pub const STIFFNESS_RANGE_NM_RAD: (f64, f64) = (1.0, 1e7);

impl Compliance {
    /// The first problem of the table (`[compliance]` key and why), if any.
    pub fn problem(&self) -> Option<(String, String)> {
        let bad =
            |key: &str, i: usize, why: &str| Some((format!("compliance.{key}[{i}]"), why.into()));
        for (i, k) in self.stiffness_nm_rad.iter().enumerate() {
            if !(STIFFNESS_RANGE_NM_RAD.0..=STIFFNESS_RANGE_NM_RAD.1).contains(k) {
                return bad("stiffness_nm_rad", i, "must be in 1..1e7 N m/rad");
            }
        }
        for (i, b) in self.backlash_deg.iter().enumerate() {
            if !(0.0..=10.0).contains(b) {
                return bad("backlash_deg", i, "must be in 0..10 degrees");
            }
        }
        for (i, m) in self.masses_kg.iter().enumerate() {
            if !(0.0..=10.0).contains(m) {
                return bad("masses_kg", i, "must be in 0..10 kg");
            }
        }
        None
    }
}

/// Lumped masses of the model: the elbow, wrist-pitch and wrist-roll joints' origins and the
/// tool tip (a link's own mass splits exactly between its two ends for every joint upstream
/// of both, so four points carry any mass distribution along the chain).
pub const LUMPED_MASSES: usize = 4;

pub(crate) fn less(a: f64, b: f64) -> bool {
    matches!(a.partial_cmp(&b), Some(std::cmp::Ordering::Less))
}

//! The joint <-> servo map of the arm: URDF joint radians to servo degrees to raw counts
//! (through dofbot-protocol's [`ServoScale`], the one servo-scale type), with the joint limits
//! and the gripper. Plan builds its frames with it, the bus reads joint states back with it:
//! one calibration for both. The default is DOFBOT.md's mapping with zero offsets;
//! [`ServoMap::from_robot`] makes it from the cell's `servos.toml` and URDF limits.
use serde::{Deserialize, Serialize};

use dofbot_protocol::servo::{ServoId, ServoScale, SERVO_COUNT};

use super::model::Robot;

/// Number of arm joints (the gripper is the sixth servo).
pub const JOINT_COUNT: usize = 5;

/// A value or a map the servo map refuses (a joint outside its limits, an angle outside a
/// servo's span, an inconsistent map). The bus reports it as a refused motion.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("refused: {0}")]
pub struct MapRefused(pub String);

/// Why [`ServoMap::from_robot`] cannot map the robot's servos.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ServoMapError {
    /// `servos.toml` and the URDF do not describe a five-joint arm with a gripper servo.
    #[error("{0}")]
    Calibration(String),
    /// The map made from them does not validate.
    #[error(transparent)]
    Refused(#[from] MapRefused),
}

/// The protocol scale of servo `id` from a map's stored scale, checked against the hardware
/// ranges.
fn scale_of(id: u8, scale: &ServoScale) -> Result<ServoScale, MapRefused> {
    let s = ServoScale { id, ..*scale };
    s.validate()
        .map_err(|e| MapRefused(format!("servo map: {e}")))?;
    Ok(s)
}

impl JointCalib {
    /// The checked protocol scale of this joint's servo (id = `servo`).
    pub fn servo_scale(&self) -> Result<ServoScale, MapRefused> {
        scale_of(self.servo, &self.scale)
    }
}

impl GripperCalib {
    /// The checked protocol scale of the gripper servo (id = `servo`).
    pub fn servo_scale(&self) -> Result<ServoScale, MapRefused> {
        scale_of(self.servo, &self.scale)
    }
}

/// The TOML/JSON keys of a scale in a map (`deg_max`, `raw_min`, `raw_max`, `inverted`; the id
/// is the joint's `servo`, set when the map is read).
mod scale_keys {
    use dofbot_protocol::servo::ServoScale;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    use super::{GripperCalib, JointCalib};

    /// The joints with each scale's id set to the joint's servo.
    pub fn joints<'de, D: Deserializer<'de>>(de: D) -> Result<Vec<JointCalib>, D::Error> {
        let mut joints = Vec::<JointCalib>::deserialize(de)?;
        for j in &mut joints {
            j.scale.id = j.servo;
        }
        Ok(joints)
    }

    /// The gripper with its scale's id set to its servo.
    pub fn gripper<'de, D: Deserializer<'de>>(de: D) -> Result<GripperCalib, D::Error> {
        let mut g = GripperCalib::deserialize(de)?;
        g.scale.id = g.servo;
        Ok(g)
    }

    #[derive(Serialize, Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Keys {
        deg_max: f64,
        raw_min: u16,
        raw_max: u16,
        inverted: bool,
    }

    /// Writes the scale `s` as its keys (its id is the joint's `servo`, not written).
    pub fn serialize<S: Serializer>(s: &ServoScale, ser: S) -> Result<S::Ok, S::Error> {
        Keys {
            deg_max: s.deg_max,
            raw_min: s.raw_min,
            raw_max: s.raw_max,
            inverted: s.inverted,
        }
        .serialize(ser)
    }

    /// Reads a scale from its keys (the id set later, from the joint's `servo`).
    pub fn deserialize<'de, D: Deserializer<'de>>(de: D) -> Result<ServoScale, D::Error> {
        let k = Keys::deserialize(de)?;
        Ok(ServoScale {
            id: 0,
            deg_max: k.deg_max,
            raw_min: k.raw_min,
            raw_max: k.raw_max,
            inverted: k.inverted,
        })
    }
}

/// One arm joint (URDF radians) and its servo: `servo_deg = zero_deg + direction*q*180/pi +
/// offset_deg`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointCalib {
    /// URDF joint name.
    pub name: String,
    /// Servo id, 1..=5.
    pub servo: u8,
    /// Servo degrees at joint zero (DOFBOT.md: 90).
    pub zero_deg: f64,
    /// +1 or -1.
    pub direction: f64,
    /// Calibration offset, degrees (0 until measured).
    pub offset_deg: f64,
    /// Lower joint limit, rad (URDF).
    pub lower_rad: f64,
    /// Upper joint limit, rad (URDF).
    pub upper_rad: f64,
    /// Velocity limit, rad/s (URDF: 1.0).
    pub max_velocity_rad_s: f64,
    /// Servo scale (a config file gives `deg_max`, `raw_min`, `raw_max`, `inverted`; its `id`
    /// is `servo`).
    #[serde(with = "scale_keys")]
    pub scale: ServoScale,
}

/// The gripper servo, commanded in servo degrees (0 open, 180 closed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperCalib {
    /// Servo id (6).
    pub servo: u8,
    /// Calibration offset, degrees.
    pub offset_deg: f64,
    /// Smallest commandable angle, degrees.
    pub min_deg: f64,
    /// Largest commandable angle, degrees.
    pub max_deg: f64,
    /// Servo scale (a config file gives `deg_max`, `raw_min`, `raw_max`, `inverted`; its `id`
    /// is `servo`).
    #[serde(with = "scale_keys")]
    pub scale: ServoScale,
}

/// Joints 1..5 and the gripper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoMap {
    /// The five arm joints, in chain order.
    #[serde(deserialize_with = "scale_keys::joints")]
    pub joints: Vec<JointCalib>,
    /// The gripper.
    #[serde(deserialize_with = "scale_keys::gripper")]
    pub gripper: GripperCalib,
}

/// DOFBOT.md's URDF limits, in chain order (rad), as the URDF writes them (not exactly pi/2).
#[allow(clippy::approx_constant)]
const URDF_LIMITS: [(&str, f64, f64); JOINT_COUNT] = [
    ("arm_joint1", -1.5708, 1.5708),
    ("arm_joint2", -1.5708, 1.5708),
    ("arm_joint3", -1.5708, 1.5708),
    ("arm_joint4", -1.5708, 1.5708),
    ("arm_joint5", -1.5708, 3.14159),
];
/// URDF velocity limit, rad/s.
const URDF_VELOCITY: f64 = 1.0;
/// DOFBOT.md: servo 90 deg is joint zero.
const ZERO_DEG: f64 = 90.0;

impl Default for ServoMap {
    fn default() -> Self {
        let joints = URDF_LIMITS
            .iter()
            .zip(ServoId::ALL)
            .map(|(&(name, lower, upper), id)| JointCalib {
                name: name.to_string(),
                servo: id.get(),
                zero_deg: ZERO_DEG,
                direction: 1.0,
                offset_deg: 0.0,
                lower_rad: lower,
                upper_rad: upper,
                max_velocity_rad_s: URDF_VELOCITY,
                scale: id.scale(),
            })
            .collect();
        let gid = ServoId::ALL[SERVO_COUNT - 1];
        let gripper = GripperCalib {
            servo: gid.get(),
            offset_deg: 0.0,
            min_deg: 0.0,
            max_deg: gid.scale().deg_max,
            scale: gid.scale(),
        };
        ServoMap { joints, gripper }
    }
}

/// Joint positions of the arm plus the gripper angle and the raw counts they came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointState {
    /// Joints 1..5, rad (URDF convention).
    pub joints: [f64; JOINT_COUNT],
    /// Gripper servo angle, degrees.
    pub gripper_deg: f64,
    /// Raw positions of servos 1..6.
    pub raw: [u16; SERVO_COUNT],
}

impl ServoMap {
    /// Checks the map: five joints on servos 1..5 in order, gripper on 6, consistent limits
    /// and scales, and every joint limit inside its servo's span.
    pub fn validate(&self) -> Result<(), MapRefused> {
        let bad = |m: String| Err(MapRefused(format!("servo map: {m}")));
        if self.joints.len() != JOINT_COUNT {
            return bad(format!("{} joints, need {JOINT_COUNT}", self.joints.len()));
        }
        for (i, j) in self.joints.iter().enumerate() {
            if j.servo as usize != i + 1 {
                return bad(format!("joint {} must use servo {}", j.name, i + 1));
            }
            j.servo_scale()?;
            if j.lower_rad.partial_cmp(&j.upper_rad) != Some(std::cmp::Ordering::Less)
                || (j.direction != 1.0 && j.direction != -1.0)
            {
                return bad(format!("joint {}: limits or direction", j.name));
            }
            if j.max_velocity_rad_s.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return bad(format!("joint {}: max_velocity_rad_s must be > 0", j.name));
            }
            for q in [j.lower_rad, j.upper_rad] {
                self.joint_raw(i, q)?;
            }
        }
        let g = &self.gripper;
        if g.servo as usize != SERVO_COUNT {
            return bad(format!("gripper must use servo {SERVO_COUNT}"));
        }
        g.servo_scale()?;
        if g.min_deg
            .partial_cmp(&g.max_deg)
            .is_none_or(|o| o == std::cmp::Ordering::Greater)
        {
            return bad("gripper min_deg > max_deg".into());
        }
        Ok(())
    }

    /// Raw position of joint `i` (0-based) at `q` rad; refused outside the joint limits or the
    /// servo's span.
    pub fn joint_raw(&self, i: usize, q: f64) -> Result<u16, MapRefused> {
        let j = &self.joints[i];
        // Limits are compared after rounding to 1e-9 rad so the URDF's 5-digit pi/2 is usable.
        if !q.is_finite() || q < j.lower_rad - 1e-9 || q > j.upper_rad + 1e-9 {
            return Err(MapRefused(format!(
                "{} = {q} rad outside its limits {}..{} rad",
                j.name, j.lower_rad, j.upper_rad
            )));
        }
        let deg = j.zero_deg + j.direction * q.to_degrees() + j.offset_deg;
        let deg = snap(deg, j.scale.deg_max);
        j.servo_scale()?
            .raw_from_deg(deg)
            .map_err(|e| MapRefused(format!("{}: {e}", j.name)))
    }

    /// Joint `i` (0-based) in rad from its servo's raw position.
    pub fn joint_from_raw(&self, i: usize, raw: u16) -> Result<f64, MapRefused> {
        let j = &self.joints[i];
        let deg = j
            .servo_scale()?
            .deg_from_raw(raw)
            .map_err(|e| MapRefused(format!("{}: {e}", j.name)))?;
        Ok(((deg - j.offset_deg - j.zero_deg) * j.direction).to_radians())
    }

    /// Raw position of the gripper at `deg` servo degrees.
    pub fn gripper_raw(&self, deg: f64) -> Result<u16, MapRefused> {
        let g = &self.gripper;
        if !deg.is_finite() || deg < g.min_deg || deg > g.max_deg {
            return Err(MapRefused(format!(
                "gripper {deg} deg outside {}..{} deg",
                g.min_deg, g.max_deg
            )));
        }
        g.servo_scale()?
            .raw_from_deg(deg + g.offset_deg)
            .map_err(|e| MapRefused(format!("gripper: {e}")))
    }

    /// Gripper angle in degrees from its raw position.
    pub fn gripper_from_raw(&self, raw: u16) -> Result<f64, MapRefused> {
        let g = &self.gripper;
        let deg = g
            .servo_scale()?
            .deg_from_raw(raw)
            .map_err(|e| MapRefused(format!("gripper: {e}")))?;
        Ok(deg - g.offset_deg)
    }

    /// Raw positions of all six servos for joints `q` (rad) and gripper angle (deg).
    pub fn pose_raw(
        &self,
        q: &[f64; JOINT_COUNT],
        gripper_deg: f64,
    ) -> Result<[u16; SERVO_COUNT], MapRefused> {
        let mut raw = [0u16; SERVO_COUNT];
        for (i, qi) in q.iter().enumerate() {
            raw[i] = self.joint_raw(i, *qi)?;
        }
        raw[SERVO_COUNT - 1] = self.gripper_raw(gripper_deg)?;
        Ok(raw)
    }

    /// Joint state from six raw positions.
    pub fn state_from_raw(&self, raw: [u16; SERVO_COUNT]) -> Result<JointState, MapRefused> {
        let mut joints = [0.0; JOINT_COUNT];
        for (i, q) in joints.iter_mut().enumerate() {
            *q = self.joint_from_raw(i, raw[i])?;
        }
        let gripper_deg = self.gripper_from_raw(raw[SERVO_COUNT - 1])?;
        Ok(JointState {
            joints,
            gripper_deg,
            raw,
        })
    }

    /// The raw pose at joint zero with the gripper at `gripper_deg` (the simulators' start).
    pub fn home_raw(&self, gripper_deg: f64) -> Result<[u16; SERVO_COUNT], MapRefused> {
        self.pose_raw(&[0.0; JOINT_COUNT], gripper_deg)
    }
}

/// Angles this close outside a servo's span (degrees) are moved onto its end: the URDF's
/// limits (1.5708 for pi/2) land 0.0002 deg outside otherwise. 1e-3 deg is 0.012 raw counts.
const SNAP_DEG: f64 = 1e-3;

/// Moves an angle that lies within [`SNAP_DEG`] outside `0..=max` onto the end.
fn snap(deg: f64, max: f64) -> f64 {
    if (-SNAP_DEG..0.0).contains(&deg) {
        0.0
    } else if deg > max && deg - max < SNAP_DEG {
        max
    } else {
        deg
    }
}

impl ServoMap {
    /// The map from the robot's `servos.toml` and joint limits (one calibration for planner
    /// and bus); the gripper is the servo without a joint.
    pub fn from_robot(robot: &Robot) -> Result<ServoMap, ServoMapError> {
        let calib = |m: String| ServoMapError::Calibration(m);
        if robot.dof() != JOINT_COUNT {
            return Err(calib(format!(
                "the bus drives {JOINT_COUNT} joints, the robot has {}",
                robot.dof()
            )));
        }
        let mut joints = Vec::new();
        for spec in &robot.joints {
            let servo = robot
                .servos
                .servos
                .iter()
                .find(|s| s.id == spec.servo_id)
                .ok_or_else(|| calib(format!("no servo {}", spec.servo_id)))?;
            joints.push(JointCalib {
                name: spec.name.clone(),
                servo: servo.id,
                zero_deg: servo.zero_offset_deg,
                direction: f64::from(servo.direction),
                offset_deg: 0.0,
                lower_rad: spec.lower,
                upper_rad: spec.upper,
                max_velocity_rad_s: spec.velocity,
                scale: servo.scale().map_err(calib)?,
            });
        }
        let g = robot
            .servos
            .gripper()
            .ok_or_else(|| calib(NO_GRIPPER.into()))?;
        let map = ServoMap {
            joints,
            gripper: GripperCalib {
                servo: g.id,
                offset_deg: 0.0,
                min_deg: g.degree_range[0],
                max_deg: g.degree_range[1],
                scale: g.scale().map_err(calib)?,
            },
        };
        map.validate()?;
        Ok(map)
    }
}

/// The message when `servos.toml` has no servo without a joint.
pub const NO_GRIPPER: &str = "servos.toml has no gripper servo (one without a joint)";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_follow_dofbot_md() {
        let m = ServoMap::default();
        m.validate().unwrap();
        // Joint zero is servo 90 deg: raw 2000 on servos 1..4, 1487 on the wrist roll.
        assert_eq!(
            m.home_raw(90.0).unwrap(),
            [2000, 2000, 2000, 2000, 1487, 2000]
        );
        // Joint 2 at +pi/2 -> servo 180 deg -> inverted raw 900.
        assert_eq!(m.joint_raw(1, std::f64::consts::FRAC_PI_2).unwrap(), 900);
        assert!(m.joint_raw(0, 1.6).is_err());
        assert!(m.joint_raw(4, 3.2).is_err());
        assert!(m.joint_raw(0, f64::NAN).is_err());
        assert!(m.gripper_raw(181.0).is_err());
    }
}

//! Driver settings and the servo map (joint <-> servo degrees, limits, scales), all data:
//! the defaults are DOFBOT.md's mapping with zero offsets, and a TOML file (later
//! `calibration/servos.toml`) can replace any of it.
use serde::{Deserialize, Serialize};

use dofbot_protocol::servo::{ServoId, ServoScale, SERVO_COUNT};

use super::error::BusError;

/// Number of arm joints (the gripper is the sixth servo).
pub const JOINT_COUNT: usize = 5;

/// Settings of the bus driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BusConfig {
    /// Minimum gap between two frames, ms. Default 10 (Yahboom's Arm_Lib pauses about 10 ms
    /// before a write).
    pub frame_gap_ms: f64,
    /// Time to wait for a reply per attempt, ms. Default 50 (the board answers in about 3 ms).
    pub read_timeout_ms: f64,
    /// Attempts per request (reads and pings fail now and then). Default 4.
    pub attempts: u32,
    /// Extra wait after a move's commanded time before reading back, ms. Default 100.
    pub settle_ms: f64,
    /// Largest allowed difference between commanded and read-back raw, counts. Default 12
    /// (about 1 degree: the backlash DOFBOT.md reports).
    pub verify_tolerance_counts: u16,
    /// Check when connecting that all six servos answer (each is read; a servo is pinged
    /// only when its read gets no reply: see `bus::alive`). Default true.
    pub ping_at_connect: bool,
    /// Joint and servo mapping.
    pub servo_map: ServoMap,
}

impl Default for BusConfig {
    fn default() -> Self {
        BusConfig {
            frame_gap_ms: 10.0,
            read_timeout_ms: 50.0,
            attempts: 4,
            settle_ms: 100.0,
            verify_tolerance_counts: 12,
            ping_at_connect: true,
            servo_map: ServoMap::default(),
        }
    }
}

/// Longest accepted wait setting (`frame_gap_ms`, `settle_ms`), ms: every wait of the driver
/// is far below this, and a larger value would only stall a run (and overflow a `Duration`
/// near 1e300).
pub const MAX_WAIT_MS: f64 = 10_000.0;
/// Longest accepted reply timeout, ms (the board answers in about 3 ms).
pub const MAX_TIMEOUT_MS: f64 = 10_000.0;
/// Shortest accepted reply timeout, ms (below a frame's time on the line no reply can come).
pub const MIN_TIMEOUT_MS: f64 = 1.0;
/// Most attempts per request (each costs up to a timeout).
pub const MAX_ATTEMPTS: u32 = 20;
/// Largest accepted read-back tolerance, counts (about 40 degrees: beyond it a read-back
/// verifies nothing).
pub const MAX_VERIFY_COUNTS: u16 = 500;

impl BusConfig {
    /// Checks every timing setting against its range (the servo map is checked by
    /// [`ServoMap::validate`]); the message names the key in backticks.
    pub fn check(&self) -> Result<(), BusError> {
        let ms = [
            ("frame_gap_ms", self.frame_gap_ms, 0.0, MAX_WAIT_MS),
            (
                "read_timeout_ms",
                self.read_timeout_ms,
                MIN_TIMEOUT_MS,
                MAX_TIMEOUT_MS,
            ),
            ("settle_ms", self.settle_ms, 0.0, MAX_WAIT_MS),
        ];
        for (key, v, lo, hi) in ms {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return Err(BusError::Refused(format!(
                    "`{key}` = {v:?} ms is outside {lo}..={hi} ms"
                )));
            }
        }
        if !(1..=MAX_ATTEMPTS).contains(&self.attempts) {
            return Err(BusError::Refused(format!(
                "`attempts` = {} is outside 1..={MAX_ATTEMPTS}",
                self.attempts
            )));
        }
        if self.verify_tolerance_counts > MAX_VERIFY_COUNTS {
            return Err(BusError::Refused(format!(
                "`verify_tolerance_counts` = {} counts is outside 0..={MAX_VERIFY_COUNTS} counts",
                self.verify_tolerance_counts
            )));
        }
        Ok(())
    }
}

/// Angle <-> raw scale of one servo (DOFBOT.md's table by default).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleCalib {
    /// Angle span, degrees.
    pub deg_max: f64,
    /// Raw at 0 degrees (at `deg_max` when inverted).
    pub raw_min: u16,
    /// Raw at `deg_max` (at 0 when inverted).
    pub raw_max: u16,
    /// Raw decreases as the angle grows.
    pub inverted: bool,
}

impl ScaleCalib {
    fn dofbot(id: ServoId) -> ScaleCalib {
        let s = id.scale();
        ScaleCalib {
            deg_max: s.deg_max,
            raw_min: s.raw_min,
            raw_max: s.raw_max,
            inverted: s.inverted,
        }
    }

    /// The protocol scale of servo `id`, checked against the hardware ranges.
    pub fn to_scale(&self, id: u8) -> Result<ServoScale, BusError> {
        let s = ServoScale {
            id,
            deg_max: self.deg_max,
            raw_min: self.raw_min,
            raw_max: self.raw_max,
            inverted: self.inverted,
        };
        s.validate()
            .map_err(|e| BusError::Refused(format!("servo map: {e}")))?;
        Ok(s)
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
    /// Servo scale.
    pub scale: ScaleCalib,
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
    /// Servo scale.
    pub scale: ScaleCalib,
}

/// Joints 1..5 and the gripper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoMap {
    /// The five arm joints, in chain order.
    pub joints: Vec<JointCalib>,
    /// The gripper.
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
                scale: ScaleCalib::dofbot(id),
            })
            .collect();
        let gid = ServoId::ALL[SERVO_COUNT - 1];
        let gripper = GripperCalib {
            servo: gid.get(),
            offset_deg: 0.0,
            min_deg: 0.0,
            max_deg: gid.scale().deg_max,
            scale: ScaleCalib::dofbot(gid),
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
    pub fn validate(&self) -> Result<(), BusError> {
        let bad = |m: String| Err(BusError::Refused(format!("servo map: {m}")));
        if self.joints.len() != JOINT_COUNT {
            return bad(format!("{} joints, need {JOINT_COUNT}", self.joints.len()));
        }
        for (i, j) in self.joints.iter().enumerate() {
            if j.servo as usize != i + 1 {
                return bad(format!("joint {} must use servo {}", j.name, i + 1));
            }
            j.scale.to_scale(j.servo)?;
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
        g.scale.to_scale(g.servo)?;
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
    pub fn joint_raw(&self, i: usize, q: f64) -> Result<u16, BusError> {
        let j = &self.joints[i];
        // Limits are compared after rounding to 1e-9 rad so the URDF's 5-digit pi/2 is usable.
        if !q.is_finite() || q < j.lower_rad - 1e-9 || q > j.upper_rad + 1e-9 {
            return Err(BusError::Refused(format!(
                "{} = {q} rad outside its limits {}..{} rad",
                j.name, j.lower_rad, j.upper_rad
            )));
        }
        let deg = j.zero_deg + j.direction * q.to_degrees() + j.offset_deg;
        let deg = snap(deg, j.scale.deg_max);
        j.scale
            .to_scale(j.servo)?
            .raw_from_deg(deg)
            .map_err(|e| BusError::Refused(format!("{}: {e}", j.name)))
    }

    /// Joint `i` (0-based) in rad from its servo's raw position.
    pub fn joint_from_raw(&self, i: usize, raw: u16) -> Result<f64, BusError> {
        let j = &self.joints[i];
        let deg = j
            .scale
            .to_scale(j.servo)?
            .deg_from_raw(raw)
            .map_err(|e| BusError::Refused(format!("{}: {e}", j.name)))?;
        Ok(((deg - j.offset_deg - j.zero_deg) * j.direction).to_radians())
    }

    /// Raw position of the gripper at `deg` servo degrees.
    pub fn gripper_raw(&self, deg: f64) -> Result<u16, BusError> {
        let g = &self.gripper;
        if !deg.is_finite() || deg < g.min_deg || deg > g.max_deg {
            return Err(BusError::Refused(format!(
                "gripper {deg} deg outside {}..{} deg",
                g.min_deg, g.max_deg
            )));
        }
        g.scale
            .to_scale(g.servo)?
            .raw_from_deg(deg + g.offset_deg)
            .map_err(|e| BusError::Refused(format!("gripper: {e}")))
    }

    /// Gripper angle in degrees from its raw position.
    pub fn gripper_from_raw(&self, raw: u16) -> Result<f64, BusError> {
        let g = &self.gripper;
        let deg = g
            .scale
            .to_scale(g.servo)?
            .deg_from_raw(raw)
            .map_err(|e| BusError::Refused(format!("gripper: {e}")))?;
        Ok(deg - g.offset_deg)
    }

    /// Raw positions of all six servos for joints `q` (rad) and gripper angle (deg).
    pub fn pose_raw(
        &self,
        q: &[f64; JOINT_COUNT],
        gripper_deg: f64,
    ) -> Result<[u16; SERVO_COUNT], BusError> {
        let mut raw = [0u16; SERVO_COUNT];
        for (i, qi) in q.iter().enumerate() {
            raw[i] = self.joint_raw(i, *qi)?;
        }
        raw[SERVO_COUNT - 1] = self.gripper_raw(gripper_deg)?;
        Ok(raw)
    }

    /// Joint state from six raw positions.
    pub fn state_from_raw(&self, raw: [u16; SERVO_COUNT]) -> Result<JointState, BusError> {
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
    pub fn home_raw(&self, gripper_deg: f64) -> Result<[u16; SERVO_COUNT], BusError> {
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

    #[test]
    fn toml_overrides_keep_other_defaults() {
        let text = "frame_gap_ms = 2.0\n";
        let c: BusConfig = toml::from_str(text).unwrap();
        assert_eq!(c.frame_gap_ms, 2.0);
        assert_eq!(c.servo_map, ServoMap::default());
    }

    #[test]
    fn timing_settings_out_of_range_are_refused_by_key() {
        BusConfig::default().check().unwrap();
        for (text, key) in [
            ("settle_ms = 1e300\n", "`settle_ms`"),
            ("frame_gap_ms = -1.0\n", "`frame_gap_ms`"),
            ("read_timeout_ms = nan\n", "`read_timeout_ms`"),
            ("attempts = 0\n", "`attempts`"),
        ] {
            let c: BusConfig = toml::from_str(text).unwrap();
            let e = c.check().unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
    }
}

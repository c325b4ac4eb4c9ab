//! Servo ids, raw position ranges and the angle <-> raw conversion per servo.
//!
//! DOFBOT.md, "Angle <-> raw position (Yahboom's convention)":
//!
//! ```text
//! servo 1     base yaw        0..180 deg   raw = 900 + 2200*a/180
//! servo 2,3,4 pitch joints    0..180 deg   raw = 900 + 2200*(180-a)/180   (inverted)
//! servo 5     wrist roll      0..270 deg   raw = 380 + 3320*a/270
//! servo 6     gripper         0..180 deg   raw = 900 + 2200*a/180         (0 open, 180 closed)
//! ```
//!
//! Raw counts are rounded to the nearest integer (Yahboom's Arm_Lib truncates; the two differ
//! by at most one count). Angles or raw values outside a servo's span are errors, never clamped.
use core::fmt;

/// Number of servos on the arm.
pub const SERVO_COUNT: usize = 6;
/// Lowest raw position any bus servo accepts.
pub const BUS_RAW_MIN: u16 = 96;
/// Highest raw position any bus servo accepts.
pub const BUS_RAW_MAX: u16 = 4000;

/// A servo of the arm, 1..=6 (1 base yaw ... 5 wrist roll, 6 gripper).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ServoId(u8);

impl ServoId {
    /// All six servos in order.
    pub const ALL: [ServoId; SERVO_COUNT] = [
        ServoId(1),
        ServoId(2),
        ServoId(3),
        ServoId(4),
        ServoId(5),
        ServoId(6),
    ];

    /// Servo `id`, refused unless 1..=6.
    pub const fn new(id: u8) -> Result<ServoId, RangeError> {
        if id >= 1 && id as usize <= SERVO_COUNT {
            Ok(ServoId(id))
        } else {
            Err(RangeError::ServoId { id })
        }
    }

    /// The id, 1..=6.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Zero-based index, 0..=5.
    pub const fn index(self) -> usize {
        self.0 as usize - 1
    }

    /// The DOFBOT.md scale of this servo.
    pub const fn scale(self) -> ServoScale {
        ServoScale::DOFBOT[self.index()]
    }
}

/// A value refused because it lies outside what the hardware accepts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RangeError {
    /// Servo id not in 1..=6.
    ServoId {
        /// The id given.
        id: u8,
    },
    /// Bus servo id not in 1..=250.
    BusId {
        /// The id given.
        id: u8,
    },
    /// Raw position outside the servo's range.
    Raw {
        /// Servo id (bus id for 0x19).
        id: u8,
        /// Raw value given.
        raw: u16,
        /// Lowest allowed.
        min: u16,
        /// Highest allowed.
        max: u16,
    },
    /// Servo angle outside `0..=deg_max` (or not a number).
    Angle {
        /// Servo id.
        id: u8,
        /// Angle given, degrees.
        deg: f64,
        /// Largest allowed, degrees.
        max: f64,
    },
    /// A scale whose numbers are inconsistent (see [`ServoScale::validate`]).
    Scale {
        /// Servo id.
        id: u8,
    },
    /// Buzzer duration not in 1..=50 (x100 ms).
    Buzzer {
        /// Value given.
        tenths: u8,
    },
}

impl fmt::Display for RangeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RangeError::ServoId { id } => write!(f, "servo id {id} not in 1..6"),
            RangeError::BusId { id } => write!(f, "bus servo id {id} not in 1..250"),
            RangeError::Raw { id, raw, min, max } => {
                write!(f, "servo {id}: raw {raw} outside {min}..{max}")
            }
            RangeError::Angle { id, deg, max } => {
                write!(f, "servo {id}: angle {deg} deg outside 0..{max} deg")
            }
            RangeError::Scale { id } => write!(
                f,
                "servo {id}: scale must have deg_max > 0 and raw_min < raw_max inside the servo's raw range"
            ),
            RangeError::Buzzer { tenths } => {
                write!(f, "buzzer duration {tenths} not in 1..50 (x100 ms)")
            }
        }
    }
}

/// Linear map between a servo's angle (degrees, `0..=deg_max`) and its raw position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoScale {
    /// Servo id, 1..=6 (used in error messages and to check the raw range).
    pub id: u8,
    /// Angle span in degrees (180, or 270 for the wrist roll).
    pub deg_max: f64,
    /// Raw position at angle 0 (at `deg_max` when inverted).
    pub raw_min: u16,
    /// Raw position at `deg_max` (at 0 when inverted).
    pub raw_max: u16,
    /// True for servos 2, 3, 4: raw decreases as the angle grows.
    pub inverted: bool,
}

const fn scale(id: u8, deg_max: f64, raw_min: u16, raw_max: u16, inverted: bool) -> ServoScale {
    ServoScale {
        id,
        deg_max,
        raw_min,
        raw_max,
        inverted,
    }
}

impl ServoScale {
    /// DOFBOT.md's table, servos 1..=6 in order. These raw ranges are also the hardware
    /// limits that every command of this crate is checked against.
    pub const DOFBOT: [ServoScale; SERVO_COUNT] = [
        scale(1, 180.0, 900, 3100, false),
        scale(2, 180.0, 900, 3100, true),
        scale(3, 180.0, 900, 3100, true),
        scale(4, 180.0, 900, 3100, true),
        scale(5, 270.0, 380, 3700, false),
        scale(6, 180.0, 900, 3100, false),
    ];

    /// Checks the numbers: a known servo id, `deg_max > 0`, and
    /// `raw_min < raw_max` inside that servo's DOFBOT.md raw range.
    pub fn validate(&self) -> Result<(), RangeError> {
        let hw = ServoId::new(self.id)?.scale();
        let ok = self.deg_max > 0.0
            && self.deg_max.is_finite()
            && self.raw_min < self.raw_max
            && self.raw_min >= hw.raw_min
            && self.raw_max <= hw.raw_max;
        if ok {
            Ok(())
        } else {
            Err(RangeError::Scale { id: self.id })
        }
    }

    /// Raw position for servo angle `deg`, rounded to the nearest count.
    pub fn raw_from_deg(&self, deg: f64) -> Result<u16, RangeError> {
        if !(0.0..=self.deg_max).contains(&deg) {
            return Err(RangeError::Angle {
                id: self.id,
                deg,
                max: self.deg_max,
            });
        }
        let a = if self.inverted {
            self.deg_max - deg
        } else {
            deg
        };
        let span = (self.raw_max - self.raw_min) as f64;
        let raw = self.raw_min as f64 + span * a / self.deg_max;
        // raw >= raw_min > 0, so truncating raw + 0.5 rounds to nearest.
        let raw = (raw + 0.5) as u16;
        self.check_raw(raw)?;
        Ok(raw)
    }

    /// Servo angle in degrees for a raw position; a raw outside the range (including a failed
    /// read's 0) is an error.
    pub fn deg_from_raw(&self, raw: u16) -> Result<f64, RangeError> {
        self.check_raw(raw)?;
        let span = (self.raw_max - self.raw_min) as f64;
        let a = (raw - self.raw_min) as f64 * self.deg_max / span;
        Ok(if self.inverted { self.deg_max - a } else { a })
    }

    /// Raw counts per degree of this servo.
    pub fn counts_per_deg(&self) -> f64 {
        (self.raw_max - self.raw_min) as f64 / self.deg_max
    }

    /// `Ok` when `raw` lies in `raw_min..=raw_max`.
    pub fn check_raw(&self, raw: u16) -> Result<(), RangeError> {
        if (self.raw_min..=self.raw_max).contains(&raw) {
            Ok(())
        } else {
            Err(RangeError::Raw {
                id: self.id,
                raw,
                min: self.raw_min,
                max: self.raw_max,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dofbot_md_table_points() {
        // DOFBOT.md formulas evaluated at the ends and the middle.
        let s1 = ServoId::new(1).unwrap().scale();
        assert_eq!(s1.raw_from_deg(0.0), Ok(900));
        assert_eq!(s1.raw_from_deg(90.0), Ok(2000));
        assert_eq!(s1.raw_from_deg(180.0), Ok(3100));
        let s2 = ServoId::new(2).unwrap().scale();
        assert_eq!(s2.raw_from_deg(0.0), Ok(3100));
        assert_eq!(s2.raw_from_deg(180.0), Ok(900));
        let s5 = ServoId::new(5).unwrap().scale();
        assert_eq!(s5.raw_from_deg(0.0), Ok(380));
        assert_eq!(s5.raw_from_deg(270.0), Ok(3700));
        // 380 + 3320*90/270 = 1486.67
        assert_eq!(s5.raw_from_deg(90.0), Ok(1487));
        assert!(s5.raw_from_deg(270.1).is_err());
        assert!(s1.raw_from_deg(-0.01).is_err());
        assert!(s1.raw_from_deg(f64::NAN).is_err());
        assert!(s1.deg_from_raw(0).is_err());
        assert!(s1.deg_from_raw(3101).is_err());
        assert!(ServoId::new(0).is_err() && ServoId::new(7).is_err());
    }

    #[test]
    fn round_trip_within_half_count() {
        for id in ServoId::ALL {
            let s = id.scale();
            for raw in s.raw_min..=s.raw_max {
                let deg = s.deg_from_raw(raw).unwrap();
                assert_eq!(s.raw_from_deg(deg), Ok(raw), "servo {id:?} raw {raw}");
            }
        }
    }
}

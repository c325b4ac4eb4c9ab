//! Driver settings and the servo map (joint <-> servo degrees, limits, scales), all data:
//! the defaults are DOFBOT.md's mapping with zero offsets, and a TOML file (later
//! `calibration/servos.toml`) can replace any of it.
use serde::{Deserialize, Serialize};

use super::error::BusError;
pub use crate::robot::servo_map::{GripperCalib, JointCalib, JointState, ServoMap, JOINT_COUNT};

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_overrides_keep_other_defaults() {
        let text = "frame_gap_ms = 2.0\n";
        let c: BusConfig = toml::from_str(text).unwrap();
        assert_eq!(c.frame_gap_ms, 2.0);
        assert_eq!(c.servo_map, ServoMap::default());
    }

    #[test]
    fn servo_map_keys_are_unchanged_and_round_trip() {
        // A scale's keys are `deg_max`, `raw_min`, `raw_max`, `inverted` (DOFBOT.md's servo 6).
        let text = "[servo_map.gripper]\nservo = 6\noffset_deg = 0.0\nmin_deg = 0.0\n\
                    max_deg = 180.0\nscale = { deg_max = 180.0, raw_min = 900, raw_max = 3100, \
                    inverted = false }\n";
        let c: BusConfig = toml::from_str(text).unwrap();
        assert_eq!(c.servo_map, ServoMap::default());
        // DOFBOT.md: servo 6 at 90 deg is raw 900 + 2200 * 90 / 180 = 2000.
        assert_eq!(c.servo_map.gripper_raw(90.0).unwrap(), 2000);
        let written = toml::to_string(&BusConfig::default()).unwrap();
        let back: BusConfig = toml::from_str(&written).unwrap();
        assert_eq!(back, BusConfig::default());
        let bad = text.replace("inverted = false", "inverted = false, id = 6");
        let e = toml::from_str::<BusConfig>(&bad).unwrap_err().to_string();
        assert!(e.contains("unknown field `id`"), "{e}");
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

//! Servo offsets: torque off, the operator holds the arm in the zero pose (all joints
//! straight up, the URDF's zero), every servo is read several times, and the servo angle read
//! there becomes the servo's `zero_offset_deg` in servos.toml (servo degrees at joint zero).
use dofbot_protocol::servo::ServoId;
use dofbot_protocol::OffsetState;

use super::config::{CalibError, CalibrationConfig};
use super::read::{at_fractional_raw, read_mean, MeanRead};
use crate::bus::{Bus, BusError, ServoMap, Transport, JOINT_COUNT};

/// One joint servo's result.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoOffset {
    /// Servo id (1..5).
    pub id: u8,
    /// URDF joint it drives.
    pub joint: String,
    /// Mean raw position at the zero pose, counts.
    pub raw_mean: f64,
    /// Spread of the reads, counts.
    pub spread_counts: u16,
    /// Servo angle at joint zero, degrees: the new `zero_offset_deg`.
    pub zero_offset_deg: f64,
    /// The `zero_offset_deg` servos.toml held before, degrees.
    pub previous_deg: f64,
}

/// The result of [`servo_offsets`].
#[derive(Debug, Clone, PartialEq)]
pub struct ServoOffsets {
    /// The five joint servos, in chain order.
    pub servos: Vec<ServoOffset>,
    /// Reads per servo.
    pub reads: usize,
    /// True when the zero pose was also stored on the servos (0x1C) and the board confirmed it.
    pub stored_mid: bool,
}

/// Measures the servo zero offsets. `map` is the bus's servo map built from the current
/// servos.toml; `confirm` is called after torque off and returns once the operator holds the
/// arm in the zero pose (it may abort). With `store_mid`, each joint servo also stores its
/// current position as its mid position (0x1C), the board's offset state (0x1B) must say ok,
/// and the servos are read again, so the offsets written match what the servos read from now.
pub fn servo_offsets<T: Transport>(
    bus: &mut Bus<T>,
    map: &ServoMap,
    cfg: &CalibrationConfig,
    confirm: &mut dyn FnMut() -> Result<(), CalibError>,
    store_mid: bool,
) -> Result<ServoOffsets, CalibError> {
    bus.torque(false)?;
    confirm()?;
    let mut read = read_mean(bus, cfg.reads_per_servo, cfg.max_spread_counts)?;
    if store_mid {
        for id in &ServoId::ALL[..JOINT_COUNT] {
            bus.store_mid_offset(*id)?;
            match bus.offset_state()? {
                OffsetState::Ok => {}
                other => {
                    return Err(CalibError::Refused(format!(
                        "servo {}: storing the mid position failed (offset state {other:?})",
                        id.get()
                    )))
                }
            }
        }
        read = read_mean(bus, cfg.reads_per_servo, cfg.max_spread_counts)?;
    }
    let servos = offsets_from(map, &read, cfg)?;
    Ok(ServoOffsets {
        servos,
        reads: read.reads,
        stored_mid: store_mid,
    })
}

fn offsets_from(
    map: &ServoMap,
    read: &MeanRead,
    cfg: &CalibrationConfig,
) -> Result<Vec<ServoOffset>, CalibError> {
    let mut out = Vec::new();
    for (i, j) in map.joints.iter().enumerate() {
        let scale = j.servo_scale().map_err(BusError::from)?;
        let deg = at_fractional_raw(read.raw[i], |r| {
            scale
                .deg_from_raw(r)
                .map_err(|e| BusError::Refused(format!("{}: {e}", j.name)))
        })?;
        let previous = j.zero_deg + j.offset_deg;
        if (deg - previous).abs() > cfg.max_zero_change_deg {
            return Err(CalibError::Refused(format!(
                "servo {} ({}) reads {deg:.2} deg at the zero pose, {:.1} deg from servos.toml's \
                 {previous:.2} (at most {} allowed): is the arm in the zero pose (all joints \
                 straight up)?",
                j.servo,
                j.name,
                deg - previous,
                cfg.max_zero_change_deg
            )));
        }
        out.push(ServoOffset {
            id: j.servo,
            joint: j.name.clone(),
            raw_mean: read.raw[i],
            spread_counts: read.spread[i],
            zero_offset_deg: deg,
            previous_deg: previous,
        });
    }
    Ok(out)
}

//! Averaged read-backs: several reads of all six servos, refused when one servo's reads spread
//! too far, averaged to a fractional raw position and converted through the servo map.
use dofbot_protocol::servo::SERVO_COUNT;

use super::config::CalibError;
use crate::bus::{Bus, BusError, ServoMap, Transport, JOINT_COUNT};

/// The mean of several reads of the six servos.
#[derive(Debug, Clone, PartialEq)]
pub struct MeanRead {
    /// Mean raw position per servo, counts (fractional).
    pub raw: [f64; SERVO_COUNT],
    /// Largest minus smallest read per servo, counts.
    pub spread: [u16; SERVO_COUNT],
    /// Reads per servo.
    pub reads: usize,
}

/// Reads all six servos `n` times (at least once); refused when a servo's reads spread more
/// than `max_spread` counts.
pub fn read_mean<T: Transport>(
    bus: &mut Bus<T>,
    n: usize,
    max_spread: u16,
) -> Result<MeanRead, CalibError> {
    let n = n.max(1);
    let mut sum = [0.0; SERVO_COUNT];
    let mut lo = [u16::MAX; SERVO_COUNT];
    let mut hi = [0u16; SERVO_COUNT];
    for _ in 0..n {
        let raw = bus.read_pose_raw()?;
        for i in 0..SERVO_COUNT {
            sum[i] += f64::from(raw[i]);
            lo[i] = lo[i].min(raw[i]);
            hi[i] = hi[i].max(raw[i]);
        }
    }
    let spread: [u16; SERVO_COUNT] = std::array::from_fn(|i| hi[i] - lo[i]);
    if let Some(i) = (0..SERVO_COUNT).find(|&i| spread[i] > max_spread) {
        return Err(CalibError::Refused(format!(
            "servo {}: {n} reads spread {} counts (raw {}..{}, at most {max_spread} allowed): \
             the arm moved or the servo jitters; hold it still and retry",
            i + 1,
            spread[i],
            lo[i],
            hi[i]
        )));
    }
    Ok(MeanRead {
        raw: sum.map(|s| s / n as f64),
        spread,
        reads: n,
    })
}

/// `f` (linear in raw) at a fractional raw position: interpolates `f` between the two counts
/// around `raw`.
pub fn at_fractional_raw(
    raw: f64,
    f: impl Fn(u16) -> Result<f64, BusError>,
) -> Result<f64, BusError> {
    let below = raw.floor().clamp(0.0, f64::from(u16::MAX - 1)) as u16;
    let a = f(below)?;
    let frac = raw - f64::from(below);
    if frac == 0.0 {
        return Ok(a);
    }
    let b = f(below + 1)?;
    Ok(a + (b - a) * frac)
}

/// Joint angles (rad) of a mean read under `map`.
pub fn joints_of(map: &ServoMap, read: &MeanRead) -> Result<[f64; JOINT_COUNT], BusError> {
    let mut q = [0.0; JOINT_COUNT];
    for (i, qi) in q.iter_mut().enumerate() {
        *qi = at_fractional_raw(read.raw[i], |r| Ok(map.joint_from_raw(i, r)?))?;
    }
    Ok(q)
}

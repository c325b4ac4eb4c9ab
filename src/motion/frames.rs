//! The servo command stream as data: every joint sample as one 0x1D six-servo frame (time =
//! the bus period) built by dofbot-protocol through robot's servo map, which is made from the
//! same `servos.toml` the planner uses; and the reverse check of a stream read from a file.
use dofbot_protocol::servo::{ServoId, SERVO_COUNT};
use dofbot_protocol::{Command, Decoder, Hex, Pose};

use super::error::PlanError;
use crate::robot::servo_map::NO_GRIPPER;
use crate::robot::{Robot, Servo, ServoMap, JOINT_COUNT};

fn frame_err(msg: impl Into<String>) -> PlanError {
    PlanError::Frames(msg.into())
}

/// The servo map from the robot's `servos.toml` and joint limits (one calibration for planner
/// and bus): [`ServoMap::from_robot`].
pub fn servo_map(robot: &Robot) -> Result<ServoMap, PlanError> {
    ServoMap::from_robot(robot).map_err(|e| frame_err(e.to_string()))
}

/// The servo without a joint (the gripper), held at its `hold_deg`.
pub fn gripper(robot: &Robot) -> Result<&Servo, PlanError> {
    robot.servos.gripper().ok_or_else(|| frame_err(NO_GRIPPER))
}

/// The angle the gripper is held at during every move, degrees: its `hold_deg`, else 90
/// (mid-range).
pub fn gripper_hold_deg(robot: &Robot) -> Result<f64, PlanError> {
    Ok(gripper(robot)?.hold_deg.unwrap_or(90.0))
}

/// Move time of every frame, ms: the period.
pub fn frame_time_ms(period: f64) -> Result<u16, PlanError> {
    let ms = (period * 1000.0).round();
    if !(1.0..=f64::from(u16::MAX)).contains(&ms) || (ms - period * 1000.0).abs() > 1e-6 {
        return Err(frame_err(format!(
            "period {period} s is not a whole number of milliseconds in 1..65535"
        )));
    }
    Ok(ms as u16)
}

/// Raw positions of the six servos for joint sample `q`.
pub fn raw_pose(map: &ServoMap, hold_deg: f64, q: &[f64]) -> Result<[u16; SERVO_COUNT], PlanError> {
    let q: [f64; JOINT_COUNT] = q
        .try_into()
        .map_err(|_| frame_err(format!("sample has {} joints", q.len())))?;
    map.pose_raw(&q, hold_deg)
        .map_err(|e| frame_err(e.to_string()))
}

/// One 0x1D frame per sample: raw poses from `map`, time = `period`. Refused (never clamped)
/// when a sample lies outside a servo's range.
pub fn encode(
    samples: &[Vec<f64>],
    map: &ServoMap,
    hold_deg: f64,
    period: f64,
) -> Result<Vec<Vec<u8>>, PlanError> {
    let time_ms = frame_time_ms(period)?;
    samples
        .iter()
        .enumerate()
        .map(|(i, q)| {
            let raw =
                raw_pose(map, hold_deg, q).map_err(|e| frame_err(format!("sample {i}: {e}")))?;
            let pose = Pose::new(raw).map_err(|e| frame_err(format!("sample {i}: {e}")))?;
            let mut buf = [0u8; 32];
            let n = Command::MoveAll { pose, time_ms }
                .encode(&mut buf)
                .map_err(|e| frame_err(format!("sample {i}: {e}")))?;
            Ok(buf[..n].to_vec())
        })
        .collect()
}

/// Hex form of a frame as journal.jsonl and the mock log write it (`FF FC 11 1D ...`).
pub fn to_hex(frame: &[u8]) -> String {
    Hex(frame).to_string()
}

/// Parses a hex frame back: it must decode as one whole 0x1D command within every servo's
/// range; returns the raw poses and the move time.
pub fn decode(text: &str) -> Result<([u16; SERVO_COUNT], u16), String> {
    let bytes: Vec<u8> = text
        .split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).map_err(|_| format!("bad hex byte {b:?}")))
        .collect::<Result<_, _>>()?;
    let mut dec = Decoder::commands();
    let frames: Vec<_> = dec.feed(&bytes).collect();
    match frames.as_slice() {
        [Ok(frame)] if dec.skipped() == 0 && dec.pending() == 0 => {
            match Command::parse(frame).map_err(|e| e.to_string())? {
                Command::MoveAll { pose, time_ms } => Ok((pose.raw(), time_ms)),
                other => Err(format!("not a 0x1D frame: {}", other.name())),
            }
        }
        _ => Err("not exactly one well-formed frame".into()),
    }
}

/// Servo ids in frame order.
pub fn servo_ids() -> [u8; SERVO_COUNT] {
    ServoId::ALL.map(|s| s.get())
}

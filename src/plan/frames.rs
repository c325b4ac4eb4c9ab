//! The servo command stream: every joint sample as one 0x1D six-servo frame (time = the bus
//! period) built by dofbot-protocol through the bus's servo map, which is made from the same
//! `servos.toml` the planner uses; and the reverse check of a stream read from a file.
use dofbot_protocol::servo::{ServoId, SERVO_COUNT};
use dofbot_protocol::{Command, Decoder, Pose};

use super::PlanError;
use crate::bus::journal::hex;
use crate::bus::{GripperCalib, JointCalib, ScaleCalib, ServoMap, JOINT_COUNT};
use crate::robot::{Robot, Servo};

fn frame_err(msg: impl Into<String>) -> PlanError {
    PlanError::Frames(msg.into())
}

fn scale(servo: &Servo) -> Result<ScaleCalib, PlanError> {
    if servo.degree_range[0] != 0.0 {
        return Err(frame_err(format!(
            "servo {}: the bus needs degree_range to start at 0 (got {})",
            servo.id, servo.degree_range[0]
        )));
    }
    Ok(ScaleCalib {
        deg_max: servo.degree_range[1],
        raw_min: servo.raw_range[0],
        raw_max: servo.raw_range[1],
        inverted: servo.raw_inverted,
    })
}

/// The bus's servo map from the robot's `servos.toml` and joint limits (one calibration for
/// planner and bus).
pub fn servo_map(robot: &Robot) -> Result<ServoMap, PlanError> {
    if robot.dof() != JOINT_COUNT {
        return Err(frame_err(format!(
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
            .ok_or_else(|| frame_err(format!("no servo {}", spec.servo_id)))?;
        joints.push(JointCalib {
            name: spec.name.clone(),
            servo: servo.id,
            zero_deg: servo.zero_offset_deg,
            direction: f64::from(servo.direction),
            offset_deg: 0.0,
            lower_rad: spec.lower,
            upper_rad: spec.upper,
            max_velocity_rad_s: spec.velocity,
            scale: scale(servo)?,
        });
    }
    let g = gripper(robot)?;
    let map = ServoMap {
        joints,
        gripper: GripperCalib {
            servo: g.id,
            offset_deg: 0.0,
            min_deg: g.degree_range[0],
            max_deg: g.degree_range[1],
            scale: scale(g)?,
        },
    };
    map.validate().map_err(|e| frame_err(e.to_string()))?;
    Ok(map)
}

/// The servo without a joint (the gripper), held at its `hold_deg`.
pub fn gripper(robot: &Robot) -> Result<&Servo, PlanError> {
    robot
        .servos
        .servos
        .iter()
        .find(|s| s.joint.is_none())
        .ok_or_else(|| frame_err("servos.toml has no gripper servo (one without a joint)"))
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
    hex(frame)
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

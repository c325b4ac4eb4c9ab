//! Streaming a checked plan over the bus: one frame per period on the transport's clock, one
//! servo read back every few frames (round robin, so a read fits between two frames), a stop
//! with the reason when a read-back strays from the plan, and the final pose verified.
use std::time::Duration;

use dofbot_protocol::servo::{ServoId, SERVO_COUNT};
use dofbot_protocol::Pose;
use serde::{Deserialize, Serialize};

use crate::bus::{Bus, BusError, Transport};
use crate::plan::file::CheckedPlan;

/// Settings of `run`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Read one servo back after every this many frames (5: each servo every 0.6 s at 20 ms).
    pub readback_every: usize,
    /// Allowed difference between a read-back and the last commanded raw position, counts,
    /// on top of that servo's step between the last two frames (the servo may lag one frame):
    /// 24 (about 2 degrees: backlash and sag).
    pub readback_tolerance_counts: u16,
    /// Extra wait after the last frame before the final read-back, ms (200).
    pub settle_ms: f64,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            readback_every: 5,
            readback_tolerance_counts: 24,
            settle_ms: 200.0,
        }
    }
}

/// What a run did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunReport {
    /// First frame sent.
    pub first: usize,
    /// Frames sent.
    pub sent: usize,
    /// Servo read-backs during motion.
    pub readbacks: usize,
    /// Largest read-back difference seen, counts.
    pub worst_readback_counts: u16,
    /// Final raw positions read back.
    pub final_raw: [u16; SERVO_COUNT],
}

/// Streams frames `from..` of `plan` over `bus`, `period` seconds apart. Refuses to start
/// unless the arm reads back at frame `from`'s pose (within the bus's verify tolerance).
pub fn execute<T: Transport>(
    bus: &mut Bus<T>,
    plan: &CheckedPlan,
    period: f64,
    from: usize,
    config: &RunConfig,
) -> Result<RunReport, BusError> {
    if from >= plan.frames.len() {
        return Err(BusError::Refused(format!(
            "resume at frame {from}, but the plan has {} frames",
            plan.frames.len()
        )));
    }
    bus.verify(from as u64, plan.raw[from])
        .map_err(|e| match e {
            BusError::ReadBackMismatch {
                servo,
                expected,
                got,
                ..
            } => BusError::Refused(format!(
                "the arm is not at the plan's frame {from}: servo {servo} reads {got}, the plan \
             has {expected}; move it there first (polishbot arm move)"
            )),
            other => other,
        })?;
    let mut report = RunReport {
        first: from,
        sent: 0,
        readbacks: 0,
        worst_readback_counts: 0,
        final_raw: [0; SERVO_COUNT],
    };
    let every = config.readback_every.max(1);
    let start = bus.transport().now();
    let mut next_servo = 0usize;
    for k in from..plan.frames.len() {
        let due = start + Duration::from_secs_f64((k - from) as f64 * period);
        let now = bus.transport().now();
        if due > now {
            bus.sleep(due - now);
        }
        let pose = Pose::new(plan.raw[k]).map_err(|e| BusError::Refused(e.to_string()))?;
        bus.send_motion(k as u64, pose, plan.time_ms)?;
        report.sent += 1;
        if (k - from + 1).is_multiple_of(every) && k + 1 < plan.frames.len() {
            let i = next_servo % SERVO_COUNT;
            next_servo += 1;
            let lag = if k > 0 {
                plan.raw[k][i].abs_diff(plan.raw[k - 1][i])
            } else {
                0
            };
            let id = ServoId::ALL[i];
            let want = plan.raw[k][i];
            let got =
                bus.verify_servo(k as u64, id, want, config.readback_tolerance_counts + lag)?;
            report.readbacks += 1;
            report.worst_readback_counts = report.worst_readback_counts.max(got.abs_diff(want));
        }
    }
    bus.sleep(Duration::from_secs_f64(
        period + config.settle_ms.max(0.0) / 1000.0,
    ));
    let last = plan.frames.len() - 1;
    let state = bus.verify(last as u64, plan.raw[last])?;
    report.final_raw = state.raw;
    Ok(report)
}

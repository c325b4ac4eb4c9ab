//! Streaming a checked plan over the bus: one frame per period on the transport's clock, one
//! servo read back every few frames (round robin, so a read fits between two frames), a stop
//! with the reason when a read-back strays from the plan, and the final pose verified.
use std::time::Duration;

use dofbot_protocol::servo::{ServoId, SERVO_COUNT};
use dofbot_protocol::{AnyTarget, BusId, Pose};
use serde::{Deserialize, Serialize};

use crate::bus::{Bus, BusError, Transport};
use crate::motion::file::CheckedPlan;

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
    /// First motion step sent (a frame index for a plan without table moves).
    pub first: usize,
    /// Motion frames sent (the arm's 0x1D and the table's 0x19).
    pub sent: usize,
    /// Servo read-backs during motion.
    pub readbacks: usize,
    /// Largest read-back difference seen, counts.
    pub worst_readback_counts: u16,
    /// Final raw positions read back.
    pub final_raw: [u16; SERVO_COUNT],
    /// Final raw position of the turntable servo read back (plans that turn one).
    pub final_table_raw: Option<u16>,
}

/// One motion step of a run: an arm frame, or frame `frame` of table move `mv` (sent after
/// the arm frame of the move's `at_sample`, while the arm rests there).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Arm frame (0x1D) of sample k.
    Arm(usize),
    /// Arm frame (0x1D) of sample `arm` and, in the same bus period, table frame `frame` of
    /// synced stretch `stretch` (the table turning with the arm).
    Synced {
        /// Arm sample.
        arm: usize,
        /// Synced stretch index.
        stretch: usize,
        /// Frame index within the stretch.
        frame: usize,
    },
    /// A table frame (0x19).
    Table {
        /// Move index.
        mv: usize,
        /// Frame index within the move.
        frame: usize,
    },
}

/// The motion steps of `plan` in sending order; the journal's motion index is a position in
/// this list (equal to the frame index when the plan turns no table).
pub fn steps(plan: &CheckedPlan) -> Vec<Step> {
    let moves = plan.table.as_ref().map_or(&[][..], |t| &t.moves[..]);
    let synced = plan.table.as_ref().map_or(&[][..], |t| &t.synced[..]);
    let mut out = Vec::with_capacity(plan.frames.len());
    for k in 0..plan.frames.len() {
        let with = synced
            .iter()
            .enumerate()
            .find(|(_, s)| k > s.first_sample && k <= s.first_sample + s.raw.len());
        out.push(match with {
            Some((stretch, s)) => Step::Synced {
                arm: k,
                stretch,
                frame: k - s.first_sample - 1,
            },
            None => Step::Arm(k),
        });
        for (mv, m) in moves.iter().enumerate().filter(|(_, m)| m.at_sample == k) {
            out.extend((0..m.frames.len()).map(|frame| Step::Table { mv, frame }));
        }
    }
    out
}

/// Where the arm (its frame index) and the table (raw) stand once step `i` is done.
fn state_after(plan: &CheckedPlan, steps: &[Step], i: usize) -> (usize, Option<u16>) {
    let table = plan.table.as_ref();
    let mut arm = 0;
    let mut raw = table.map(|t| t.start_raw);
    for s in &steps[..=i] {
        match *s {
            Step::Arm(k) => arm = k,
            Step::Synced {
                arm: k,
                stretch,
                frame,
            } => {
                arm = k;
                raw = table.map(|t| t.synced[stretch].raw[frame]);
            }
            Step::Table { mv, frame } => raw = table.map(|t| t.moves[mv].raw[frame]),
        }
    }
    (arm, raw)
}

/// Reads the table back at step `index` against `want` within `tolerance` (none to check for a
/// plan that turns no table).
fn verify_table<T: Transport>(
    bus: &mut Bus<T>,
    plan: &CheckedPlan,
    index: usize,
    want: Option<u16>,
    tolerance: u16,
) -> Result<Option<u16>, BusError> {
    let (Some(t), Some(want)) = (plan.table.as_ref(), want) else {
        return Ok(None);
    };
    let id = BusId::new(t.servo_id).map_err(|e| BusError::Refused(e.to_string()))?;
    bus.verify_any(index as u64, id, t.raw_range, want, tolerance)
        .map(Some)
}

/// Refuses to start unless the arm and the table read back where step `from` (re-)sends them:
/// the arm at its frame's pose, the table at the step's target (within its last step: the
/// interrupted frame may not have arrived) or, before any table frame, where the plan has it.
fn check_start<T: Transport>(
    bus: &mut Bus<T>,
    plan: &CheckedPlan,
    steps: &[Step],
    from: usize,
) -> Result<(), BusError> {
    let (arm, table) = state_after(plan, steps, from);
    let moved = |e| match e {
        BusError::ReadBackMismatch {
            servo,
            expected,
            got,
            ..
        } => BusError::Refused(format!(
            "the arm is not at the plan's step {from}: servo {servo} reads {got}, the plan \
             has {expected}; move it there first (polishbot arm move / --table)"
        )),
        other => other,
    };
    bus.verify(from as u64, plan.raw[arm]).map_err(moved)?;
    let lag = match (steps[from], from.checked_sub(1)) {
        (Step::Table { .. } | Step::Synced { .. }, Some(prev)) => {
            let before = state_after(plan, steps, prev).1;
            table.zip(before).map_or(0, |(a, b)| a.abs_diff(b))
        }
        _ => 0,
    };
    let tol = bus.config().verify_tolerance_counts + lag;
    verify_table(bus, plan, from, table, tol).map_err(moved)?;
    Ok(())
}

/// Sends table step `k` (`steps[k]` is a table frame): first, for a move's first frame, reads
/// the arm back at its resting pose (not when resuming at that frame: the start check did);
/// after a move's last frame waits `settle` and reads the table back at its target. Returns
/// when the frame was sent.
fn send_table_step<T: Transport>(
    bus: &mut Bus<T>,
    plan: &CheckedPlan,
    steps: &[Step],
    k: usize,
    settle: Duration,
) -> Result<Duration, BusError> {
    let (Step::Table { mv, frame }, Some(t)) = (steps[k], plan.table.as_ref()) else {
        return Err(BusError::Refused(format!("step {k} is no table frame")));
    };
    let m = &t.moves[mv];
    let index = k as u64;
    if frame == 0 && k > 0 && steps[k - 1] == Step::Arm(m.at_sample) {
        bus.verify(index, plan.raw[m.at_sample])?;
    }
    let id = BusId::new(t.servo_id).map_err(|e| BusError::Refused(e.to_string()))?;
    let target = AnyTarget::new(id, m.raw[frame]).map_err(|e| BusError::Refused(e.to_string()))?;
    bus.send_any(index, target, plan.time_ms)?;
    let sent_at = bus.transport().now();
    if frame + 1 == m.raw.len() {
        bus.sleep(settle);
        let tol = bus.config().verify_tolerance_counts;
        verify_table(bus, plan, k, Some(m.raw[frame]), tol)?;
    }
    Ok(sent_at)
}

/// Sends the table frame `frame` of synced stretch `stretch` at step `k` (right after its arm
/// frame, in the same period) and, with `read` (the read-back tolerance, counts), reads the
/// table back against it within that tolerance plus its step between the last two frames (the servo
/// may lag one frame). Returns the read-back's difference, counts, when it read.
fn send_synced<T: Transport>(
    bus: &mut Bus<T>,
    plan: &CheckedPlan,
    k: usize,
    (stretch, frame): (usize, usize),
    read: Option<u16>,
) -> Result<Option<u16>, BusError> {
    let Some(t) = plan.table.as_ref() else {
        return Err(BusError::Refused(format!("step {k} is no table frame")));
    };
    let s = &t.synced[stretch];
    let id = BusId::new(t.servo_id).map_err(|e| BusError::Refused(e.to_string()))?;
    let want = s.raw[frame];
    let target = AnyTarget::new(id, want).map_err(|e| BusError::Refused(e.to_string()))?;
    // the table is bus servo 7: Arm_Lib's `Arm_serial_servo_write(id, angle, time)` addresses
    // only ids 1..6 (FUNC 0x10 + id), so its frame is `Arm_serial_servo_write_any(id, angle,
    // time)`'s 0x19 (DOFBOT.md, "Commands"), sent right after the 0x1D of the same sample
    bus.send_any(k as u64, target, plan.time_ms)?;
    let Some(tolerance) = read else {
        return Ok(None);
    };
    // the stretch starts at rest: its first frame has no lag
    let before = if frame > 0 { s.raw[frame - 1] } else { want };
    let tol = tolerance + want.abs_diff(before);
    let got = bus.verify_any(k as u64, id, t.raw_range, want, tol)?;
    Ok(Some(got.abs_diff(want)))
}

/// Streams steps `from..` of `plan` ([`steps`]) over `bus`, `period` seconds apart. Refuses to
/// start unless the arm (and the table) read back at step `from`'s pose. Before each table
/// move the arm's pose is read back (it rests at its start pose); after it, once settled, the
/// table's angle.
pub fn execute<T: Transport>(
    bus: &mut Bus<T>,
    plan: &CheckedPlan,
    period: f64,
    from: usize,
    config: &RunConfig,
) -> Result<RunReport, BusError> {
    let steps = steps(plan);
    if from >= steps.len() {
        return Err(BusError::Refused(format!(
            "resume at step {from}, but the plan has {} steps",
            steps.len()
        )));
    }
    check_start(bus, plan, &steps, from)?;
    let mut report = RunReport {
        first: from,
        sent: 0,
        readbacks: 0,
        worst_readback_counts: 0,
        final_raw: [0; SERVO_COUNT],
        final_table_raw: None,
    };
    let every = config.readback_every.max(1);
    let settle = Duration::from_secs_f64(period + config.settle_ms.max(0.0) / 1000.0);
    let step = Duration::from_secs_f64(period);
    let mut start = bus.transport().now();
    let mut next_servo = 0usize;
    for k in from..steps.len() {
        let due = start + Duration::from_secs_f64((k - from) as f64 * period);
        let now = bus.transport().now();
        if due > now {
            bus.sleep(due - now);
        }
        let index = k as u64;
        let (a, with) = match steps[k] {
            Step::Arm(a) => (a, None),
            Step::Synced {
                arm,
                stretch,
                frame,
            } => (arm, Some((stretch, frame))),
            Step::Table { .. } => (usize::MAX, None),
        };
        if a == usize::MAX {
            let sent_at = send_table_step(bus, plan, &steps, k, settle)?;
            report.sent += 1;
            // a read-back around a table move kept this frame back or took longer than a
            // period: the schedule waits, so no table frame follows the last sooner than a period
            let behind = sent_at.saturating_sub(due);
            let settled = bus.transport().now().saturating_sub(due + step);
            start += behind.max(settled);
            continue;
        }
        let pose = Pose::new(plan.raw[a]).map_err(|e| BusError::Refused(e.to_string()))?;
        bus.send_motion(index, pose, plan.time_ms)?;
        report.sent += 1;
        let due_read = (k - from + 1).is_multiple_of(every) && a + 1 < plan.frames.len();
        if let Some((stretch, frame)) = with {
            // the table's frame of the same sample, and every other read-back the table's
            let read =
                (due_read && next_servo % 2 == 1).then_some(config.readback_tolerance_counts);
            let got = send_synced(bus, plan, k, (stretch, frame), read)?;
            report.sent += 1;
            if let Some(diff) = got {
                next_servo += 1;
                report.readbacks += 1;
                report.worst_readback_counts = report.worst_readback_counts.max(diff);
                continue;
            }
        }
        if due_read {
            let i = next_servo % SERVO_COUNT;
            next_servo += 1;
            let lag = if a > 0 {
                plan.raw[a][i].abs_diff(plan.raw[a - 1][i])
            } else {
                0
            };
            let id = ServoId::ALL[i];
            let want = plan.raw[a][i];
            let got = bus.verify_servo(index, id, want, config.readback_tolerance_counts + lag)?;
            report.readbacks += 1;
            report.worst_readback_counts = report.worst_readback_counts.max(got.abs_diff(want));
        }
    }
    bus.sleep(settle);
    let last = steps.len() - 1;
    let (arm, table) = state_after(plan, &steps, last);
    let state = bus.verify(last as u64, plan.raw[arm])?;
    report.final_raw = state.raw;
    report.final_table_raw =
        verify_table(bus, plan, last, table, bus.config().verify_tolerance_counts)?;
    Ok(report)
}

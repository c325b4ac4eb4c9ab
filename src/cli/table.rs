//! `polishbot arm move --table DEG [--cell DIR]`: one rest-to-rest move of the part turntable
//! (bus servo id 7 of the cell's `[turntable]`), planned as `plan` plans a table move (Ruckig
//! within the table's velocity, acceleration and jerk limits, one 0x19 frame per bus period),
//! every frame validated by the same check as a plan's, sent only while the arm reads back at
//! its home pose, and verified by a read-back (0x37) at the end.
use std::time::Duration;

use dofbot_protocol::{AnyTarget, BusId};
use serde_json::json;

use crate::bus::{Bus, BusError, Transport, JOINT_COUNT};
use crate::motion::table_file::{self, TablePlan};
use crate::motion::TrajectoryConfig;
use crate::robot::Turntable;

/// The arm pose the table may turn under: every joint at zero (`[plan] home`'s default, the
/// arm upright and clear of the part), radians.
const HOME: [f64; JOINT_COUNT] = [0.0; JOINT_COUNT];

/// How far past its range, rad, a read-back of the table may land and still be taken as the
/// range's end (half a degree: about six counts of the 270-degree servo, its read noise).
const FROM_SLACK: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Turns the table to `deg` degrees: refused before anything moves when the angle is outside
/// the table's range or the arm is not at its home pose. Returns the verified read-back.
pub fn turn<T: Transport>(
    bus: &mut Bus<T>,
    table: &Turntable,
    deg: f64,
    period: f64,
    settle_ms: f64,
) -> anyhow::Result<serde_json::Value> {
    let to = deg.to_radians();
    table
        .raw(to)
        .map_err(|m| anyhow::anyhow!("--table {deg}: {m}"))?;
    let id = BusId::new(table.servo.id).map_err(|e| anyhow::anyhow!("turntable id: {e}"))?;
    let arm = bus.read_joints()?;
    let home = bus.config().servo_map.pose_raw(&HOME, arm.gripper_deg)?;
    let tol = bus.config().verify_tolerance_counts;
    if let Some(i) = (0..JOINT_COUNT).find(|&i| arm.raw[i].abs_diff(home[i]) > tol) {
        anyhow::bail!(
            "--table: the arm is not at its home pose (servo {} reads {}, home is {}): the table \
             turns only under the retracted arm (polishbot arm move --joints 0,0,0,0,0)",
            i + 1,
            arm.raw[i],
            home[i]
        );
    }
    let raw = bus.read_any_raw(id, table.servo.raw_range)?;
    let from = table
        .angle_from_raw(raw)
        .map_err(|m| anyhow::anyhow!("turntable reads raw {raw}: {m}"))?;
    let [lo, hi] = table.range();
    if !(from >= lo - FROM_SLACK && from <= hi + FROM_SLACK) {
        anyhow::bail!(
            "--table: the turntable reads {:.2} deg, outside its range {:.2}..={:.2} deg: turn it back by hand first",
            from.to_degrees(),
            lo.to_degrees(),
            hi.to_degrees()
        );
    }
    let from = from.clamp(lo, hi);
    let config = TrajectoryConfig {
        period,
        ..TrajectoryConfig::default()
    };
    let mv = table_file::table_move(table, from, to, 0, &config)?;
    let plan = TablePlan {
        servo_id: table.servo.id,
        start: from,
        regions: Vec::new(),
        moves: vec![mv],
        synced: Vec::new(),
    };
    let checked = table_file::check(&plan, table, 1, period)?;
    let targets = &checked.moves[0].raw;
    let time_ms = crate::motion::frames::frame_time_ms(period)?;
    let start = bus.transport().now();
    for (k, &r) in targets.iter().enumerate() {
        let due = start + Duration::from_secs_f64(k as f64 * period);
        let now = bus.transport().now();
        if due > now {
            bus.sleep(due - now);
        }
        let target = AnyTarget::new(id, r).map_err(|e| BusError::Refused(e.to_string()))?;
        bus.send_any(k as u64, target, time_ms)?;
    }
    bus.sleep(Duration::from_secs_f64(
        period + settle_ms.max(0.0) / 1000.0,
    ));
    let last = *targets.last().unwrap_or(&raw);
    let got = bus.verify_any(targets.len() as u64, id, table.servo.raw_range, last, tol)?;
    Ok(json!({
        "table_deg": deg,
        "from_deg": from.to_degrees(),
        "frames": targets.len(),
        "raw": got,
    }))
}

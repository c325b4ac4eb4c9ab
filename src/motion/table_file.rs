//! The turntable's part of plan.json (`turntable`): each region's table angle and the table
//! moves, each a rest-to-rest Ruckig move of the table angle sampled at the bus period with one
//! 0x19 frame (dofbot-protocol's `MoveAny`, Arm_Lib's `Arm_serial_servo_write_any`) per
//! sample; and the re-check of that part against the cell's turntable.
use dofbot_protocol::{AnyTarget, BusId, Command};
use serde::{Deserialize, Serialize};

use super::error::PlanError;
use super::frames::{frame_time_ms, to_hex};
use super::trajectory::{JointTrajectory, Limits, Move, TrajectoryConfig};
use crate::robot::Turntable;

/// Share by which a step between table samples may exceed `velocity x period` (the same
/// floating-point slack the arm's validation allows its finite differences).
const STEP_TOLERANCE: f64 = 0.01;

/// The table angle chosen for one region.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionTable {
    /// Region id.
    pub region: usize,
    /// Table angle the region is ground at, degrees.
    pub angle_deg: f64,
    /// Estimated share of the region's core points the tool reaches at that angle.
    pub reachable_share: f64,
    /// The same at table angle 0 (the cell without turning).
    pub reachable_share_at_zero: f64,
    /// The other table angles the region was planned at alone because the plan at its first
    /// angle left it short, best first: what would reach the rest, and why not. Absent in
    /// plans from before 2026-12-05 and where none was needed: empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tried: Vec<TriedAngle>,
    /// The region split by table angle: the further pieces, each the core points the strokes
    /// so far left uncovered, planned at another angle (`angle_deg` grinds the first piece).
    /// Absent in plans from before 2026-12-05 and where no piece was needed: empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pieces: Vec<TablePiece>,
}

/// One further piece of a region split by table angle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TablePiece {
    /// Table angle the piece is ground at, degrees.
    pub angle_deg: f64,
    /// Core points of the region the piece was planned on (those left uncovered before it).
    pub points: usize,
    /// Share of the region's core points covered once the piece is added.
    pub coverage: f64,
}

impl RegionTable {
    /// Every table angle the region is ground at, degrees: its own, then its pieces'.
    pub fn angles_deg(&self) -> impl Iterator<Item = f64> + '_ {
        std::iter::once(self.angle_deg).chain(self.pieces.iter().map(|p| p.angle_deg))
    }
}

/// One table angle a region was planned at alone.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TriedAngle {
    /// Table angle, degrees.
    pub angle_deg: f64,
    /// Share of the region's core points the plan there covers (0 when refused).
    pub coverage: f64,
    /// Why the region is short there: the planner's error (its first clause) when the plan
    /// was refused, else the first reason the plan gives for the region's left-out contacts;
    /// None when it covers enough or names no reason.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
}

/// One table move: the arm rests at arm sample `at_sample` (retracted, at home) while the
/// table turns; the arm's samples continue after the move's last sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableMove {
    /// Arm sample index the move happens at.
    pub at_sample: usize,
    /// Table angle per bus period, radians: first the angle it starts from, last its target.
    pub samples: Vec<f64>,
    /// One 0x19 frame per sample after the first (hex), time = the period.
    pub frames: Vec<String>,
}

/// A table move `run` may send: where it happens and each frame's raw target.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedMove {
    /// Arm sample index the move happens at (the arm rests there, at its start pose).
    pub at_sample: usize,
    /// Raw count each frame sends the table servo to.
    pub raw: Vec<u16>,
    /// The frames' bytes.
    pub frames: Vec<Vec<u8>>,
}

/// The table part of a plan as checked against the cell's turntable.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedTable {
    /// Bus id of the table servo.
    pub servo_id: u8,
    /// The servo's raw range (what a read-back may be).
    pub raw_range: [u16; 2],
    /// Raw count of the plan's start angle (where the table must be before the first frame).
    pub start_raw: u16,
    /// The moves in order.
    pub moves: Vec<CheckedMove>,
}

/// The `turntable` object of plan.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TablePlan {
    /// Bus id of the table servo.
    pub servo_id: u8,
    /// Table angle the plan starts from, radians (0: the workcell's calibrated placement).
    pub start: f64,
    /// Per region (regions.json order) its table angle.
    pub regions: Vec<RegionTable>,
    /// The table moves in order.
    pub moves: Vec<TableMove>,
}

impl TablePlan {
    /// Total duration of the table moves, s.
    pub fn duration(&self, period: f64) -> f64 {
        let total: f64 = self
            .moves
            .iter()
            .map(|m| (m.samples.len().saturating_sub(1)) as f64 * period)
            .sum();
        // an empty sum is -0.0: printed as "-0.00 s"
        total + 0.0
    }

    /// The table angle after the last move, radians.
    pub fn end(&self) -> f64 {
        self.moves
            .last()
            .and_then(|m| m.samples.last().copied())
            .unwrap_or(self.start)
    }
}

/// The 0x19 frame sending the table to `angle` in `time_ms`.
pub fn frame(table: &Turntable, angle: f64, time_ms: u16) -> Result<Vec<u8>, PlanError> {
    let err = |m: String| PlanError::Frames(format!("turntable servo {}: {m}", table.servo.id));
    let raw = table.raw(angle).map_err(err)?;
    let id = BusId::new(table.servo.id).map_err(|e| err(e.to_string()))?;
    let target = AnyTarget::new(id, raw).map_err(|e| err(e.to_string()))?;
    let mut buf = [0u8; 16];
    let n = Command::MoveAny { target, time_ms }
        .encode(&mut buf)
        .map_err(|e| err(e.to_string()))?;
    Ok(buf[..n].to_vec())
}

/// The rest-to-rest move of the table from `from` to `to` (radians) within its limits, sampled
/// at `config.period`, with its frames; the arm rests at `at_sample`.
pub fn table_move(
    table: &Turntable,
    from: f64,
    to: f64,
    at_sample: usize,
    config: &TrajectoryConfig,
) -> Result<TableMove, PlanError> {
    let [v, a, j] = table.limits();
    let limits = Limits {
        velocity: vec![v],
        acceleration: vec![a],
        jerk: vec![j],
    };
    let mv = Move::new(&[from], &[to], &limits, config)
        .map_err(|e| PlanError::Config(format!("turntable move: {e}")))?;
    let mut traj = JointTrajectory::starting_at(&[from], config.period);
    traj.append_move(&mv);
    let samples: Vec<f64> = (0..traj.len()).map(|i| traj.sample(i)[0]).collect();
    let time_ms = frame_time_ms(config.period)?;
    let frames = samples[1..]
        .iter()
        .map(|&q| frame(table, q, time_ms).map(|f| to_hex(&f)))
        .collect::<Result<_, _>>()?;
    Ok(TableMove {
        at_sample,
        samples,
        frames,
    })
}

/// The 0x19 frame's raw target, read back from its bytes.
fn frame_raw(frame: &[u8]) -> u16 {
    // FF FC LEN 19 id posH posL timeH timeL CHK
    u16::from_be_bytes([frame[5], frame[6]])
}

/// Checks the plan's table part against the cell's `table`: the servo id, each move's place
/// (in order, within the arm's samples), continuity from the start angle, every sample inside
/// the table's range (so every raw target inside its raw and degree ranges), every step within
/// its velocity limit and every change of step within its acceleration limit, and every frame
/// equal byte for byte to the 0x19 frame its sample makes. Returns what `run` sends.
pub fn check(
    plan: &TablePlan,
    table: &Turntable,
    arm_samples: usize,
    period: f64,
) -> Result<CheckedTable, PlanError> {
    let bad = |m: String| Err(PlanError::Frames(format!("turntable: {m}")));
    if plan.servo_id != table.servo.id {
        return bad(format!(
            "servo id {} is not the cell's {}",
            plan.servo_id, table.servo.id
        ));
    }
    let time_ms = frame_time_ms(period)?;
    let [lo, hi] = table.range();
    let [v, a, _] = table.limits();
    let most = v * period * (1.0 + STEP_TOLERANCE);
    let most_change = a * period * period * (1.0 + STEP_TOLERANCE);
    let (mut at, mut angle) = (0usize, plan.start);
    let start_raw = table
        .raw(plan.start)
        .map_err(|m| PlanError::Frames(format!("turntable: start: {m}")))?;
    let mut out = Vec::with_capacity(plan.moves.len());
    for (k, m) in plan.moves.iter().enumerate() {
        if m.at_sample < at || m.at_sample >= arm_samples.max(1) {
            return bad(format!(
                "move {k}: at arm sample {} (out of order or past the last)",
                m.at_sample
            ));
        }
        if m.samples.len() < 2 || m.frames.len() + 1 != m.samples.len() {
            return bad(format!(
                "move {k}: {} frames for {} samples",
                m.frames.len(),
                m.samples.len()
            ));
        }
        if (m.samples[0] - angle).abs() > 1e-9 {
            return bad(format!(
                "move {k}: starts at {} rad, the table is at {angle} rad",
                m.samples[0]
            ));
        }
        let mut bytes = Vec::with_capacity(m.frames.len());
        for (i, q) in m.samples.iter().enumerate() {
            if !(q.is_finite() && *q >= lo - 1e-12 && *q <= hi + 1e-12) {
                return bad(format!(
                    "move {k} sample {i}: {q} rad outside {lo}..={hi} rad"
                ));
            }
            if i == 0 {
                continue;
            }
            if (q - m.samples[i - 1]).abs() > most {
                return bad(format!(
                    "move {k} sample {i}: steps {:.5} rad in one period, the velocity limit allows {most:.5}",
                    (q - m.samples[i - 1]).abs()
                ));
            }
            let change = if i >= 2 {
                q - 2.0 * m.samples[i - 1] + m.samples[i - 2]
            } else {
                q - m.samples[0]
            };
            if change.abs() > most_change {
                return bad(format!(
                    "move {k} sample {i}: its step changes by {:.6} rad, the acceleration limit allows {most_change:.6}",
                    change.abs()
                ));
            }
            let want = frame(table, *q, time_ms)?;
            if to_hex(&want) != m.frames[i - 1] {
                return bad(format!(
                    "move {k} frame {}: is not the frame sample {i} makes ({})",
                    i - 1,
                    to_hex(&want)
                ));
            }
            bytes.push(want);
        }
        let last = m.samples.len() - 1;
        if (m.samples[last] - m.samples[last - 1]).abs() > most_change {
            return bad(format!(
                "move {k}: does not end at rest (last step {:.6} rad)",
                (m.samples[last] - m.samples[last - 1]).abs()
            ));
        }
        out.push(CheckedMove {
            at_sample: m.at_sample,
            raw: bytes.iter().map(|f| frame_raw(f)).collect(),
            frames: bytes,
        });
        at = m.at_sample;
        angle = *m.samples.last().unwrap_or(&angle);
    }
    Ok(CheckedTable {
        servo_id: table.servo.id,
        raw_range: table.servo.raw_range,
        start_raw,
        moves: out,
    })
}

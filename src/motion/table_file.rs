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
    /// Strokes of the region ground with the table turning during the stroke (the table as a
    /// sixth axis: `synced` of the table part), after its pieces; absent where none: 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub synced_strokes: usize,
    /// Share of the region's core points covered once those strokes are added (absent
    /// without them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub synced_coverage: Option<f64>,
}

/// Whether `n` is 0 (a count left out of plan.json when nothing was counted).
fn is_zero(n: &usize) -> bool {
    *n == 0
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

/// A stretch of arm samples in which the table turns with the arm (a stroke ground with the
/// table as a sixth axis, `table_sync.rs`): the table angle at every arm sample of the
/// stretch, and one 0x19 frame per sample after the first, sent in the same bus period as
/// that sample's arm frame (0x1D).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SyncedStretch {
    /// Arm sample index of the stretch's first sample (where the table stands at `angles[0]`).
    pub first_sample: usize,
    /// Table angle per arm sample from `first_sample` on, radians.
    pub angles: Vec<f64>,
    /// One 0x19 frame per angle after the first (hex), time = the period.
    pub frames: Vec<String>,
}

impl SyncedStretch {
    /// Arm sample index of the stretch's last sample.
    pub fn last_sample(&self) -> usize {
        self.first_sample + self.angles.len().saturating_sub(1)
    }
}

/// A synced stretch `run` may send: the raw target of each table frame and its bytes.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedSynced {
    /// Arm sample index of the stretch's first sample; frame `i` goes with arm sample
    /// `first_sample + 1 + i`.
    pub first_sample: usize,
    /// Raw count each frame sends the table servo to.
    pub raw: Vec<u16>,
    /// The frames' bytes.
    pub frames: Vec<Vec<u8>>,
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
    /// The synced stretches in order.
    pub synced: Vec<CheckedSynced>,
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
    /// The stretches in which the table turns with the arm (strokes ground with the table as
    /// a sixth axis), in order; absent in plans without in-stroke table motion.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub synced: Vec<SyncedStretch>,
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

    /// The table angle after the last move or synced stretch, radians (a move at a
    /// stretch's last sample comes after it).
    pub fn end(&self) -> f64 {
        let mv = self
            .moves
            .last()
            .and_then(|m| Some((m.at_sample, *m.samples.last()?)));
        let st = self
            .synced
            .last()
            .and_then(|s| Some((s.last_sample(), *s.angles.last()?)));
        match (mv, st) {
            (Some(m), Some(s)) if s.0 > m.0 => s.1,
            (Some(m), _) => m.1,
            (None, Some(s)) => s.1,
            (None, None) => self.start,
        }
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

/// The limits one table sample path is checked against.
struct SampleRule<'a> {
    table: &'a Turntable,
    time_ms: u16,
    range: [f64; 2],
    /// Largest step per period, rad.
    most: f64,
    /// Largest change of step per period, rad.
    most_change: f64,
}

impl SampleRule<'_> {
    /// Checks `samples` (`what`: "move 3", "synced stretch 1") starting at `angle` where the
    /// table stands: inside the range, every step within the velocity limit and every change
    /// of step within the acceleration limit, from rest to rest, and every frame equal byte
    /// for byte to the 0x19 frame its sample makes. Returns the frames' bytes.
    fn check(
        &self,
        what: &str,
        samples: &[f64],
        frames: &[String],
        angle: f64,
    ) -> Result<Vec<Vec<u8>>, PlanError> {
        let bad = |m: String| Err(PlanError::Frames(format!("turntable: {what}{m}")));
        let [lo, hi] = self.range;
        if samples.len() < 2 || frames.len() + 1 != samples.len() {
            return bad(format!(
                ": {} frames for {} samples",
                frames.len(),
                samples.len()
            ));
        }
        if (samples[0] - angle).abs() > 1e-9 {
            return bad(format!(
                ": starts at {} rad, the table is at {angle} rad",
                samples[0]
            ));
        }
        let mut bytes = Vec::with_capacity(frames.len());
        for (i, q) in samples.iter().enumerate() {
            if !(q.is_finite() && *q >= lo - 1e-12 && *q <= hi + 1e-12) {
                return bad(format!(" sample {i}: {q} rad outside {lo}..={hi} rad"));
            }
            if i == 0 {
                continue;
            }
            let step = (q - samples[i - 1]).abs();
            if step > self.most {
                return bad(format!(
                    " sample {i}: steps {step:.5} rad in one period, the velocity limit allows {:.5}",
                    self.most
                ));
            }
            let change = if i >= 2 {
                q - 2.0 * samples[i - 1] + samples[i - 2]
            } else {
                q - samples[0]
            };
            if change.abs() > self.most_change {
                return bad(format!(
                    " sample {i}: its step changes by {:.6} rad, the acceleration limit allows {:.6}",
                    change.abs(),
                    self.most_change
                ));
            }
            let want = frame(self.table, *q, self.time_ms)?;
            if to_hex(&want) != frames[i - 1] {
                return bad(format!(
                    " frame {}: is not the frame sample {i} makes ({})",
                    i - 1,
                    to_hex(&want)
                ));
            }
            bytes.push(want);
        }
        let last = samples.len() - 1;
        if (samples[last] - samples[last - 1]).abs() > self.most_change {
            return bad(format!(
                ": does not end at rest (last step {:.6} rad)",
                (samples[last] - samples[last - 1]).abs()
            ));
        }
        Ok(bytes)
    }
}

/// Checks the plan's table part against the cell's `table`: the servo id, each move's place
/// (in order, within the arm's samples) and each synced stretch's (in order, within the arm's
/// samples, no move inside it), continuity from the start angle, every sample inside the
/// table's range (so every raw target inside its raw and degree ranges), every step within its
/// velocity limit and every change of step within its acceleration limit, and every frame
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
    let [v, a, _] = table.limits();
    let rule = SampleRule {
        table,
        time_ms: frame_time_ms(period)?,
        range: table.range(),
        most: v * period * (1.0 + STEP_TOLERANCE),
        most_change: a * period * period * (1.0 + STEP_TOLERANCE),
    };
    let start_raw = table
        .raw(plan.start)
        .map_err(|m| PlanError::Frames(format!("turntable: start: {m}")))?;
    // the moves and stretches in time order: a move at sample k comes after a stretch ending
    // there and before one starting there
    let mut events: Vec<(usize, bool, usize)> = (plan.moves.iter().enumerate())
        .map(|(k, m)| (m.at_sample, true, k))
        .chain(
            plan.synced
                .iter()
                .enumerate()
                .map(|(k, s)| (s.first_sample, false, k)),
        )
        .collect();
    events.sort_by_key(|e| (e.0, !e.1));
    let (mut at, mut angle, mut busy_to) = (0usize, plan.start, 0usize);
    let (mut moves, mut synced) = (Vec::new(), Vec::new());
    let (mut next_move, mut next_sync) = (0usize, 0usize);
    for (sample, is_move, k) in events {
        let (what, expected) = if is_move {
            (format!("move {k}"), &mut next_move)
        } else {
            (format!("synced stretch {k}"), &mut next_sync)
        };
        let last = if is_move {
            sample
        } else {
            plan.synced[k].last_sample()
        };
        if k != *expected || sample < at.max(busy_to) || last >= arm_samples.max(1) {
            return bad(format!(
                "{what}: at arm sample {sample} (out of order, inside a synced stretch or past the last)"
            ));
        }
        *expected += 1;
        if is_move {
            let m = &plan.moves[k];
            let bytes = rule.check(&what, &m.samples, &m.frames, angle)?;
            moves.push(CheckedMove {
                at_sample: m.at_sample,
                raw: bytes.iter().map(|f| frame_raw(f)).collect(),
                frames: bytes,
            });
            angle = *m.samples.last().unwrap_or(&angle);
            at = sample;
        } else {
            let s = &plan.synced[k];
            let bytes = rule.check(&what, &s.angles, &s.frames, angle)?;
            synced.push(CheckedSynced {
                first_sample: s.first_sample,
                raw: bytes.iter().map(|f| frame_raw(f)).collect(),
                frames: bytes,
            });
            angle = *s.angles.last().unwrap_or(&angle);
            (at, busy_to) = (last, last);
        }
    }
    Ok(CheckedTable {
        servo_id: table.servo.id,
        raw_range: table.servo.raw_range,
        start_raw,
        moves,
        synced,
    })
}

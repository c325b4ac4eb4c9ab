//! Planning with a part turntable (an indexing axis): per region the table angle that brings
//! it into the arm's reach (most reachable area, then least turning away from the calibrated
//! placement), chosen before the strokes; regions grouped by angle and the groups visited in
//! one sweep of the table; each group planned as today ([`super::plan_part`]) with the part, and
//! the collision model's part, turned to its angle; between groups the arm rests at home while
//! the table makes a rest-to-rest Ruckig move. Method: docs/ALGORITHMS.md, "Turntable".
//!
//! Front function: [`plan`] (the cell's turntable, if any, beside [`super::plan_part`]'s
//! arguments); result: [`Plan`] with its `turntable` part ([`TablePlan`]).
use super::check::tool_reaches;
use super::config::PlanConfig;
use super::config::PlanMode;
use super::error::PlanError;
use super::file::Plan;
use super::raster;
use super::table_file::{frame, SyncedStretch};
use super::table_file::{table_move, RegionTable, TablePiece, TablePlan, TriedAngle};
use super::table_split::{self as split, concat, PieceCell, MIN_PIECE_GAIN, MIN_PIECE_POINTS};
use super::table_sync;
use crate::repair::{Inspection, RegionInfo};
use crate::robot::{Robot, Turntable, Workcell};

/// Every how many samples of a synced stroke its table angle joins the region's angles at
/// which its reachable points are counted (a stroke turns the table by at most a few degrees
/// over ten samples; counting every sample would cost an IK call per core point each).
const SYNC_REACH_STRIDE: usize = 10;
/// Spacing of the candidate table angles, degrees: the IK accepts the tool axis within a cone
/// around the normal (45 degrees), so 5-degree steps lose at most 2.5 degrees of it; over a
/// 270-degree table that is 55 candidates.
const CANDIDATE_STEP_DEG: f64 = 5.0;
/// Most core points of a region tried per candidate angle (evenly strided): the reachable
/// share is then known to about 1/150 of the region, and a region costs 55 x 150 IK calls.
const SAMPLE_POINTS: usize = 150;
/// Reachable shares in the same band of this width count as equally good; among them the
/// angle nearest the calibrated placement (0) wins (least table motion).
const TIE_SHARE: f64 = 0.02;
/// Candidate angles tried, best first, for a region its group leaves short (a refused free
/// move, a link against the part): six plans per region at most.
const FALLBACK_ANGLES: usize = 6;
/// Least difference between the candidate angles tried for one region, degrees: the arm's
/// links clear the part or hit it over tens of degrees, so neighbouring 5-degree steps would
/// repeat the same failure (seen on the posterior condyle in tests/turntable.rs).
const FALLBACK_SPREAD_DEG: f64 = 20.0;
/// Share of a region's core points a plan should cover: a region its group leaves below this
/// is tried alone at its next candidate angles (the reach estimate samples single points; the
/// strokes can still split or be refused at the chosen angle).
pub(super) const GOOD_COVERAGE: f64 = 0.95;

/// Plans `inspection` in a cell with `table` (`None`: exactly [`super::plan_part`]).
pub fn plan(
    inspection: &Inspection,
    robot: &Robot,
    workcell: &Workcell,
    table: Option<&Turntable>,
    config: &PlanConfig,
) -> Result<Plan, PlanError> {
    let Some(table) = table else {
        return super::plan_part(inspection, robot, workcell, config);
    };
    config.check(robot)?;
    let ranked = rank_angles(inspection, robot, workcell, table, config);
    let choices: Vec<RegionTable> = ranked.iter().map(|r| r.choice.clone()).collect();
    let mut cell = GroupedPlan {
        inspection,
        robot,
        workcell,
        table,
        config,
        merged: None,
        table_plan: TablePlan {
            servo_id: table.servo.id,
            start: 0.0,
            regions: choices,
            moves: Vec::new(),
            synced: Vec::new(),
        },
    };
    let groups = sweep(&cell.table_plan.regions, inspection, |r| {
        planned(r, config, robot)
    });
    for (angle, regions) in groups {
        cell.plan_group(angle, regions, &ranked)?;
    }
    cell.split_short()?;
    let GroupedPlan {
        merged, table_plan, ..
    } = cell;
    let mut plan = merged.ok_or_else(|| PlanError::Config("no region to plan".into()))?;
    let order = |id: usize| inspection.regions.iter().position(|r| r.id == id);
    plan.reachability.regions.sort_by_key(|r| order(r.id));
    let extra = table_plan.duration(plan.period);
    plan.predicted_duration_s += extra;
    plan.metrics.predicted_duration_s += extra;
    plan.turntable = Some(table_plan);
    Ok(plan)
}

/// A region's chosen angle and every candidate angle (radians) best first.
struct Ranked {
    choice: RegionTable,
    candidates: Vec<f64>,
}

/// The plan being built group by group.
struct GroupedPlan<'a> {
    inspection: &'a Inspection,
    robot: &'a Robot,
    workcell: &'a Workcell,
    table: &'a Turntable,
    config: &'a PlanConfig,
    merged: Option<Plan>,
    table_plan: TablePlan,
}

impl<'a> GroupedPlan<'a> {
    /// `regions` planned as today with the part turned to `angle`.
    fn plan_at(&self, angle: f64, regions: Vec<RegionInfo>) -> Result<Plan, PlanError> {
        let mut part = self.inspection.clone();
        part.regions = regions;
        let wc = self.table.workcell_at(self.workcell, angle);
        super::plan_part(&part, self.robot, &wc, self.config)
    }

    /// Appends `sub`, planned at `angle`, after a table move to it if needed.
    fn append(&mut self, angle: f64, sub: Plan) -> Result<(), PlanError> {
        let at = self.merged.as_ref().map_or(0, |m| m.samples.len() - 1);
        let end = self.table_plan.end();
        if (angle - end).abs() > 1e-12 {
            let mv = table_move(self.table, end, angle, at, &self.config.trajectory)?;
            self.table_plan.moves.push(mv);
        }
        self.merged = Some(match self.merged.take() {
            None => sub,
            Some(m) => concat(m, sub),
        });
        Ok(())
    }

    /// Plans the group `regions` at `angle` and appends it; a region the group leaves short
    /// of [`GOOD_COVERAGE`] (or every region, when the group needs a free move the collision
    /// model refuses) is tried alone at its next candidate angles and moves to the best of
    /// them, appended after the group.
    fn plan_group(
        &mut self,
        angle: f64,
        regions: Vec<RegionInfo>,
        ranked: &[Ranked],
    ) -> Result<(), PlanError> {
        let (group, weak) = match self.plan_at(angle, regions.clone()) {
            Ok(sub) => {
                let weak: Vec<RegionInfo> = regions
                    .iter()
                    .filter(|r| {
                        sub.reachability.regions.iter().any(|rep| {
                            rep.id == r.id && rep.layers > 0 && rep.coverage_of_all < GOOD_COVERAGE
                        })
                    })
                    .cloned()
                    .collect();
                (Some(sub), weak)
            }
            // a free move the collision model refuses at this angle, or the check of the
            // whole trajectory finds a sample against the part: each region alone
            Err(e @ (PlanError::Collision(_) | PlanError::Collides(_))) => {
                let first = first_clause(&e.to_string());
                let mut alone = Vec::new();
                for region in regions.iter() {
                    let best = self.best_alone(region, ranked, None);
                    let msg = || {
                        PlanError::Collision(format!(
                            "region {} at each of its {FALLBACK_ANGLES} best table angles (first: {first})",
                            region.id
                        ))
                    };
                    alone.push(best.ok_or_else(msg)?);
                }
                return self.append_alone(alone);
            }
            Err(e) => return Err(e),
        };
        let mut moved = Vec::new();
        let mut kept: Vec<RegionInfo> = regions.clone();
        for region in &weak {
            let had = coverage(group.as_ref(), region.id);
            if let Some(alt) = self.best_alone(region, ranked, Some(angle)) {
                if coverage(Some(&alt.1), region.id) > had + 1e-9 {
                    kept.retain(|r| r.id != region.id);
                    moved.push(alt);
                }
            }
        }
        let group = match (moved.is_empty(), kept.is_empty()) {
            (true, _) => group,
            (false, true) => None,
            (false, false) => Some(self.plan_at(angle, kept)?),
        };
        if let Some(sub) = group {
            self.append(angle, sub)?;
        }
        self.append_alone(moved)
    }

    /// Splits every region with strokes that the plan so far leaves short of
    /// [`GOOD_COVERAGE`] by table angle: up to `config.table_pieces` further pieces
    /// (docs/ALGORITHMS.md, "Turntable", step 5; `table_split.rs`).
    fn split_short(&mut self) -> Result<(), PlanError> {
        for k in 0..self.inspection.regions.len() {
            if !planned(&self.inspection.regions[k], self.config, self.robot) {
                continue;
            }
            for _ in 0..self.config.table_pieces {
                if !self.add_piece(k)? {
                    break;
                }
            }
            if self.config.table_sync > 0 && self.config.mode == PlanMode::Rigid {
                self.add_synced(k)?;
            }
        }
        Ok(())
    }

    /// The cell a piece of a region is planned in.
    fn piece_cell(&self) -> PieceCell<'a> {
        PieceCell {
            inspection: self.inspection,
            robot: self.robot,
            workcell: self.workcell,
            table: self.table,
            config: self.config,
        }
    }

    /// The plan so far and the core points of region `id` no stroke of it covers yet, when
    /// the region is covered less than [`GOOD_COVERAGE`] and at least [`MIN_PIECE_POINTS`]
    /// are left; None otherwise.
    fn still_uncovered(&self, cell: &PieceCell, id: usize) -> Option<(&Plan, Vec<usize>)> {
        let merged = self.merged.as_ref()?;
        let (left, n) = split::uncovered(cell, merged, id);
        let covered = 1.0 - left.len() as f64 / n.max(1) as f64;
        (covered < GOOD_COVERAGE && left.len() >= MIN_PIECE_POINTS).then_some((merged, left))
    }

    /// Plans the core points of region `k` (regions.json order) no stroke covers yet as a
    /// piece at the best of its candidate angles and appends it; false when the region is
    /// covered enough or no angle adds enough.
    fn add_piece(&mut self, k: usize) -> Result<bool, PlanError> {
        let region = self.inspection.regions[k].clone();
        let cell = self.piece_cell();
        let Some((merged, left)) = self.still_uncovered(&cell, region.id) else {
            return Ok(false);
        };
        let entry = &self.table_plan.regions[k];
        let used: Vec<f64> = entry.angles_deg().map(f64::to_radians).collect();
        let ranked = split::rank(&cell, &left, &candidates(self.table), &used, used[0]);
        let part = split::piece_of(self.inspection, &region, &left, merged.removal.as_ref());
        let mut best: Option<(f64, Plan, usize)> = None;
        for angle in spread(&ranked).into_iter().take(split::PIECE_ANGLES) {
            let wc = self.table.workcell_at(self.workcell, angle);
            // refused at this angle (a free move, a collision): no piece there
            let Ok(sub) = super::plan_part(&part, self.robot, &wc, self.config) else {
                continue;
            };
            let got = split::gained(&cell, &sub, region.id, &left);
            if best.as_ref().is_none_or(|b| got > b.2) {
                best = Some((angle, sub, got));
            }
            if got as f64 >= GOOD_COVERAGE * left.len() as f64 {
                break;
            }
        }
        let Some((angle, sub, got)) = best else {
            return Ok(false);
        };
        if got < MIN_PIECE_POINTS || (got as f64) < MIN_PIECE_GAIN * left.len() as f64 {
            return Ok(false);
        }
        self.append(angle, sub)?;
        let mut angles = used;
        angles.push(angle);
        let coverage = self
            .merged
            .as_mut()
            .and_then(|merged| split::fold(&cell, merged, &region, &angles))
            .unwrap_or(0.0);
        self.table_plan.regions[k].pieces.push(TablePiece {
            angle_deg: tidy_deg(angle),
            points: left.len(),
            coverage,
        });
        Ok(true)
    }

    /// Grinds the core points of region `k` no stroke covers yet with strokes during which
    /// the table turns (`table_sync.rs`), when they add enough; false when not.
    fn add_synced(&mut self, k: usize) -> Result<bool, PlanError> {
        let region = self.inspection.regions[k].clone();
        let cell = self.piece_cell();
        let Some((merged, left)) = self.still_uncovered(&cell, region.id) else {
            return Ok(false);
        };
        let part = split::piece_of(self.inspection, &region, &left, merged.removal.as_ref());
        let parts = table_sync::synced(&cell, &part, &region, self.table_plan.end());
        if table_sync::gained(&cell, &parts, region.id, &left) < MIN_PIECE_POINTS {
            return Ok(false);
        }
        let time_ms = super::frames::frame_time_ms(self.config.trajectory.period)?;
        let mut angles: Vec<f64> = self.table_plan.regions[k]
            .angles_deg()
            .map(f64::to_radians)
            .collect();
        let strokes = parts.len();
        let mut coverage = 0.0;
        for part in parts {
            let base = self.merged.as_ref().map_or(0, |m| m.samples.len() - 1);
            self.append(part.start, part.plan)?;
            let first_sample = base + part.first_sample;
            let frames = part.angles[1..]
                .iter()
                .map(|&a| frame(self.table, a, time_ms).map(|f| super::frames::to_hex(&f)))
                .collect::<Result<_, _>>()?;
            angles.extend(part.angles.iter().step_by(SYNC_REACH_STRIDE).copied());
            self.table_plan.synced.push(SyncedStretch {
                first_sample,
                angles: part.angles,
                frames,
            });
            // one report per region: each stroke's folded in as it is appended
            coverage = self
                .merged
                .as_mut()
                .and_then(|merged| split::fold(&cell, merged, &region, &angles))
                .unwrap_or(0.0);
        }
        let entry = &mut self.table_plan.regions[k];
        entry.synced_strokes = strokes;
        entry.synced_coverage = Some(coverage);
        Ok(true)
    }

    /// Appends regions planned alone, sorted by angle from where the table stands.
    fn append_alone(&mut self, mut alone: Vec<(f64, Plan, usize)>) -> Result<(), PlanError> {
        let end = self.table_plan.end();
        alone.sort_by(|a, b| (a.0 - end).abs().total_cmp(&(b.0 - end).abs()));
        for (angle, sub, k) in alone {
            self.table_plan.regions[k].angle_deg = tidy_deg(angle);
            self.append(angle, sub)?;
        }
        Ok(())
    }

    /// `region` planned alone at each of its first [`FALLBACK_ANGLES`] candidate angles but
    /// `skip`: the plan covering most of it (angle, plan, index in regions.json order). Every
    /// angle tried goes into the region's `tried` list.
    fn best_alone(
        &mut self,
        region: &RegionInfo,
        ranked: &[Ranked],
        skip: Option<f64>,
    ) -> Option<(f64, Plan, usize)> {
        let k = self
            .inspection
            .regions
            .iter()
            .position(|r| r.id == region.id)?;
        let mut best: Option<(f64, Plan, usize)> = None;
        let mut tried = Vec::new();
        for &angle in ranked[k].candidates.iter().take(FALLBACK_ANGLES) {
            if skip.is_some_and(|s| (s - angle).abs() < 1e-9) {
                continue;
            }
            let sub = match self.plan_at(angle, vec![region.clone()]) {
                Ok(sub) => sub,
                Err(e) => {
                    tried.push(TriedAngle {
                        angle_deg: tidy_deg(angle),
                        coverage: 0.0,
                        refused: Some(first_clause(&e.to_string())),
                    });
                    continue;
                }
            };
            let c = coverage(Some(&sub), region.id);
            // short of good: the first reason the plan there gives for the region's contacts
            let why = sub
                .reachability
                .unreachable
                .iter()
                .find(|u| u.region == region.id && c < GOOD_COVERAGE)
                .map(|u| first_clause(&u.reason));
            tried.push(TriedAngle {
                angle_deg: tidy_deg(angle),
                coverage: c,
                refused: why,
            });
            if best
                .as_ref()
                .is_none_or(|b| c > coverage(Some(&b.1), region.id))
            {
                best = Some((angle, sub, k));
            }
            if c >= GOOD_COVERAGE {
                break;
            }
        }
        tried.sort_by(|a, b| b.coverage.total_cmp(&a.coverage));
        self.table_plan.regions[k].tried.extend(tried);
        best
    }
}

/// Longest reason kept for a refused table angle, characters (a collision error lists every
/// sample; its first clause names the rule, the body and the place).
const REASON_CHARS: usize = 240;

/// The first clause of a planner error (up to the first `;`), at most [`REASON_CHARS`].
pub(super) fn first_clause(e: &str) -> String {
    let first = e.split(';').next().unwrap_or(e).trim();
    first.chars().take(REASON_CHARS).collect()
}

/// Share of region `id`'s core points a plan covers (0 without a plan).
pub(super) fn coverage(plan: Option<&Plan>, id: usize) -> f64 {
    plan.and_then(|p| p.reachability.regions.iter().find(|r| r.id == id))
        .map_or(0.0, |r| r.coverage_of_all)
}

/// An angle in degrees rounded to 1e-9 degree (the candidates are whole steps: no 59.999...).
fn tidy_deg(angle: f64) -> f64 {
    (angle.to_degrees() * 1e9).round() / 1e9
}

/// Whether `region` gets strokes (the filter of [`super::plan_part`]).
pub(super) fn planned(region: &RegionInfo, config: &PlanConfig, robot: &Robot) -> bool {
    let geometry = config.geometry(robot.tool.radius_mm());
    region.repairable && !raster::layer_offsets(region.peak, &geometry).is_empty()
}

/// The table angle of every region of `inspection` (regions.json order): for planned regions
/// the candidate with the largest reachable share (ties: nearest 0); for the rest 0.
pub fn choose_angles(
    inspection: &Inspection,
    robot: &Robot,
    workcell: &Workcell,
    table: &Turntable,
    config: &PlanConfig,
) -> Vec<RegionTable> {
    rank_angles(inspection, robot, workcell, table, config)
        .into_iter()
        .map(|r| r.choice)
        .collect()
}

/// [`choose_angles`] with every region's candidates ranked: larger reachable share first
/// (shares within [`TIE_SHARE`] equal), then nearer 0.
fn rank_angles(
    inspection: &Inspection,
    robot: &Robot,
    workcell: &Workcell,
    table: &Turntable,
    config: &PlanConfig,
) -> Vec<Ranked> {
    let reach = robot.tool.radius_mm() + config.contact_offset_mm;
    let candidates = candidates(table);
    let cells: Vec<Workcell> = candidates
        .iter()
        .map(|&a| table.workcell_at(workcell, a))
        .collect();
    let zero = table.workcell_at(workcell, 0.0);
    inspection
        .regions
        .iter()
        .map(|region| {
            let members = inspection.region_points(region.id);
            let stride = members.len().div_ceil(SAMPLE_POINTS).max(1);
            let tried: Vec<_> = members.iter().step_by(stride).collect();
            let share = |wc: &Workcell| {
                let n = tried
                    .iter()
                    .filter(|&&&i| tool_reaches(&inspection.points[i], robot, wc, config, reach))
                    .count();
                n as f64 / tried.len().max(1) as f64
            };
            let at_zero = share(&zero);
            let mut order = vec![(0.0, at_zero)];
            if planned(region, config, robot) {
                order = candidates
                    .iter()
                    .copied()
                    .zip(cells.iter().map(share))
                    .collect();
                let tier = |s: f64| (s / TIE_SHARE).floor();
                order.sort_by(|x, y| {
                    tier(y.1)
                        .total_cmp(&tier(x.1))
                        .then(x.0.abs().total_cmp(&y.0.abs()))
                });
            }
            Ranked {
                choice: RegionTable {
                    region: region.id,
                    angle_deg: tidy_deg(order[0].0),
                    reachable_share: order[0].1,
                    reachable_share_at_zero: at_zero,
                    tried: Vec::new(),
                    pieces: Vec::new(),
                    synced_strokes: 0,
                    synced_coverage: None,
                },
                candidates: spread(&order),
            }
        })
        .collect()
}

/// The candidate table angles, radians: every [`CANDIDATE_STEP_DEG`] over the table's range.
fn candidates(table: &Turntable) -> Vec<f64> {
    let [lo, hi] = table.range();
    let step = CANDIDATE_STEP_DEG.to_radians();
    ((lo / step).ceil() as i64..=(hi / step).floor() as i64)
        .map(|k| k as f64 * step)
        .collect()
}

/// The ranked angles `order` (radians, best first) thinned so that each differs from every
/// earlier one by at least [`FALLBACK_SPREAD_DEG`]: the alternatives then approach the region
/// from clearly different sides instead of repeating the best one's approach.
fn spread(order: &[(f64, f64)]) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for &(a, _) in order {
        if out
            .iter()
            .all(|b| (a - b).abs() >= FALLBACK_SPREAD_DEG.to_radians() - 1e-9)
        {
            out.push(a);
        }
    }
    out
}

/// The regions grouped by table angle (radians) in visiting order: one sweep from 0 over the
/// angles of the regions that get strokes (`is_planned`), towards the nearer end first. The
/// other regions (reported, not ground) ride with the first group.
fn sweep(
    choices: &[RegionTable],
    inspection: &Inspection,
    is_planned: impl Fn(&RegionInfo) -> bool,
) -> Vec<(f64, Vec<RegionInfo>)> {
    let pairs: Vec<(&RegionInfo, f64)> = inspection
        .regions
        .iter()
        .zip(choices)
        .map(|(r, c)| (r, c.angle_deg))
        .collect();
    let mut angles: Vec<f64> = pairs
        .iter()
        .filter(|(r, _)| is_planned(r))
        .map(|p| p.1)
        .collect();
    angles.sort_by(f64::total_cmp);
    angles.dedup();
    if angles.last().is_some_and(|l| l.abs() < angles[0].abs()) {
        angles.reverse();
    }
    if angles.is_empty() {
        angles.push(0.0);
    }
    let mut groups: Vec<(f64, Vec<RegionInfo>)> = angles
        .iter()
        .map(|&a| {
            let regions = pairs
                .iter()
                .filter(|(r, b)| is_planned(r) && *b == a)
                .map(|(r, _)| (*r).clone())
                .collect();
            (a.to_radians(), regions)
        })
        .collect();
    let idle = pairs.iter().filter(|(r, _)| !is_planned(r));
    groups[0].1.extend(idle.map(|(r, _)| (*r).clone()));
    groups
}

//! Regions split by table angle (issue 51, "the table as a sixth axis", at stroke
//! granularity): after the groups are planned, a region its strokes still leave short of
//! [`GOOD_COVERAGE`] is split. The core points no stroke covers yet become a piece of the
//! region, planned alone at the table angle that best reaches them; the table turns between
//! the pieces while the arm rests at home ([`GroupedPlan::append`]), so the table angle changes
//! from stroke to stroke within the region. The piece's report is folded into the region's
//! (one report per region, its coverage the union of its pieces'), and the region's left-out
//! contacts a piece now grinds leave the unreachable list. Method: docs/ALGORITHMS.md,
//! "Turntable".
//!
//! Front: [`GroupedPlan::split_short`], called by [`super::plan`] after the groups.
use super::super::check::{tool_reaches, Cover};
use super::super::error::PlanError;
use super::super::file::Plan;
use super::super::table_file::TablePiece;
use super::{planned, spread, tidy_deg, GroupedPlan, CANDIDATE_STEP_DEG, GOOD_COVERAGE};
use crate::repair::{Inspection, RegionInfo};

/// Most further pieces per region: each costs a table move and an approach from home, and
/// the uniform femoral cases gained nothing from a third (their rest lies beyond the 45
/// degree cone at every angle).
const MAX_PIECES: usize = 2;
/// Table angles planned per piece, best reach first (each a whole plan of the piece).
const PIECE_ANGLES: usize = 3;
/// Fewest uncovered core points worth a piece (and the fewest a piece must add): at the
/// inspection's spacing a handful of points is under one footprint, which the neighbouring
/// strokes' rims already graze.
const MIN_PIECE_POINTS: usize = 5;
/// Least share of the uncovered points a piece must cover to be kept (less is not worth a
/// table move and a trip from home).
const MIN_PIECE_GAIN: f64 = 0.1;
/// Most uncovered points whose reach is estimated per candidate angle (evenly strided), as
/// the table planner's `SAMPLE_POINTS`.
const RANK_POINTS: usize = 150;

impl GroupedPlan<'_> {
    /// Splits every region with strokes that the plan so far leaves short of
    /// [`GOOD_COVERAGE`] into up to [`MAX_PIECES`] further pieces at other table angles.
    pub(super) fn split_short(&mut self) -> Result<(), PlanError> {
        for k in 0..self.inspection.regions.len() {
            if !planned(&self.inspection.regions[k], self.config, self.robot) {
                continue;
            }
            for _ in 0..MAX_PIECES {
                if !self.add_piece(k)? {
                    break;
                }
            }
        }
        Ok(())
    }

    /// Plans the uncovered core points of region `k` (regions.json order) as a piece at the
    /// best of its [`PIECE_ANGLES`] candidate angles and appends it; false when the region is
    /// covered enough or no angle adds enough.
    fn add_piece(&mut self, k: usize) -> Result<bool, PlanError> {
        let region = self.inspection.regions[k].clone();
        let Some(merged) = self.merged.as_ref() else {
            return Ok(false);
        };
        let footprint = merged.footprint_mm;
        let members = self.inspection.region_points(region.id);
        let cover = Cover::new(&merged.passes, region.id, footprint);
        let points = &self.inspection.points;
        let left: Vec<usize> = members
            .iter()
            .copied()
            .filter(|&i| !cover.covers(&points[i].position))
            .collect();
        let n = members.len().max(1);
        if 1.0 - left.len() as f64 / n as f64 >= GOOD_COVERAGE || left.len() < MIN_PIECE_POINTS {
            return Ok(false);
        }
        let part = piece_of(self.inspection, &region, &left);
        let mut best: Option<(f64, Plan, usize)> = None;
        for angle in self.piece_angles(k, &left) {
            let wc = self.table.workcell_at(self.workcell, angle);
            // a piece refused at this angle (a free move, a collision) is not a piece there
            let Ok(sub) = super::super::plan_part(&part, self.robot, &wc, self.config) else {
                continue;
            };
            let got = Cover::new(&sub.passes, region.id, footprint);
            let gained = left
                .iter()
                .filter(|&&i| got.covers(&points[i].position))
                .count();
            if best.as_ref().is_none_or(|b| gained > b.2) {
                best = Some((angle, sub, gained));
            }
            if gained as f64 >= GOOD_COVERAGE * left.len() as f64 {
                break;
            }
        }
        let Some((angle, sub, gained)) = best else {
            return Ok(false);
        };
        if gained < MIN_PIECE_POINTS || (gained as f64) < MIN_PIECE_GAIN * left.len() as f64 {
            return Ok(false);
        }
        self.append(angle, sub)?;
        let coverage = self.fold_piece(&region, k)?;
        self.table_plan.regions[k].pieces.push(TablePiece {
            angle_deg: tidy_deg(angle),
            points: left.len(),
            coverage,
        });
        Ok(true)
    }

    /// The candidate table angles (radians) for the uncovered points `left` of region `k`,
    /// best first: the larger share of them the tool reaches (a sample of [`RANK_POINTS`]),
    /// then the nearer the region's own angle (least table motion); angles the region is
    /// already ground at, and angles reaching none, left out; thinned as the table planner's
    /// fallbacks are, at most [`PIECE_ANGLES`].
    fn piece_angles(&self, k: usize, left: &[usize]) -> Vec<f64> {
        let entry = &self.table_plan.regions[k];
        let own = entry.angle_deg.to_radians();
        let used: Vec<f64> = entry.angles_deg().map(f64::to_radians).collect();
        let reach = self.robot.tool.radius_mm() + self.config.contact_offset_mm;
        let stride = left.len().div_ceil(RANK_POINTS).max(1);
        let sample: Vec<usize> = left.iter().copied().step_by(stride).collect();
        let [lo, hi] = self.table.range();
        let step = CANDIDATE_STEP_DEG.to_radians();
        let mut order: Vec<(f64, f64)> = ((lo / step).ceil() as i64..=(hi / step).floor() as i64)
            .map(|s| s as f64 * step)
            .filter(|a| used.iter().all(|u| (a - u).abs() > 1e-9))
            .map(|a| {
                let wc = self.table.workcell_at(self.workcell, a);
                let pts = &self.inspection.points;
                let n = sample
                    .iter()
                    .filter(|&&i| tool_reaches(&pts[i], self.robot, &wc, self.config, reach))
                    .count();
                (a, n as f64 / sample.len().max(1) as f64)
            })
            .filter(|(_, share)| *share > 0.0)
            .collect();
        order.sort_by(|x, y| {
            y.1.total_cmp(&x.1)
                .then((x.0 - own).abs().total_cmp(&(y.0 - own).abs()))
        });
        let mut out = spread(&order);
        out.truncate(PIECE_ANGLES);
        out
    }

    /// Folds the piece just appended into region `k`'s report: one report per region (the
    /// piece's removed), its path points and layers summed over the pieces, its coverage the
    /// union of theirs, its reachable points those the tool reaches at any of its angles; the
    /// region's left-out contacts that some stroke now covers leave the unreachable list.
    /// Returns the region's coverage.
    fn fold_piece(&mut self, region: &RegionInfo, k: usize) -> Result<f64, PlanError> {
        let missing = || PlanError::Config(format!("region {}: no report to fold", region.id));
        let merged = self.merged.as_mut().ok_or_else(missing)?;
        let reports = &mut merged.reachability.regions;
        let last = reports.iter().rposition(|r| r.id == region.id);
        let first = reports.iter().position(|r| r.id == region.id);
        let (Some(first), Some(last)) = (first, last) else {
            return Err(missing());
        };
        if first != last {
            let piece = reports.remove(last);
            let r = &mut reports[first];
            r.layers = r.layers.max(piece.layers);
            r.path_points += piece.path_points;
            r.unreachable_path_points += piece.unreachable_path_points;
        }
        let cover = Cover::new(&merged.passes, region.id, merged.footprint_mm);
        merged
            .reachability
            .unreachable
            .retain(|u| u.region != region.id || !cover.covers(&u.surface_mm.into()));
        let members = self.inspection.region_points(region.id);
        let reach = self.robot.tool.radius_mm() + self.config.contact_offset_mm;
        let mut angles: Vec<f64> = self.table_plan.regions[k]
            .angles_deg()
            .map(f64::to_radians)
            .collect();
        // the piece just appended: the table stands at its angle
        angles.push(self.table_plan.end());
        let cells: Vec<_> = angles
            .iter()
            .map(|&a| self.table.workcell_at(self.workcell, a))
            .collect();
        let pts = &self.inspection.points;
        let (mut reachable, mut covered, mut both) = (0usize, 0usize, 0usize);
        for &i in &members {
            let ok = cells
                .iter()
                .any(|wc| tool_reaches(&pts[i], self.robot, wc, self.config, reach));
            let near = cover.covers(&pts[i].position);
            reachable += usize::from(ok);
            covered += usize::from(near);
            both += usize::from(ok && near);
        }
        let n = members.len().max(1) as f64;
        let r = &mut merged.reachability.regions[first];
        r.reachable_points = reachable;
        r.unreachable_share = 1.0 - reachable as f64 / n;
        r.coverage_of_reachable = if reachable == 0 {
            0.0
        } else {
            both as f64 / reachable as f64
        };
        r.coverage_of_all = covered as f64 / n;
        Ok(r.coverage_of_all)
    }
}

/// The inspection with region `region` cut down to its core points `left` (the others no
/// longer in a region: they are ground, or neighbours, for the piece's plan).
fn piece_of(inspection: &Inspection, region: &RegionInfo, left: &[usize]) -> Inspection {
    let mut part = inspection.clone();
    for p in part
        .points
        .iter_mut()
        .filter(|p| p.region == region.id as i64)
    {
        p.region = -1;
    }
    for &i in left {
        part.points[i].region = region.id as i64;
    }
    let mut piece = region.clone();
    piece.area = region.area * left.len() as f64 / region.points.max(1) as f64;
    piece.points = left.len();
    part.regions = vec![piece];
    part
}

//! Regions split by table angle (issue 51, "the table as a sixth axis", at stroke
//! granularity): after the groups are planned, a region its strokes still leave short of
//! [`GOOD_COVERAGE`] is split. The core points no stroke covers yet become a piece of the
//! region, planned alone at the table angle that best reaches them; the table turns between
//! the pieces while the arm rests at home (as between the groups), so the table angle changes
//! from stroke to stroke within the region. The piece's report is folded into the region's
//! (one report per region, its coverage the union of its pieces'), and the region's left-out
//! contacts a piece now grinds leave the unreachable list. Method: docs/ALGORITHMS.md,
//! "Turntable".
//!
//! Front: `table::plan` calls these for each short region after the groups (its
//! `GroupedPlan::split_short`): [`uncovered`], [`rank`], [`piece_of`], [`gained`], [`fold`].
use std::collections::HashMap;

use super::check::{tool_reaches, Cover};
use super::config::PlanConfig;
use super::file::Plan;
use super::report::Metrics;
use crate::removal::prediction::RemovalReport;
use crate::repair::{Inspection, RegionInfo};
use crate::robot::{Robot, Turntable, Workcell};

/// Table angles planned per piece, best reach first (each a whole plan of the piece).
pub(super) const PIECE_ANGLES: usize = 3;
/// Fewest uncovered core points worth a piece (and the fewest a piece must add): at the
/// inspection's spacing a handful of points is under one footprint, which the neighbouring
/// strokes' rims already graze.
pub(super) const MIN_PIECE_POINTS: usize = 5;
/// Least share of the uncovered points a piece must cover to be kept (less is not worth a
/// table move and a trip from home).
pub(super) const MIN_PIECE_GAIN: f64 = 0.1;
/// Most uncovered points whose reach is estimated per candidate angle (evenly strided), as
/// the table planner's `SAMPLE_POINTS`.
const RANK_POINTS: usize = 150;

/// The cell the pieces are planned in: the part, the arm, the placement at table angle 0,
/// the table and the planner's settings.
pub(super) struct PieceCell<'a> {
    /// The part.
    pub inspection: &'a Inspection,
    /// The arm.
    pub robot: &'a Robot,
    /// The part's placement at table angle 0.
    pub workcell: &'a Workcell,
    /// The table.
    pub table: &'a Turntable,
    /// The planner's settings.
    pub config: &'a PlanConfig,
}

impl PieceCell<'_> {
    /// Whether the tool reaches core point `i` in any of `cells` (the part at table angles).
    fn reaches(&self, i: usize, cells: &[Workcell]) -> bool {
        let reach = self.robot.tool.radius_mm() + self.config.contact_offset_mm;
        let p = &self.inspection.points[i];
        cells
            .iter()
            .any(|wc| tool_reaches(p, self.robot, wc, self.config, reach))
    }
}

/// The core points of region `id` no stroke of `plan` covers, and the region's count of
/// core points.
pub(super) fn uncovered(cell: &PieceCell, plan: &Plan, id: usize) -> (Vec<usize>, usize) {
    let members = cell.inspection.region_points(id);
    let cover = Cover::new(&plan.passes, id, plan.footprint_mm);
    let pts = &cell.inspection.points;
    let left = members
        .iter()
        .copied()
        .filter(|&i| !cover.covers(&pts[i].position))
        .collect();
    (left, members.len())
}

/// How many of the core points `left` of region `id` the strokes of `sub` cover.
pub(super) fn gained(cell: &PieceCell, sub: &Plan, id: usize, left: &[usize]) -> usize {
    let cover = Cover::new(&sub.passes, id, sub.footprint_mm);
    let pts = &cell.inspection.points;
    left.iter()
        .filter(|&&i| cover.covers(&pts[i].position))
        .count()
}

/// The table angles `candidates` (radians) but those in `used`, each with the share of the
/// core points `left` the tool reaches there (a sample of [`RANK_POINTS`]), ranked: larger
/// share first, then nearer `own` (least table motion); angles reaching none left out.
pub(super) fn rank(
    cell: &PieceCell,
    left: &[usize],
    candidates: &[f64],
    used: &[f64],
    own: f64,
) -> Vec<(f64, f64)> {
    let stride = left.len().div_ceil(RANK_POINTS).max(1);
    let sample: Vec<usize> = left.iter().copied().step_by(stride).collect();
    let mut order: Vec<(f64, f64)> = candidates
        .iter()
        .copied()
        .filter(|a| used.iter().all(|u| (a - u).abs() > 1e-9))
        .map(|a| {
            let at = [cell.table.workcell_at(cell.workcell, a)];
            let n = sample.iter().filter(|&&i| cell.reaches(i, &at)).count();
            (a, n as f64 / sample.len().max(1) as f64)
        })
        .filter(|(_, share)| *share > 0.0)
        .collect();
    order.sort_by(|x, y| {
        y.1.total_cmp(&x.1)
            .then((x.0 - own).abs().total_cmp(&(y.0 - own).abs()))
    });
    order
}

/// Folds a piece of region `region`, just appended to `merged`, into the region's report:
/// one report per region (the piece's removed), its path points summed over the pieces and
/// its layers their most, its coverage the union of theirs, its reachable points those the
/// tool reaches at any of its table angles `angles` (radians); the region's left-out contacts
/// that some stroke now covers leave the unreachable list. Returns the region's coverage
/// (None when `merged` has no report of the region).
pub(super) fn fold(
    cell: &PieceCell,
    merged: &mut Plan,
    region: &RegionInfo,
    angles: &[f64],
) -> Option<f64> {
    let reports = &mut merged.reachability.regions;
    let first = reports.iter().position(|r| r.id == region.id)?;
    let last = reports.iter().rposition(|r| r.id == region.id)?;
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
    let cells: Vec<Workcell> = angles
        .iter()
        .map(|&a| cell.table.workcell_at(cell.workcell, a))
        .collect();
    let members = cell.inspection.region_points(region.id);
    let (mut reachable, mut covered, mut both) = (0usize, 0usize, 0usize);
    for &i in &members {
        let ok = cell.reaches(i, &cells);
        let near = cover.covers(&cell.inspection.points[i].position);
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
    Some(r.coverage_of_all)
}

/// The inspection with region `region` cut down to its core points `left` (the others no
/// longer in a region: they are ground, or neighbours, for the piece's plan), and the part as
/// the plan so far leaves it: a core point with a predicted residual in `earlier` (removal
/// mode) takes the lowest one, so that the piece's dwell and its over-grind check start from
/// what the earlier strokes remove (at the seam between pieces, and the neighbours).
pub(super) fn piece_of(
    inspection: &Inspection,
    region: &RegionInfo,
    left: &[usize],
    earlier: Option<&RemovalReport>,
) -> Inspection {
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
    let key = |p: [f64; 3]| p.map(f64::to_bits);
    let mut after: HashMap<[u64; 3], f64> = HashMap::new();
    for row in earlier.map_or(&[][..], |r| &r.rows[..]) {
        let at = after.entry(key(row.position)).or_insert(row.residual);
        *at = at.min(row.residual);
    }
    for p in part.points.iter_mut() {
        if let Some(&r) = after.get(&key([p.position.x, p.position.y, p.position.z])) {
            p.distance = p.distance.min(r);
        }
    }
    let mut piece = region.clone();
    piece.area = region.area * left.len() as f64 / region.points.max(1) as f64;
    piece.points = left.len();
    part.regions = vec![piece];
    part
}

/// `a` followed by `b` (which starts at the home pose `a` ends at): samples and frames after
/// `b`'s first, segments and passes re-indexed, reports, metrics and removal predictions
/// combined.
pub(super) fn concat(mut a: Plan, b: Plan) -> Plan {
    let base = a.samples.len() - 1;
    let passes = a.passes.len();
    let b_samples = b.samples.clone();
    for s in b.samples.into_iter().skip(1) {
        a.samples.push(super::file::Sample {
            t: a.samples.len() as f64 * a.period,
            q: s.q,
        });
    }
    a.frames.extend(b.frames.into_iter().skip(1));
    a.commands = match (a.commands.take(), b.commands) {
        (None, None) => None,
        (x, y) => {
            let own = |c: Option<Vec<Vec<f64>>>, s: &[super::file::Sample]| {
                c.unwrap_or_else(|| s.iter().map(|s| s.q.clone()).collect())
            };
            let mut x = own(x, &a.samples[..=base]);
            x.extend(own(y, &b_samples).into_iter().skip(1));
            Some(x)
        }
    };
    a.segments.extend(b.segments.into_iter().map(|mut s| {
        s.first_sample += base;
        s.last_sample += base;
        s.pass = s.pass.map(|p| p + passes);
        s
    }));
    a.passes.extend(b.passes);
    a.predicted_duration_s += b.predicted_duration_s;
    a.reachability.regions.extend(b.reachability.regions);
    a.reachability
        .unreachable
        .extend(b.reachability.unreachable);
    a.reachability.jumps += b.reachability.jumps;
    a.reachability.softened += b.reachability.softened;
    a.reachability.lifted += b.reachability.lifted;
    a.metrics = combine(&a.metrics, &b.metrics);
    // removal mode: each group predicted its own regions (same tool, preload and tolerance)
    a.removal = match (a.removal.take(), b.removal) {
        (Some(mut x), Some(y)) => {
            x.regions.extend(y.regions);
            x.rows.extend(y.rows);
            Some(x)
        }
        (x, y) => x.or(y),
    };
    a
}

/// Metrics of two plans run one after the other: sums, extremes, and sample-weighted means
/// (the cruise share weighted by samples too: an estimate).
fn combine(a: &Metrics, b: &Metrics) -> Metrics {
    let (wa, wb) = (a.samples as f64, b.samples.saturating_sub(1) as f64);
    let mean = |x: f64, y: f64| (x * wa + y * wb) / (wa + wb).max(1.0);
    let grinds = |m: &Metrics| m.path_points > 0;
    let cruise_min = match (grinds(a), grinds(b)) {
        (true, true) => a.cruise_feed_min_mm_s.min(b.cruise_feed_min_mm_s),
        (false, true) => b.cruise_feed_min_mm_s,
        _ => a.cruise_feed_min_mm_s,
    };
    Metrics {
        predicted_duration_s: a.predicted_duration_s + b.predicted_duration_s,
        path_points: a.path_points + b.path_points,
        samples: a.samples + b.samples.saturating_sub(1),
        resolution_error_max_mm: a.resolution_error_max_mm.max(b.resolution_error_max_mm),
        resolution_error_mean_mm: mean(a.resolution_error_mean_mm, b.resolution_error_mean_mm),
        sample_to_path_max_mm: a.sample_to_path_max_mm.max(b.sample_to_path_max_mm),
        path_to_samples_max_mm: a.path_to_samples_max_mm.max(b.path_to_samples_max_mm),
        feed_mm_s: a.feed_mm_s,
        cruise_feed_min_mm_s: cruise_min,
        cruise_feed_max_mm_s: a.cruise_feed_max_mm_s.max(b.cruise_feed_max_mm_s),
        slowed_strokes: a.slowed_strokes + b.slowed_strokes,
        cruise_share: mean(a.cruise_share, b.cruise_share),
    }
}

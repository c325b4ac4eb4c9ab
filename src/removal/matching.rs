//! What a grind's plan predicted against what the inspections measured, core point by core
//! point: predicted.csv read and matched to the core points, the same core point found in two
//! inspections ([`partners`], once per grind: [`GrindPair`]), and the pass re-predicted with a
//! fitted k ([`agreement`]). Used by the removal fit (`fit`), `cell` and `cycle`.
use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use super::prediction::PredictedRow;
use crate::repair::Inspection;
use crate::spatial::Neighbours;

/// Largest distance between a core point of two inspections for them to count as the same
/// point, mm: core points are sampled from the same reference with the same seed, so equal
/// points agree to the last bit; densified points of one inspection have no partner.
pub const SAME_POINT_MM: f64 = 1e-6;

/// Largest distance from a core point of the first inspection with no partner to the second
/// inspection's core points its measured removal is read from, mm (0.6: about twice the
/// reference sample's core spacing, 0.28 mm median; a densified point of the first inspection
/// lies 0.22 mm (median) to 0.60 mm (most, calibrate_removal's case) from the second's
/// nearest core point).
pub const NEAR_POINT_MM: f64 = 0.6;

/// Core points of the second inspection a point with no partner reads its value from (4:
/// the points around it on both sides at the core spacing; inverse-distance weighted).
const NEAR_POINTS: usize = 4;

/// Least cosine between the normals of a point with no partner and a core point it reads
/// from (0.9, 26 degrees): a point across a thin wall or an edge faces another way and
/// measures another surface.
const NEAR_NORMAL_COS: f64 = 0.9;

/// Largest distance between a predicted.csv row and its core point, mm: the file prints
/// positions with 6 decimals (rounding moves a coordinate by at most 5e-7 mm).
const CSV_POINT_MM: f64 = 1e-5;

/// Predicted removal per core point of `before`, mm: the rows of predicted.csv matched to the
/// core points by position and summed (a point in reach of two regions' tools has a row for
/// each). Rows that match no core point are an error naming the row (1-based, after the
/// header).
pub fn predicted_removal(before: &Inspection, rows: &[PredictedRow]) -> Result<Vec<f64>, String> {
    let pos: Vec<Point3<f64>> = before.points.iter().map(|p| p.position).collect();
    let index = Neighbours::new(&pos);
    let mut removal = vec![0.0; pos.len()];
    for (i, r) in rows.iter().enumerate() {
        let p = Point3::from(r.position);
        match index.nearest(&p) {
            Some(nb) if nb.dist2 <= CSV_POINT_MM * CSV_POINT_MM => {
                removal[nb.index] += r.deviation - r.residual;
            }
            _ => {
                return Err(format!(
                    "row {}: ({:.3}, {:.3}, {:.3}) is no core point of the first inspection \
                     (was the plan made from it?)",
                    i + 1,
                    p.x,
                    p.y,
                    p.z
                ))
            }
        }
    }
    Ok(removal)
}

/// The index of the core points of `inspection`.
fn index_of(inspection: &Inspection) -> Neighbours {
    let pos: Vec<Point3<f64>> = inspection.points.iter().map(|p| p.position).collect();
    Neighbours::new(&pos)
}

/// Per core point of `before`, the index of the same core point in the inspection whose core
/// points `index` holds (within [`SAME_POINT_MM`]), None for a point it has not.
fn partners(before: &Inspection, index: &Neighbours) -> Vec<Option<usize>> {
    before
        .points
        .iter()
        .map(|p| {
            index
                .nearest(&p.position)
                .filter(|nb| nb.dist2 <= SAME_POINT_MM * SAME_POINT_MM)
                .map(|nb| nb.index)
        })
        .collect()
}

/// The two inspections of a grind, before and after it, with their same core points matched
/// once ([`partners`]): what the k fit, the agreement, the removal's shift and reach
/// (`cell::removal_shift`, `cell::removal_reach`) and cycle.html's figures read.
pub struct GrindPair<'a> {
    /// The inspection before the grind (the one its plan was made from).
    pub before: &'a Inspection,
    /// The inspection of the rescan after it.
    pub after: &'a Inspection,
    /// Per core point of `before`, the index of the same core point in `after`.
    partner: Vec<Option<usize>>,
    /// The index of `after`'s core points, for the points with no partner
    /// ([`Self::removal_near`]).
    index: Neighbours,
}

impl<'a> GrindPair<'a> {
    /// Matches the core points of `before` to those of `after` ([`partners`]).
    pub fn new(before: &'a Inspection, after: &'a Inspection) -> Self {
        let index = index_of(after);
        GrindPair {
            before,
            after,
            partner: partners(before, &index),
            index,
        }
    }

    /// The index in `after` of core point `i` of `before`, None when `after` has not it.
    pub fn partner(&self, i: usize) -> Option<usize> {
        self.partner[i]
    }

    /// How many core points of `before` have a partner in `after`.
    pub fn matched(&self) -> usize {
        self.partner.iter().flatten().count()
    }

    /// The measured removal at core point `i` of `before`: its distance before minus its
    /// partner's after, mm (not finite where either was not measured); None without a partner.
    pub fn removal(&self, i: usize) -> Option<f64> {
        let j = self.partner[i]?;
        Some(self.before.points[i].distance - self.after.points[j].distance)
    }

    /// [`Self::removal`], or at a point with no partner (densified around a defect by the
    /// first inspection alone, where the removal is deepest) its distance before minus the
    /// distance `after` measured around it: the inverse-distance mean of its [`NEAR_POINTS`]
    /// nearest core points of `after` within [`NEAR_POINT_MM`] that face its way and were
    /// measured; None where neither is.
    pub fn removal_near(&self, i: usize) -> Option<f64> {
        if let Some(m) = self.removal(i) {
            return Some(m);
        }
        let p = &self.before.points[i];
        let (mut sum, mut weight) = (0.0, 0.0);
        for nb in self
            .index
            .knn_within(&p.position, NEAR_POINTS, NEAR_POINT_MM)
        {
            let a = &self.after.points[nb.index];
            if a.distance.is_finite() && a.normal.dot(&p.normal) >= NEAR_NORMAL_COS {
                // beyond SAME_POINT_MM (no partner), so the weight is finite
                let w = 1.0 / nb.dist2.sqrt();
                sum += w * a.distance;
                weight += w;
            }
        }
        (weight > 0.0).then(|| p.distance - sum / weight)
    }
}

/// The residual a pass left against the one its plan predicted, over the same defect points:
/// the plan's prediction re-made with the fitted k (issue 29: "the achieved residual agrees
/// with the plan's prediction, made with the fitted k, within 0.01 mm RMS").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Agreement {
    /// Defect points compared: core points of the planned repairable regions of the first
    /// inspection, measured (finite) in both inspections.
    pub points: usize,
    /// RMS of the residual predicted at the plan's k over them, mm.
    pub predicted_plan_k_mm: f64,
    /// RMS of the residual predicted at the fitted k (None: k not fitted), mm.
    pub predicted_fitted_k_mm: Option<f64>,
    /// RMS of the achieved residual (the second inspection's distance) over them, mm.
    pub achieved_mm: f64,
    /// RMS over them of achieved minus predicted at the fitted k (at the plan's k when k
    /// was not fitted), point by point, mm.
    pub difference_mm: f64,
    /// Lowest achieved distance over those points and every other core point where the plan
    /// predicted removal, mm: below -tolerance the pass over-ground.
    pub lowest_ground_mm: f64,
}

/// Re-predicts a ground pass with `scale` = fitted k / the plan's k and compares it with what
/// the next inspection (`pair.after`) measured, over the core points of `pair.before` in the
/// regions `ids` that both inspections measured. `predicted` is the plan's removal per core
/// point of `pair.before` at the plan's k ([`predicted_removal`]; 0 where the tool does not
/// reach); the planner's removal is k x (its influence matrix x the dwell the trajectory
/// spends), linear in k at a fixed trajectory, so the removal at k_fit is `predicted` x
/// `scale`. None: no such point.
pub fn agreement(
    pair: &GrindPair,
    predicted: &[f64],
    scale: Option<f64>,
    ids: &[i64],
) -> Option<Agreement> {
    let (before, after) = (pair.before, pair.after);
    // (defect point, deviation before, after, predicted removal) of every matched point
    let all: Vec<(bool, f64, f64, f64)> = before
        .points
        .iter()
        .zip(&pair.partner)
        .zip(predicted)
        .filter_map(|((p, j), r)| {
            let a = after.points[(*j)?].distance;
            Some((ids.contains(&p.region), p.distance, a, *r))
        })
        .filter(|(_, d, a, _)| d.is_finite() && a.is_finite())
        .collect();
    let rows: Vec<(f64, f64, f64)> = all
        .iter()
        .filter(|x| x.0)
        .map(|x| (x.1, x.2, x.3))
        .collect();
    let lowest_ground_mm = all
        .iter()
        .filter(|x| x.0 || x.3 > 0.0)
        .map(|x| x.2)
        .fold(f64::INFINITY, f64::min);
    let rms = |f: &dyn Fn(&(f64, f64, f64)) -> f64| {
        (rows.iter().map(|x| f(x).powi(2)).sum::<f64>() / rows.len() as f64).sqrt()
    };
    let s = scale.unwrap_or(1.0);
    (!rows.is_empty()).then(|| Agreement {
        points: rows.len(),
        predicted_plan_k_mm: rms(&|(d, _, r)| d - r),
        predicted_fitted_k_mm: scale.map(|s| rms(&|(d, _, r)| d - r * s)),
        achieved_mm: rms(&|(_, a, _)| *a),
        difference_mm: rms(&|(d, a, r)| a - (d - r * s)),
        lowest_ground_mm,
    })
}

/// Ids of the repairable regions of `inspection` (as deviations.csv's `region` column).
pub fn repairable_ids(inspection: &Inspection) -> Vec<i64> {
    inspection
        .regions
        .iter()
        .filter(|r| r.repairable)
        .map(|r| r.id as i64)
        .collect()
}

/// Reads predicted.csv's text (`x,y,z,deviation,predicted_residual,spread_p95`); the error
/// names the line and the column.
pub fn parse_predicted(text: &str) -> Result<Vec<PredictedRow>, String> {
    let mut lines = text.lines().enumerate();
    let head = lines.next().map(|(_, l)| l).unwrap_or_default();
    if !head.starts_with("x,y,z,deviation,predicted_residual") {
        return Err(format!(
            "line 1: header {head:?}, expected x,y,z,deviation,predicted_residual,..."
        ));
    }
    let mut rows = Vec::new();
    for (n, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let cells: Vec<&str> = line.split(',').collect();
        let mut v = [0.0; 5];
        for (c, slot) in v.iter_mut().enumerate() {
            *slot = cells
                .get(c)
                .and_then(|s| s.trim().parse::<f64>().ok())
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("line {}: column {}: not a finite number", n + 1, c + 1))?;
        }
        rows.push(PredictedRow {
            position: [v[0], v[1], v[2]],
            deviation: v[3],
            residual: v[4],
            spread_p95: 0.0,
        });
    }
    Ok(rows)
}

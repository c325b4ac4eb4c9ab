//! The loop's removal ledger (issue 50, "a loop that never gouges"): per core point of the
//! first inspection, its first reading and the removal the grinds since were predicted to make
//! within [`LEDGER_REACH_MM`] of it (the largest such prediction each grind, moved to where the
//! grind's removal was measured to land and scaled by the k fitted after it). From the loop's
//! `ledger_from_grind` on (`cycle::LEDGER_FROM_GRIND`, 4) the planner reads each core point
//! at the lower of its rescan's reading and the ledger's (first reading less the removal
//! entered), so that a spot the rescans read higher than what the grinds took off it is not
//! ground again on that reading.
//!
//! Why: a rescan reads a ground spot as the mean over its comparison cylinder (1.3-3.7 mm
//! across where the noise asks, 0.6 mm with `--footprint-radius`), and a grind leaves dips
//! narrower than that. Run for 8 grinds (30-run survey, documented arm, main 175a683), the
//! loop took 10 of 30 runs below the tolerance, each through small losses over grinds 4-8 at
//! points the rescans read 0.04-0.15 mm above their truth (case 61 cell 30: true 0.082 /
//! -0.030 mm read 0.202 / 0.119 mm after grinds 3 / 6), while the first reading, made before
//! any grind on a smooth part, was within 0.02 mm of the truth at 8 of 9 of those points.
//! docs/ALGORITHMS.md, "The removal ledger".
use nalgebra::{Point3, Vector3};

use crate::repair::Inspection;
use crate::spatial::Neighbours;

/// Largest distance between a core point and the ledger point it is read from, mm (0.3: about
/// the reference sample's core spacing, 0.28 mm median; the inspections share the reference's
/// core points to the last bit, and a point one inspection densified around a defect takes
/// its nearest sampled neighbour's entry, whose predicted removal differs by a fraction of the
/// 1.2 mm patch's).
pub const LEDGER_POINT_MM: f64 = 0.3;

/// Distance within which a grind's predicted removal is entered at a ledger point, the
/// largest of them, mm (1.0): where the removal really lands. Replayed on the simulated ideal
/// arm (survey case 21, cell 30, grind 3), the patch's centre lay 0.20 / 0.40 / 0.62 mm
/// (median / p90 / p99) from the planned landing of the same joint angles; the 8-grind survey's
/// gouged points had lost 1.5-8 times what the plan predicted at the point itself (case 81,
/// cell 29, ideal arm: 0.279 mm against 0.036 mm over 5 grinds).
pub const LEDGER_REACH_MM: f64 = 1.0;

/// Least cosine between the normals of a core point and the ledger point it is read from
/// (0.9, 26 degrees): across a thin wall or an edge the nearest point measures another surface.
const LEDGER_NORMAL_COS: f64 = 0.9;

/// Per core point of the loop's first inspection: where it is, its first reading and the
/// removal the grinds since were predicted to make there.
#[derive(Debug)]
pub struct Ledger {
    /// The first inspection's core points.
    index: Neighbours,
    /// Their normals.
    normals: Vec<Vector3<f64>>,
    /// Their distances as the first plan read them, mm (NaN: not measured).
    start: Vec<f64>,
    /// Removal entered so far, mm.
    removed: Vec<f64>,
}

/// What [`Ledger::bound`] changed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Bounded {
    /// Core points read at the ledger's value.
    pub points: usize,
    /// The largest difference between a reading and the ledger's value, mm.
    pub most_mm: f64,
}

impl Ledger {
    /// Opens the ledger on the first inspection the loop planned from (`first`, the planner's
    /// view of it: `cycle::planner_input`).
    pub fn open(first: &Inspection) -> Ledger {
        let positions: Vec<Point3<f64>> = first.points.iter().map(|p| p.position).collect();
        Ledger {
            index: Neighbours::new(&positions),
            normals: first.points.iter().map(|p| p.normal).collect(),
            start: first.points.iter().map(|p| p.distance).collect(),
            removed: vec![0.0; positions.len()],
        }
    }

    /// The ledger point core point `p` (normal `n`) is read from, if any.
    fn entry(&self, p: &Point3<f64>, n: &Vector3<f64>) -> Option<usize> {
        let nb = self.index.nearest(p)?;
        let near = nb.dist2 <= LEDGER_POINT_MM * LEDGER_POINT_MM;
        (near && self.normals[nb.index].dot(n) >= LEDGER_NORMAL_COS).then_some(nb.index)
    }

    /// Enters a grind: `predicted` is its removal per core point of `before` (the inspection
    /// its plan was made from), mm, entered times `scale` (the k fitted after it over the k
    /// the plan was made with). A ledger point takes the largest prediction among the core
    /// points of `before` within [`LEDGER_REACH_MM`] of it that face its way: where the
    /// removal really lands within that distance of where it was predicted, the entry is at
    /// least what the point lost.
    pub fn enter(&mut self, before: &Inspection, predicted: &[f64], scale: f64) {
        let ground: Vec<usize> = (0..before.points.len())
            .filter(|&i| predicted.get(i).is_some_and(|r| r.is_finite() && *r > 0.0))
            .collect();
        let positions: Vec<Point3<f64>> =
            ground.iter().map(|&i| before.points[i].position).collect();
        let index = Neighbours::new(&positions);
        for (j, removed) in self.removed.iter_mut().enumerate() {
            let p = self.index.point(j);
            let most = index
                .within_unsorted(&p, LEDGER_REACH_MM)
                .iter()
                .map(|nb| ground[nb.index])
                .filter(|&i| before.points[i].normal.dot(&self.normals[j]) >= LEDGER_NORMAL_COS)
                .map(|i| predicted[i])
                .fold(0.0, f64::max);
            *removed += scale * most;
        }
    }

    /// `inspection` as the planner reads it: each core point's distance lowered to its ledger
    /// point's first reading less the removal entered, where that is lower; and how many points
    /// that moved, by how much at most. The rim guard takes a lowered value below nominal as
    /// it takes a reading there (`motion::dwell::rim_budget`: the loss a comparison under-reads
    /// scaled up), which can only hold a conform point's budget lower.
    pub fn bound(&self, mut inspection: Inspection) -> (Inspection, Bounded) {
        let mut done = Bounded::default();
        for p in inspection.points.iter_mut() {
            let Some(j) = self.entry(&p.position, &p.normal) else {
                continue;
            };
            let left = self.start[j] - self.removed[j];
            if self.removed[j] > 0.0 && left.is_finite() && left < p.distance {
                done.points += 1;
                done.most_mm = done.most_mm.max(p.distance - left);
                p.distance = left;
            }
        }
        (inspection, done)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::repair::SurfacePoint;

    fn inspection(distances: &[f64]) -> Inspection {
        let points = distances
            .iter()
            .enumerate()
            .map(|(i, &d)| SurfacePoint {
                position: Point3::new([0.0, 0.5, 3.0][i], 0.0, 0.0),
                normal: Vector3::z(),
                distance: d,
                uncertainty: 0.01,
                region: 0,
            })
            .collect();
        Inspection {
            dir: "iter-1/inspection".into(),
            tolerance: Some(0.05),
            regions: Vec::new(),
            points,
            fine: Vec::new(),
        }
    }

    /// Two grinds predicted to take 0.1 and 0.05 mm (the second's k fitted 1.2 x its plan's)
    /// off a point first read at 0.2 mm leave 0.04 mm on the ledger: a rescan reading 0.12 mm
    /// there is planned at 0.04 mm; its neighbour 0.5 mm away, predicted to lose nothing in
    /// grind 1, is entered the same (the largest prediction within reach) and keeps its reading
    /// of 0.01 mm; a point 3 mm away that no grind was predicted to touch keeps its reading
    /// whatever the first one was; a point facing another way takes no entry.
    #[test]
    fn a_point_read_above_what_the_grinds_left_is_planned_at_the_ledgers_value() {
        let first = inspection(&[0.2, 0.2, 0.3]);
        let mut ledger = Ledger::open(&first);
        ledger.enter(&first, &[0.1, 0.0, 0.0], 1.0);
        ledger.enter(&inspection(&[0.1, 0.1, 0.3]), &[0.05, 0.05, 0.0], 1.2);
        let (read, done) = ledger.bound(inspection(&[0.12, 0.01, 0.5]));
        let d: Vec<f64> = read.points.iter().map(|p| p.distance).collect();
        assert!((d[0] - 0.04).abs() < 1e-12, "{d:?}");
        assert_eq!(d[1..], [0.01, 0.5]);
        assert_eq!(done.points, 1);
        assert!((done.most_mm - 0.08).abs() < 1e-12, "{done:?}");
        let mut turned = inspection(&[0.12, 0.12, 0.12]);
        turned.points[0].normal = Vector3::x();
        let (read, done) = ledger.bound(turned);
        assert_eq!(read.points[0].distance, 0.12);
        assert!((read.points[1].distance - 0.04).abs() < 1e-12);
        assert_eq!(done.points, 1);
    }
}

//! The true (noise-free) part of an acceptance case through the loop's grinds: synth's
//! planted deviation less the simulator's removal summed so far (`TruePart`), and what the
//! issue's acceptance reads from it (`TrueState`); used by [`super::accept`].
use std::path::Path;

use nalgebra::{Point3, Vector3};
use polishbot::spatial::Neighbours;
use polishbot::synth::Truth;

use super::accept::TOLERANCE_MM;

/// The true (noise-free) part at one moment of the loop: synth's planted deviation less the
/// simulator's removal summed so far, over the truth file's points.
#[derive(Debug, Clone, Copy, Default)]
pub struct TrueState {
    /// Points of the reachable repairable area: truly above the tolerance before the first
    /// grind, away from the pits, and reachable square to the reference surface (the reach
    /// test of `Inspected::open`).
    pub area: usize,
    /// Of them, within +-tolerance, above it, below it.
    pub within: usize,
    /// See `within`.
    pub above: usize,
    /// See `within`.
    pub below: usize,
    /// Of those above, the ones with no point any grind removed from within
    /// [`UNTOUCHED_MM`]: the plan never ground there.
    pub untouched: usize,
    /// True volume above the tolerance away from the pits, mm^3 (each point's share of the
    /// surface from the truth points within [`PATCH_MM`]).
    pub volume: f64,
}

impl TrueState {
    /// Share of the reachable repairable area within +-tolerance (1 when it is empty).
    pub fn share(&self) -> f64 {
        match self.area {
            0 => 1.0,
            n => self.within as f64 / n as f64,
        }
    }
}

/// A point of the area above the tolerance counts as never ground when no point some grind
/// removed from lies this near, mm (1.0: under the 1.2 mm patch, over the 0.3 mm point
/// spacing).
pub const UNTOUCHED_MM: f64 = 1.0;
/// Radius over which a truth point's share of the surface is counted, mm (1.0: tens of
/// points at the scans' 0.3 mm spacing, under a defect's 2-4 mm width).
pub const PATCH_MM: f64 = 1.0;

/// Farthest a point's place before a grind, found from its place after it (moved back along
/// its normal by its removal), lies from where the previous truth file has it, mm (0.1: the
/// normal turns by up to 10 degrees over a grind's 0.25 mm, 0.04 mm off; the points lie
/// 0.3 mm apart).
const MATCH_MM: f64 = 0.1;
/// More of that distance per mm removed at the point (0.35, sin 20 degrees): a cut far below
/// the planned depth (issue 50: 0.4-0.6 mm with 1 degree of backlash) turns the normal by up to
/// 20 degrees, so its point lies farther off than 0.1 mm and the walk ran off the end.
const MATCH_PER_MM_REMOVED: f64 = 0.35;

/// The true part through the grinds without the scan's noise: the deviation synth planted at
/// each point of the simulated part (its truth files keep their points in order from grind to
/// grind) less the removal the simulator summed there over the grinds so far. The truth
/// files' own points carry the first scan's 0.015 mm noise (the first grind's part is that
/// scan), which on single points reads as -0.06..-0.08 mm where the ground surface averages
/// -0.01..-0.05 within 0.5 mm.
#[derive(Default)]
pub struct TruePart {
    points: Vec<Point3<f64>>,
    planted: Vec<f64>,
    removed: Vec<f64>,
    /// Each grind's removal at the point, in order, mm.
    by_grind: Vec<Vec<f64>>,
    /// Whether the point is in the reachable repairable area (see [`TrueState`]).
    area: Vec<bool>,
    /// The point's share of the surface, mm^2 (0 where the planted deviation is within the
    /// tolerance: only the volume above it is summed).
    patch: Vec<f64>,
}

/// Whether a point (reference frame, with the reference surface's normal there) can be in the
/// reachable repairable area.
pub type AreaTest<'a> = &'a (dyn Fn(&Point3<f64>, &Vector3<f64>) -> bool + Sync);

impl TruePart {
    /// Adds grind `k`'s removal (its truth file); on the first, the points of the reachable
    /// repairable area are those above the tolerance that `in_area` accepts.
    pub fn grind(&mut self, dir: &Path, truth: &Truth, k: usize, in_area: AreaTest) {
        use rayon::prelude::*;
        let file = dir.join(format!("cycle/iter-{k}/after_truth.ply"));
        let after = polishbot::cloud::load_cloud(&file, None, None).unwrap();
        let removal = after.field("removal").unwrap();
        if self.planted.is_empty() {
            let reference =
                polishbot::cloud::load_cloud(&dir.join("reference.ply"), None, None).unwrap();
            let (index, normals) = (
                Neighbours::new(&reference.points),
                reference.normals.unwrap(),
            );
            let normal = |p: &Point3<f64>| normals[index.nearest(p).unwrap().index];
            self.planted = after
                .points
                .iter()
                .map(|p| truth.deviation_at(p, &normal(p)))
                .collect();
            self.removed = vec![0.0; after.len()];
            self.by_grind = vec![Vec::new(); after.len()];
            let own = Neighbours::new(&after.points);
            let excess = |i: usize| self.planted[i] > TOLERANCE_MM;
            self.area = (0..after.len())
                .into_par_iter()
                .map(|i| excess(i) && in_area(&after.points[i], &normal(&after.points[i])))
                .collect();
            let disc = std::f64::consts::PI * PATCH_MM * PATCH_MM;
            self.patch = (0..after.len())
                .map(|i| match excess(i) {
                    true => disc / own.within(&after.points[i], PATCH_MM).len() as f64,
                    false => 0.0,
                })
                .collect();
        } else {
            self.follow(&after.points, after.normals.as_ref().unwrap(), removal, k);
        }
        for (total, r) in self.removed.iter_mut().zip(removal) {
            *total += r;
        }
        for (each, r) in self.by_grind.iter_mut().zip(removal) {
            each.push(*r);
        }
        self.points = after.points;
    }

    /// The points some grind removed from, where they are now (reference frame).
    pub fn ground(&self) -> Vec<Point3<f64>> {
        (0..self.points.len())
            .filter(|&i| self.removed[i] > 0.0)
            .map(|i| self.points[i])
            .collect()
    }

    /// The most removed so far at a point `inside` accepts, mm (0 where none).
    pub fn most_removed(&self, inside: &dyn Fn(&Point3<f64>) -> bool) -> f64 {
        (0..self.points.len())
            .filter(|&i| inside(&self.points[i]))
            .map(|i| self.removed[i])
            .fold(0.0, f64::max)
    }

    /// Keeps, in order, the points of the last grind that grind `k`'s part kept (`points`, the
    /// truth file's, each moved `removal` along its `normals` from where it was: the simulator
    /// drops the points off the inspected surface before each grind and never reorders them).
    fn follow(
        &mut self,
        points: &[Point3<f64>],
        normals: &[Vector3<f64>],
        removal: &[f64],
        k: usize,
    ) {
        let mut at = 0;
        let mut kept = Vec::with_capacity(points.len());
        for ((p, n), r) in points.iter().zip(normals).zip(removal) {
            let before = p + n * *r;
            loop {
                let earlier = self.points.get(at);
                let earlier =
                    earlier.unwrap_or_else(|| panic!("grind {k}: a point of no earlier grind"));
                if (earlier - before).norm() <= MATCH_MM + MATCH_PER_MM_REMOVED * r.abs() {
                    break;
                }
                at += 1;
            }
            kept.push(at);
            at += 1;
        }
        self.planted = kept.iter().map(|&i| self.planted[i]).collect();
        self.removed = kept.iter().map(|&i| self.removed[i]).collect();
        self.by_grind = kept.iter().map(|&i| self.by_grind[i].clone()).collect();
        self.area = kept.iter().map(|&i| self.area[i]).collect();
        self.patch = kept.iter().map(|&i| self.patch[i]).collect();
    }

    /// The true part now (`ground`) or before the first grind, over the reachable repairable
    /// area, and its volume above the tolerance.
    pub fn state(&self, ground: bool) -> TrueState {
        let dev = |i: usize| self.planted[i] - if ground { self.removed[i] } else { 0.0 };
        let touched = self.ground();
        let touched = (ground && !touched.is_empty()).then(|| Neighbours::new(&touched));
        let mut s = TrueState::default();
        for i in (0..self.points.len()).filter(|&i| self.area[i]) {
            s.area += 1;
            match dev(i) {
                d if d > TOLERANCE_MM => {
                    s.above += 1;
                    let near = touched
                        .as_ref()
                        .is_some_and(|t| !t.within(&self.points[i], UNTOUCHED_MM).is_empty());
                    s.untouched += usize::from(!near);
                }
                d if d < -TOLERANCE_MM => s.below += 1,
                _ => s.within += 1,
            }
        }
        s.volume = (0..self.points.len())
            .map(|i| self.patch[i] * (dev(i) - TOLERANCE_MM).max(0.0))
            .sum();
        s
    }

    /// The ground points `keep` accepts whose true deviation lies below `limit`: where they
    /// are, the deviation synth planted there and each grind's removal, mm (to take a gouge
    /// apart by hand).
    pub fn below(
        &self,
        keep: &dyn Fn(&Point3<f64>) -> bool,
        limit: f64,
    ) -> Vec<(Point3<f64>, f64, Vec<f64>)> {
        (0..self.points.len())
            .filter(|&i| self.removed[i] > 0.0 && keep(&self.points[i]))
            .filter(|&i| self.planted[i] - self.removed[i] < limit)
            .map(|i| (self.points[i], self.planted[i], self.by_grind[i].clone()))
            .collect()
    }

    /// The lowest true deviation at a point ground so far, and how many ground points lie
    /// below the tolerance of how many, over the points `keep` accepts, mm.
    pub fn lowest_ground(&self, keep: &dyn Fn(&Point3<f64>) -> bool) -> (f64, usize, usize) {
        let ground: Vec<f64> = (0..self.removed.len())
            .filter(|&i| self.removed[i] > 0.0 && keep(&self.points[i]))
            .map(|i| self.planted[i] - self.removed[i])
            .collect();
        let below = ground.iter().filter(|d| **d < -TOLERANCE_MM).count();
        let lowest = ground.iter().copied().fold(f64::INFINITY, f64::min);
        (lowest, below, ground.len())
    }
}

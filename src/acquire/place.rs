//! Placing the views one by one against the growing model (every placed view that overlaps
//! the new one), with each correction bounded by the table's stated accuracy.
use anyhow::{bail, Result};
use nalgebra::Isometry3;
use serde::Serialize;

use super::pair::{coarse_pair, overlap, pair_icp, union, Prepared};
use super::MergeConfig;
use crate::cloud::transform::pose_difference;
use crate::cloud::PointCloud;

/// Share of a new view's sample points within the middle ICP distance of a placed view (at the
/// predicted pose) for that view to join the model the new one is aligned against. Low: the
/// bunny's 90 degree neighbours share 20-35 % of their points, a 45 degree error halves that.
const MIN_MODEL_OVERLAP: f64 = 0.05;

/// Every how many sample points the overlap test uses (it only needs a share, not a fit).
const OVERLAP_EVERY: usize = 8;

/// How many overlapping placed views (nearest in angle first) coarse registration is tried
/// against when ICP gives no match within the bound (each costs a full `register()`).
const COARSE_TRIES: usize = 2;

/// Largest union a new view is aligned against, in multiples of `icp_target_points`.
const MODEL_TARGETS: usize = 2;

/// How a view's pose was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Placement {
    /// The first view: it defines the frame.
    First,
    /// ICP onto the model from the predicted pose fitted within the bound.
    Aligned,
    /// A first match was rejected (beyond the bound) or did not fit; ICP from the nominal pose
    /// or coarse registration then fitted within the bound.
    Realigned,
    /// No match fitted within the bound: the view is kept at its predicted pose refined by a
    /// short-range ICP (or unrefined when that too leaves the bound).
    Held,
}

/// A match rejected because its correction exceeds the angle tolerance.
#[derive(Debug, Clone, Serialize)]
pub struct Rejected {
    /// Where it started: "predicted", "nominal" or "coarse onto NAME".
    pub start: String,
    /// Its rotation against the nominal pose, degrees.
    pub correction_deg: f64,
    /// Its fitness onto the model.
    pub fitness: f64,
}

/// A placed view.
pub(super) struct Placed {
    /// Index into the input views.
    pub index: usize,
    /// View-to-first pose.
    pub pose: Isometry3<f64>,
    /// Fitness onto the model it was aligned against.
    pub fitness: f64,
    /// Coarse registration gave the accepted start.
    pub coarse: bool,
    /// How the pose was found.
    pub placement: Placement,
    /// Matches rejected on the way.
    pub rejected: Vec<Rejected>,
    /// The placed views (input indices) it was aligned against.
    pub model: Vec<usize>,
}

/// The inputs of [`place_views`].
pub(super) struct Inputs<'a> {
    pub views: &'a [PointCloud],
    pub prepared: &'a [Prepared],
    pub names: &'a [String],
    pub angles: &'a [f64],
    pub nominal: &'a [Isometry3<f64>],
}

/// Result of [`place_views`].
pub(super) struct Placements {
    /// Placed views in input order.
    pub placed: Vec<Placed>,
    /// Names of skipped views.
    pub skipped: Vec<String>,
}

/// Angle between two table angles, degrees in [0, 180].
fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// Places every view after the first against the placed views it overlaps.
pub(super) fn place_views(inp: &Inputs, cfg: &MergeConfig) -> Result<Placements> {
    let mut placed = vec![Placed {
        index: 0,
        pose: Isometry3::identity(),
        fitness: 1.0,
        coarse: false,
        placement: Placement::First,
        rejected: Vec::new(),
        model: Vec::new(),
    }];
    let mut skipped = Vec::new();
    for i in 1..inp.views.len() {
        match place_one(inp, &placed, i, cfg) {
            Some(p) => placed.push(p),
            None if cfg.skip_bad => skipped.push(inp.names[i].clone()),
            None => {
                let j = nearest_placed(inp, &placed, i);
                bail!(
                    "{}: cannot be aligned to {} (ICP from the nominal angle {} deg and coarse \
                     alignment both fit below {}); use --skip-bad to leave it out",
                    inp.names[i],
                    inp.names[placed[j].index],
                    inp.angles[i],
                    cfg.min_fitness
                )
            }
        }
    }
    Ok(Placements { placed, skipped })
}

/// Position in `placed` of the placed view nearest to view `i` in nominal angle (held views,
/// whose pose is not a match, neither predict nor join a model).
fn nearest_placed(inp: &Inputs, placed: &[Placed], i: usize) -> usize {
    (0..placed.len())
        .filter(|&k| placed[k].placement != Placement::Held)
        .min_by(|&a, &b| {
            let ga = angle_gap(inp.angles[placed[a].index], inp.angles[i]);
            let gb = angle_gap(inp.angles[placed[b].index], inp.angles[i]);
            ga.total_cmp(&gb)
        })
        .expect("the first view is placed")
}

/// The matches tried for one view: those beyond the bound are kept for the report.
struct Trials<'a> {
    src: &'a Prepared,
    model: &'a Prepared,
    nominal: Isometry3<f64>,
    cfg: &'a MergeConfig,
    rejected: Vec<Rejected>,
    any_fit: bool,
}

impl Trials<'_> {
    /// ICP onto the model from `start` (short range only with `short`): the pose and fitness
    /// when it fits within the bound; recorded as rejected when it fits beyond it.
    fn try_start(
        &mut self,
        name: &str,
        start: &Isometry3<f64>,
        short: bool,
    ) -> Option<(Isometry3<f64>, f64)> {
        let (pose, f) = pair_icp(self.src, self.model, start, self.cfg, short);
        if f < self.cfg.min_fitness {
            return None;
        }
        self.any_fit = true;
        let correction = pose_difference(&self.nominal, &pose).0;
        if correction <= self.cfg.angle_tolerance {
            return Some((pose, f));
        }
        self.rejected.push(Rejected {
            start: name.to_string(),
            correction_deg: correction,
            fitness: f,
        });
        None
    }
}

/// Positions in `placed` of the placed views that overlap view `i` at `predicted`, nearest in
/// angle first (the nearest placed view alone when none does).
fn model_members(
    inp: &Inputs,
    placed: &[Placed],
    i: usize,
    predicted: &Isometry3<f64>,
    cfg: &MergeConfig,
) -> Vec<usize> {
    let mid = 0.5 * (cfg.start_distance + cfg.final_distance);
    let src = &inp.prepared[i];
    let mut members: Vec<usize> = (0..placed.len())
        .filter(|&k| {
            let p = &placed[k];
            if p.placement == Placement::Held {
                return false;
            }
            let rel = p.pose.inverse() * predicted;
            overlap(src, &inp.prepared[p.index], &rel, mid, OVERLAP_EVERY) >= MIN_MODEL_OVERLAP
        })
        .collect();
    if members.is_empty() {
        members.push(nearest_placed(inp, placed, i));
    }
    let gap = |k: usize| angle_gap(inp.angles[placed[k].index], inp.angles[i]);
    members.sort_by(|&a, &b| gap(a).total_cmp(&gap(b)));
    members
}

/// Places view `i`: ICP onto the model from the predicted pose, then from the nominal one, then
/// from coarse registrations onto the nearest members; the first fit within the bound counts.
/// None when no match fits at all.
fn place_one(inp: &Inputs, placed: &[Placed], i: usize, cfg: &MergeConfig) -> Option<Placed> {
    let nominal = inp.nominal[i];
    // The nearest placed view carries its correction over to the new one.
    let near = &placed[nearest_placed(inp, placed, i)];
    let predicted = near.pose * inp.nominal[near.index].inverse() * nominal;
    let members = model_members(inp, placed, i, &predicted, cfg);
    let parts: Vec<(&Prepared, Isometry3<f64>)> = members
        .iter()
        .map(|&k| (&inp.prepared[placed[k].index], placed[k].pose))
        .collect();
    let model = union(&parts, MODEL_TARGETS * cfg.icp_target_points);
    let mut trials = Trials {
        src: &inp.prepared[i],
        model: &model,
        nominal,
        cfg,
        rejected: Vec::new(),
        any_fit: false,
    };
    let make = |pose, fitness, coarse, placement, rejected| Placed {
        index: i,
        pose,
        fitness,
        coarse,
        placement,
        rejected,
        model: members.iter().map(|&k| placed[k].index).collect(),
    };
    let mut starts = vec![("predicted", predicted)];
    if pose_difference(&predicted, &nominal).0 > 1e-9 {
        starts.push(("nominal", nominal));
    }
    for (n, (name, start)) in starts.iter().enumerate() {
        if let Some((pose, f)) = trials.try_start(name, start, false) {
            let how = if n == 0 && trials.rejected.is_empty() {
                Placement::Aligned
            } else {
                Placement::Realigned
            };
            return Some(make(pose, f, false, how, trials.rejected));
        }
    }
    for &m in members.iter().take(COARSE_TRIES) {
        let j = placed[m].index;
        let Some((rel, _)) = coarse_pair(inp.views, inp.prepared, (i, j), cfg) else {
            continue;
        };
        let name = format!("coarse onto {}", inp.names[j]);
        if let Some((pose, f)) = trials.try_start(&name, &(placed[m].pose * rel), true) {
            return Some(make(pose, f, true, Placement::Realigned, trials.rejected));
        }
    }
    if !trials.any_fit {
        return None;
    }
    // Held: the predicted pose refined by a short-range ICP, or unrefined beyond the bound.
    let (pose, f) = pair_icp(trials.src, &model, &predicted, cfg, true);
    let (pose, f) = if pose_difference(&nominal, &pose).0 <= cfg.angle_tolerance {
        (pose, f)
    } else {
        (
            predicted,
            overlap(trials.src, &model, &predicted, cfg.final_distance, 1),
        )
    };
    Some(make(pose, f, false, Placement::Held, trials.rejected))
}

/// True when the views make a full turn: the next step after the last view reaches 360.
fn full_turn(angles: &[f64]) -> bool {
    let n = angles.len();
    if n < 3 {
        return false;
    }
    let step = (angles[n - 1] - angles[0]) / (n - 1) as f64;
    let next = angles[n - 1] + step - angles[0];
    (next.abs() - 360.0).abs() < 0.5 * step.abs()
}

/// Loop closure of a full turn whose last view was placed: the last view aligned directly onto
/// the first from its placed pose, against that pose (rotation deg, translation mm). None
/// without a full turn, or when the direct match does not fit or is half a step or more off
/// (a wrong match, not drift). A diagnostic: the global step closes the loop.
pub(super) fn loop_closure(inp: &Inputs, placed: &[Placed], cfg: &MergeConfig) -> Option<[f64; 2]> {
    let last = placed.last()?;
    let n = inp.angles.len();
    if !full_turn(inp.angles) || placed.len() < 3 || last.index != n - 1 {
        return None;
    }
    let half_step = 0.5 * (inp.angles[n - 1] - inp.angles[0]).abs() / (n - 1) as f64;
    let (rel, f) = pair_icp(
        &inp.prepared[last.index],
        &inp.prepared[0],
        &last.pose,
        cfg,
        false,
    );
    let e = rel * last.pose.inverse();
    let deg = e.rotation.angle().to_degrees();
    (f >= cfg.min_fitness && deg < half_step).then_some([deg, e.translation.vector.norm()])
}

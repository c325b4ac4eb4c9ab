//! Placing the views one by one against the growing model (every placed view that overlaps
//! the new one), with each correction bounded by the table's stated accuracy.
use anyhow::{bail, Result};
use nalgebra::{Isometry3, Unit, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use super::config::MergeConfig;
use super::pair::{coarse_pair, overlap, pair_icp, union, Prepared};
use crate::cloud::transform::pose_difference;
use crate::cloud::PointCloud;

/// Share of a new view's sample points within the final ICP distance of a placed view (once
/// pulled in) for that view to join the model the new one is refined against. Low: the
/// bunny's 90 degree neighbours share 20-35 % of their points, opposite views a few percent
/// along their rims.
const MIN_MODEL_OVERLAP: f64 = 0.05;

/// Every how many sample points the overlap test uses (it only needs a share, not a fit).
const OVERLAP_EVERY: usize = 8;

/// How many placed views (nearest in angle first) coarse registration is tried against when ICP
/// gives no match within the bound (each costs a full `register()`).
const COARSE_TRIES: usize = 2;

/// Largest union a new view is aligned against, in multiples of `icp_target_points`.
const MODEL_TARGETS: usize = 4;

/// Most placed views in the model, nearest in angle first: with all 35 earlier views of a
/// 36-view turn (each thinned 15-fold) the poses drifted by 0.01 degrees at view 16 and 30 at
/// view 32; the four nearest overlapping views hold the bunny's 45-90 degree neighbours.
const MAX_MODEL_VIEWS: usize = 4;

/// How many tolerances the table's corrections may span. The tolerance is the table's
/// accuracy a: each true angle is within a of its nominal one, the first view's too. A pose is
/// a view's turn against the first view, so its correction carries both errors and reaches 2a
/// (the synthetic table, angles within 3 degrees, corrects view 7 of seed 3 by 5.12 degrees),
/// and all corrections about the axis (the first view's 0 among them) lie in one window 2a
/// wide: a set of true angles within a exists exactly when they do.
const SPAN_TOLERANCES: f64 = 2.0;

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
    /// The span of the accepted views' corrections about the table axis (the first view's 0
    /// among them) with this one added, degrees.
    pub span_deg: f64,
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
    /// Its signed correction about the table axis, degrees (0 for the first view).
    pub turn: f64,
}

/// The inputs of [`place_views`].
pub(super) struct Inputs<'a> {
    /// The views, as read.
    pub views: &'a [PointCloud],
    /// Each view prepared as an ICP target and as a source.
    pub prepared: &'a [Prepared],
    /// Each view's name, for messages.
    pub names: &'a [String],
    /// Each view's nominal table angle, degrees.
    pub angles: &'a [f64],
    /// Each view's nominal pose: the table turned back by its angle from the first view's,
    /// about the axis and centre.
    pub nominal: &'a [Isometry3<f64>],
    /// The table axis (first view's frame).
    pub axis: &'a Unit<Vector3<f64>>,
    /// Pulls computed ahead ([`nominal_pulls`]).
    pub pulls: Vec<Pull>,
}

/// A pull computed ahead: view `pair.0` pulled onto view `pair.1` by the full ICP from
/// `start` (their nominal relative pose), with its result (relative pose, fitness).
pub(super) struct Pull {
    pair: (usize, usize),
    start: Isometry3<f64>,
    result: (Isometry3<f64>, f64),
}

/// The pulls placing and the loop closure will ask for when every view fits at its first
/// try: each view from its nominal pose onto the nearest earlier view in angle (the first on
/// ties, as [`nearest_placed`] picks), and on a full turn the last view onto its predecessor.
/// They depend on the two views and their nominal angles only, not on the placed poses, so
/// they run side by side (one pull leaves a core idle most of the time) and give the same
/// poses as one after the other. A pull that is not asked for (a held or skipped view
/// changes the nearest placed one) is wasted work, not a different answer: [`pull`] matches
/// the pair and the start exactly.
pub(super) fn nominal_pulls(inp: &Inputs, cfg: &MergeConfig) -> Vec<Pull> {
    let n = inp.views.len();
    let mut pairs: Vec<(usize, usize)> = (1..n)
        .map(|i| {
            let j = (0..i)
                .min_by(|&a, &b| {
                    let gap = |k: usize| angle_gap(inp.angles[k], inp.angles[i]);
                    gap(a).total_cmp(&gap(b))
                })
                .expect("view 0 is earlier");
            (i, j)
        })
        .collect();
    if full_turn(inp.angles) && !pairs.contains(&(n - 1, n - 2)) {
        pairs.push((n - 1, n - 2));
    }
    pairs
        .into_par_iter()
        .map(|(i, j)| {
            let start = inp.nominal[j].inverse() * inp.nominal[i];
            let result = pair_icp(&inp.prepared[i], &inp.prepared[j], &start, cfg, false);
            Pull {
                pair: (i, j),
                start,
                result,
            }
        })
        .collect()
}

/// View `i` pulled onto view `j` by the full ICP from `start`: computed ahead when it was
/// among [`nominal_pulls`], else now.
fn pull(
    inp: &Inputs,
    (i, j): (usize, usize),
    start: &Isometry3<f64>,
    cfg: &MergeConfig,
) -> (Isometry3<f64>, f64) {
    match inp
        .pulls
        .iter()
        .find(|p| p.pair == (i, j) && p.start == *start)
    {
        Some(p) => p.result,
        None => pair_icp(&inp.prepared[i], &inp.prepared[j], start, cfg, false),
    }
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

/// Signed correction of view `i` at `pose` about the table axis against its nominal pose,
/// degrees.
fn turn_of(inp: &Inputs, i: usize, pose: &Isometry3<f64>) -> f64 {
    let d = pose.rotation * inp.nominal[i].rotation.inverse();
    d.scaled_axis().dot(inp.axis).to_degrees()
}

/// The bound check of view `i` at `pose`: its rotation against the nominal pose (degrees),
/// the span of the accepted views' corrections about the axis with it added (degrees), and
/// whether both are within [`SPAN_TOLERANCES`] tolerances.
fn within_bound(
    inp: &Inputs,
    placed: &[Placed],
    i: usize,
    pose: &Isometry3<f64>,
    cfg: &MergeConfig,
) -> (f64, f64, bool) {
    let correction = pose_difference(&inp.nominal[i], pose).0;
    let turn = turn_of(inp, i, pose);
    let accepted = placed.iter().filter(|p| p.placement != Placement::Held);
    let (lo, hi) = accepted.fold((turn, turn), |(lo, hi), p| (lo.min(p.turn), hi.max(p.turn)));
    let span = hi - lo;
    let bound = SPAN_TOLERANCES * cfg.angle_tolerance;
    (correction, span, correction <= bound && span <= bound)
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
        turn: 0.0,
    }];
    let mut skipped = Vec::new();
    for i in 1..inp.views.len() {
        match place_one(inp, &placed, i, cfg) {
            // Held at a pose that fits too little of it: a wrong pose, not a merge (issue 52:
            // a view given twice at another angle merged at fitness 0.04, RMS 5.76 mm).
            Some(p)
                if p.placement == Placement::Held
                    && (p.fitness.is_nan() || p.fitness < cfg.min_fitness) =>
            {
                if !cfg.skip_bad {
                    bail!(
                        "{}: no match within the angle tolerance ({} deg) and at its predicted \
                         pose only {:.3} of its points fit (min_fitness {}): a wrong view or \
                         angle; use --skip-bad to leave it out",
                        inp.names[i],
                        cfg.angle_tolerance,
                        p.fitness,
                        cfg.min_fitness
                    );
                }
                skipped.push(inp.names[i].clone());
            }
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
    inp: &'a Inputs<'a>,
    placed: &'a [Placed],
    /// The view being placed.
    i: usize,
    cfg: &'a MergeConfig,
    rejected: Vec<Rejected>,
    any_fit: bool,
}

/// A match: pose, fitness onto its model, the model's members (positions in `placed`).
type Match = (Isometry3<f64>, f64, Vec<usize>);

impl Trials<'_> {
    /// The match from `start`: pulled in by the full ICP onto the placed view at position
    /// `onto` (`start` then relative to that view, as the chain of main computed it: composing
    /// the placed pose in and out again changed the pull on weakly constrained pairs; None:
    /// `start` is a view-to-first pose already pulled in), then (`model_refine`) refined by a
    /// short-range ICP onto the
    /// union of the placed views it then overlaps. Returned when it fits within the bound;
    /// recorded as rejected when it fits beyond it.
    fn try_start(
        &mut self,
        name: &str,
        start: &Isometry3<f64>,
        onto: Option<usize>,
    ) -> Option<Match> {
        let src = &self.inp.prepared[self.i];
        let (pulled, pull_fit) = match onto {
            Some(k) => {
                let p = &self.placed[k];
                let (rel, f) = pull(self.inp, (self.i, p.index), start, self.cfg);
                (p.pose * rel, Some(f))
            }
            None => (*start, None),
        };
        let members = model_members(self.inp, self.placed, self.i, &pulled, self.cfg);
        // The union is only built when the pull is refined onto it.
        let (pose, f) = match pull_fit {
            Some(f) if !self.cfg.model_refine => (pulled, f),
            _ => {
                let target = model(self.inp, self.placed, &members, self.cfg);
                pair_icp(src, &target, &pulled, self.cfg, true)
            }
        };
        if f < self.cfg.min_fitness {
            return None;
        }
        self.any_fit = true;
        let (correction, span, ok) = within_bound(self.inp, self.placed, self.i, &pose, self.cfg);
        if ok {
            return Some((pose, f, members));
        }
        self.rejected.push(Rejected {
            start: name.to_string(),
            correction_deg: correction,
            span_deg: span,
            fitness: f,
        });
        None
    }
}

/// The union of the placed views at `members` (positions in `placed`) at their poses.
fn model(inp: &Inputs, placed: &[Placed], members: &[usize], cfg: &MergeConfig) -> Prepared {
    let parts: Vec<(&Prepared, Isometry3<f64>)> = members
        .iter()
        .map(|&k| (&inp.prepared[placed[k].index], placed[k].pose))
        .collect();
    union(&parts, MODEL_TARGETS * cfg.icp_target_points)
}

/// Positions in `placed` of the placed views (not held) that view `i` overlaps at `pose`
/// (within the final ICP distance), nearest in angle first, at most [`MAX_MODEL_VIEWS`]; the
/// nearest placed view alone when none does. Candidates are tested nearest first and the test
/// stops at the cap (the overlap tests of all placed views were a sixth of a 36-view merge).
fn model_members(
    inp: &Inputs,
    placed: &[Placed],
    i: usize,
    pose: &Isometry3<f64>,
    cfg: &MergeConfig,
) -> Vec<usize> {
    let src = &inp.prepared[i];
    let gap = |k: usize| angle_gap(inp.angles[placed[k].index], inp.angles[i]);
    let mut candidates: Vec<usize> = (0..placed.len())
        .filter(|&k| placed[k].placement != Placement::Held)
        .collect();
    candidates.sort_by(|&a, &b| gap(a).total_cmp(&gap(b)));
    let mut members: Vec<usize> = candidates
        .into_iter()
        .filter(|&k| {
            let p = &placed[k];
            let rel = p.pose.inverse() * pose;
            overlap(
                src,
                &inp.prepared[p.index],
                &rel,
                cfg.final_distance,
                OVERLAP_EVERY,
            ) >= MIN_MODEL_OVERLAP
        })
        .take(MAX_MODEL_VIEWS)
        .collect();
    if members.is_empty() {
        members.push(nearest_placed(inp, placed, i));
    }
    members
}

/// Places view `i`. Starts, in turn: the predicted pose (the nearest placed view's correction
/// carried over) and the nominal pose, each pulled in by ICP onto the nearest placed view;
/// then coarse registrations onto the nearest placed views. Each is refined against the
/// placed views it overlaps; the first fit within the bound counts. None when no match fits.
fn place_one(inp: &Inputs, placed: &[Placed], i: usize, cfg: &MergeConfig) -> Option<Placed> {
    let nominal = inp.nominal[i];
    let near_k = nearest_placed(inp, placed, i);
    let near = &placed[near_k];
    let predicted = near.pose * inp.nominal[near.index].inverse() * nominal;
    let mut trials = Trials {
        inp,
        placed,
        i,
        cfg,
        rejected: Vec::new(),
        any_fit: false,
    };
    let make = |(pose, fitness, members): Match, coarse, placement, rejected| Placed {
        index: i,
        pose,
        fitness,
        coarse,
        placement,
        rejected,
        model: members.iter().map(|&k: &usize| placed[k].index).collect(),
        turn: turn_of(inp, i, &pose),
    };
    // Starts relative to the nearest placed view.
    let mut starts = vec![("predicted", inp.nominal[near.index].inverse() * nominal)];
    if pose_difference(&predicted, &nominal).0 > 1e-9 {
        starts.push(("nominal", near.pose.inverse() * nominal));
    }
    for (n, (name, start)) in starts.iter().enumerate() {
        if let Some(m) = trials.try_start(name, start, Some(near_k)) {
            let how = if n == 0 && trials.rejected.is_empty() {
                Placement::Aligned
            } else {
                Placement::Realigned
            };
            return Some(make(m, false, how, trials.rejected));
        }
    }
    let mut nearest: Vec<usize> = (0..placed.len())
        .filter(|&k| placed[k].placement != Placement::Held)
        .collect();
    nearest.sort_by(|&a, &b| {
        let gap = |k: usize| angle_gap(inp.angles[placed[k].index], inp.angles[i]);
        gap(a).total_cmp(&gap(b))
    });
    for &k in nearest.iter().take(COARSE_TRIES) {
        let j = placed[k].index;
        let Some((rel, _)) = coarse_pair(inp.views, inp.prepared, (i, j), cfg) else {
            continue;
        };
        let name = format!("coarse onto {}", inp.names[j]);
        if let Some(m) = trials.try_start(&name, &(placed[k].pose * rel), None) {
            return Some(make(m, true, Placement::Realigned, trials.rejected));
        }
    }
    if !trials.any_fit {
        return None;
    }
    // Held: the predicted pose refined by a short-range ICP, or unrefined beyond the bound.
    let members = model_members(inp, placed, i, &predicted, cfg);
    let target = model(inp, placed, &members, cfg);
    let src = &inp.prepared[i];
    let (pose, f) = pair_icp(src, &target, &predicted, cfg, true);
    let held = if within_bound(inp, placed, i, &pose, cfg).2 {
        (pose, f, members)
    } else {
        let f = overlap(src, &target, &predicted, cfg.final_distance, 1);
        (predicted, f, members)
    };
    Some(make(held, false, Placement::Held, trials.rejected))
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

/// Loop closure of a full turn whose last two views were placed: the last view pulled onto
/// its predecessor (the chain's pose: the placement may have pulled it onto the first view,
/// which would measure the closure against itself) and then aligned directly onto the first
/// from there; the direct pose against the chain's (rotation deg, translation mm). None
/// without a full turn, or when either match does not fit or the direct one is half a step or
/// more off (a wrong match, not drift). A diagnostic: the global step closes the loop.
pub(super) fn loop_closure(inp: &Inputs, placed: &[Placed], cfg: &MergeConfig) -> Option<[f64; 2]> {
    let n = inp.angles.len();
    if !full_turn(inp.angles) || placed.len() < 3 || placed.last()?.index != n - 1 {
        return None;
    }
    let prev = placed
        .iter()
        .find(|p| p.index == n - 2 && p.placement != Placement::Held)?;
    let last = &inp.prepared[n - 1];
    let start = inp.nominal[n - 2].inverse() * inp.nominal[n - 1];
    let (rel, f) = pull(inp, (n - 1, n - 2), &start, cfg);
    if f < cfg.min_fitness {
        return None;
    }
    let chain = prev.pose * rel;
    let half_step = 0.5 * (inp.angles[n - 1] - inp.angles[0]).abs() / (n - 1) as f64;
    let (direct, f) = pair_icp(last, &inp.prepared[0], &chain, cfg, false);
    let e = direct * chain.inverse();
    let deg = e.rotation.angle().to_degrees();
    (f >= cfg.min_fitness && deg < half_step).then_some([deg, e.translation.vector.norm()])
}

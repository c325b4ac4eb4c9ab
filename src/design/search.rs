//! The search: a coarse grid of table axes, part mountings, table places and shanks scored on
//! a few surface samples, the best re-scored on more, then local refinement of the winner.

use nalgebra::{Rotation3, Unit, Vector3};
use rayon::prelude::*;

use super::config::DesignConfig;
use super::eval::{score, Candidate, Context};
use super::setups::setups;

/// What the search found.
pub struct Found {
    /// The best candidate.
    pub best: Candidate,
    /// Candidates scored in all.
    pub scored: usize,
    /// The best coverage of each table-axis family at the ranking stage.
    pub alternatives: Vec<(String, f64, Candidate)>,
}

/// First refinement steps: table place, m (20 mm), and turns of the mount and the axis,
/// degrees (15); each round halves them.
const PLACE_STEP_M: f64 = 0.02;
/// See [`PLACE_STEP_M`].
const TURN_STEP_DEG: f64 = 15.0;

/// The family of a table axis, by its angle from the vertical.
fn family(axis: &[f64; 3]) -> &'static str {
    let up = axis[2].clamp(-1.0, 1.0).acos().to_degrees();
    if up < 15.0 {
        "vertical table axis"
    } else if up > 75.0 {
        "horizontal table axis"
    } else {
        "tilted table axis"
    }
}

/// Part directions tried along the table axis: the six axis directions and the eight cube
/// diagonals of the reference frame.
fn mounts() -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for k in 0..3 {
        for s in [1.0, -1.0] {
            let mut v = [0.0; 3];
            v[k] = s;
            out.push(v);
        }
    }
    let c = 1.0 / 3f64.sqrt();
    for x in [c, -c] {
        for y in [c, -c] {
            for z in [c, -c] {
                out.push([x, y, z]);
            }
        }
    }
    out
}

/// The coarse grid.
fn grid(ctx: &Context, cfg: &DesignConfig) -> Vec<Candidate> {
    let mut out = Vec::new();
    for &axis in &cfg.axes {
        for mount in mounts() {
            for &y in &cfg.distances_m {
                for &z in &cfg.heights_m {
                    for (shank, &shank_m) in ctx.shanks.iter().enumerate() {
                        out.push(Candidate {
                            axis,
                            mount,
                            centre: [0.0, y, z],
                            shank,
                            shank_m,
                        });
                    }
                }
            }
        }
    }
    out
}

/// Scores every candidate on `n` samples at `step` degrees; the feasible ones, best first.
fn rank(ctx: &Context, all: Vec<Candidate>, n: usize, step: f64) -> Vec<(Candidate, f64)> {
    let mut out: Vec<(Candidate, f64)> = all
        .into_par_iter()
        .filter_map(|c| score(ctx, &c, n, step, false).map(|s| (c, s.coverage)))
        .collect();
    out.sort_by(|a, b| b.1.total_cmp(&a.1));
    out
}

/// `v` turned by `deg` about each of two directions perpendicular to it, both ways.
fn turned(v: &[f64; 3], deg: f64) -> Vec<[f64; 3]> {
    let v = Vector3::from(*v);
    let side = if v.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let p1 = v.cross(&side).normalize();
    let p2 = v.cross(&p1).normalize();
    let mut out = Vec::new();
    for p in [p1, p2] {
        for s in [1.0, -1.0] {
            let r = Rotation3::from_axis_angle(&Unit::new_normalize(p), s * deg.to_radians());
            let w = r * v;
            out.push([w.x, w.y, w.z]);
        }
    }
    out
}

/// The neighbours of `c` at step `place` (m) and `turn` (degrees).
fn neighbours(ctx: &Context, c: &Candidate, place: f64, turn: f64) -> Vec<Candidate> {
    let mut out = Vec::new();
    for k in 0..3 {
        for s in [1.0, -1.0] {
            let mut n = c.clone();
            n.centre[k] += s * place;
            out.push(n);
        }
    }
    for mount in turned(&c.mount, turn) {
        out.push(Candidate { mount, ..c.clone() });
    }
    for axis in turned(&c.axis, turn).into_iter().filter(|a| a[2] >= 0.0) {
        out.push(Candidate { axis, ..c.clone() });
    }
    for shank in [c.shank.wrapping_sub(1), c.shank + 1] {
        if let Some(&shank_m) = ctx.shanks.get(shank) {
            out.push(Candidate {
                shank,
                shank_m,
                ..c.clone()
            });
        }
    }
    out
}

/// Of `all` (the refined winner first; None when none is buildable), the candidate whose setups
/// (`setups::setups`, on the ranking's samples and table angle step) reach most together; ties
/// (within one sample) go to the larger share of the first setup, then to the earlier candidate.
fn over_setups(ctx: &Context, cfg: &DesignConfig, all: Vec<Candidate>) -> Option<Candidate> {
    let tie = 0.5 / cfg.samples.max(1) as f64;
    let mut best: Option<(Candidate, f64, f64)> = None;
    for c in all {
        let Some(s) = score(ctx, &c, cfg.samples, cfg.step_deg, true) else {
            continue;
        };
        let reached: Vec<bool> = s.verdicts.iter().map(|v| v.angle_deg.is_some()).collect();
        let fixturings = setups(ctx, &c, &reached, cfg, cfg.step_deg);
        let union = fixturings.last().map_or(s.coverage, |f| f.union_coverage);
        let better = best
            .as_ref()
            .is_none_or(|b| union > b.1 + tie || (union > b.1 - tie && s.coverage > b.2 + tie));
        if better {
            best = Some((c, union, s.coverage));
        }
    }
    best.map(|b| b.0)
}

/// Runs the search.
pub fn run(ctx: &Context, cfg: &DesignConfig) -> Found {
    let all = grid(ctx, cfg);
    let mut scored = all.len();
    let coarse = rank(ctx, all, cfg.coarse_samples, cfg.coarse_step_deg);
    let mut kept: Vec<Candidate> = coarse.iter().take(cfg.keep).map(|c| c.0.clone()).collect();
    // the best of each family rides along, so the alternatives are scored alike
    for fam in [
        "vertical table axis",
        "horizontal table axis",
        "tilted table axis",
    ] {
        if let Some((c, _)) = coarse.iter().find(|(c, _)| family(&c.axis) == fam) {
            if !kept.contains(c) {
                kept.push(c.clone());
            }
        }
    }
    scored += kept.len();
    let ranked = rank(ctx, kept, cfg.samples, cfg.step_deg);
    let mut alternatives = Vec::new();
    for fam in [
        "vertical table axis",
        "horizontal table axis",
        "tilted table axis",
    ] {
        if let Some((c, s)) = ranked.iter().find(|(c, _)| family(&c.axis) == fam) {
            alternatives.push((fam.to_string(), *s, c.clone()));
        }
    }
    let finalists: Vec<Candidate> = ranked
        .iter()
        .take(cfg.finalists)
        .map(|r| r.0.clone())
        .collect();
    let Some((mut best, mut best_score)) = ranked.into_iter().next() else {
        let c = coarse.into_iter().next().map(|c| c.0);
        return Found {
            best: c.unwrap_or_else(|| grid(ctx, cfg).remove(0)),
            scored,
            alternatives,
        };
    };
    let (mut place, mut turn) = (PLACE_STEP_M, TURN_STEP_DEG);
    for _ in 0..cfg.rounds {
        let near = neighbours(ctx, &best, place, turn);
        scored += near.len();
        if let Some((c, s)) = rank(ctx, near, cfg.samples, cfg.step_deg)
            .into_iter()
            .next()
        {
            if s > best_score {
                (best, best_score) = (c, s);
                continue;
            }
        }
        place /= 2.0;
        turn /= 2.0;
    }
    if cfg.setups > 1 && cfg.finalists > 0 {
        let mut all = vec![best.clone()];
        all.extend(finalists.into_iter().filter(|c| *c != best));
        scored += all.len();
        if let Some(c) = over_setups(ctx, cfg, all) {
            best = c;
        }
    }
    Found {
        best,
        scored,
        alternatives,
    }
}

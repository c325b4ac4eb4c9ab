//! Global refinement: one joint point-to-plane ICP over every overlapping pair of placed views
//! (multi-view ICP), replacing the loop-closure spread of a single chain.
use nalgebra::{DMatrix, DVector, Isometry3, Matrix6, Point3, Vector3, Vector6};
use rayon::prelude::*;
use serde::Serialize;

use super::config::MergeConfig;
use super::pair::{overlap, strided, Prepared};

/// Least share of a view's sample points within the final ICP distance of another view (at
/// the placed poses) for the ordered pair to join the refinement: below it the pair shares a
/// rim only, whose normals are the least reliable.
const MIN_PAIR_OVERLAP: f64 = 0.05;

/// Most partners per view, those of the largest overlap first: a 36-view turn at 10 degree
/// steps overlaps 16 neighbours, six of them tie it down and keep the step under 10 s.
const MAX_PARTNERS: usize = 6;

/// How many views, nearest in turn first, a view's partners are sought among: its largest
/// overlaps are with its nearest neighbours on the table, [`MAX_PARTNERS`] of them, and twice
/// as many leave room for uneven steps and held views. The overlap test of every ordered pair
/// (1,260 on a 36-view turn) was a third of the global step.
const PAIR_CANDIDATES: usize = 2 * MAX_PARTNERS;

/// Source points per view and pair (evenly strided from its ICP sample).
const PAIR_POINTS: usize = 2_000;

/// Every how many sample points the pair overlap test uses.
const OVERLAP_EVERY: usize = 8;

/// Cap of the joint solve's searches for matches (each followed by its Gauss–Newton steps).
const ITERATIONS: usize = 15;

/// Most Gauss–Newton steps on one search's matches. The nearest-point searches of all pairs
/// are the step's cost (216 pairs x 2,000 points on a 36-view turn) while a step on fixed
/// matches costs a fraction of one: the steps go on with the same matches until they settle
/// (4-6 steps on the 36-view turn), then the matches are sought again. Bounded so that a
/// far-off start cannot run long on stale matches.
const STEPS_PER_SEARCH: usize = 8;

/// The joint solve has converged when no pose moves by more than this (degrees and mm).
const CONVERGED: f64 = 1e-4;

/// Damping of the normal equations relative to their mean diagonal: keeps a view that is
/// tied down in fewer than six directions from blowing up, far below any real constraint.
const DAMPING: f64 = 1e-9;

/// What the global step did.
#[derive(Debug, Clone, Serialize)]
pub struct GlobalRefinement {
    /// Ordered view pairs (moving, fixed) in the joint fit.
    pub pairs: usize,
    /// Gauss–Newton steps run (on fresh matches and on kept ones).
    pub iterations: usize,
    /// Searches for matches (nearest target points of every pair's points), the last one
    /// giving the residuals after.
    pub searches: usize,
    /// RMS point-to-plane residual over all pairs before and after, mm.
    pub rms_before_mm: f64,
    /// RMS point-to-plane residual over all pairs after, mm.
    pub rms_after_mm: f64,
    /// Largest rotation and translation of one view by the step, degrees and mm.
    pub largest_move: [f64; 2],
}

/// One view's fit after the global step.
#[derive(Debug, Clone, Default)]
pub(super) struct ViewResidual {
    /// RMS point-to-plane residual of its points onto its partners, mm (NaN: no pair).
    pub rms_mm: f64,
    /// Its matched points.
    pub points: usize,
    /// Its partners (positions in the refined list).
    pub partners: Vec<usize>,
}

/// One matched point: Jacobian of the residual with respect to the moving view's pose
/// (the fixed view's is its negative) and the residual.
type Row = (Vector6<f64>, f64);

/// One pair's matches: a source point of the moving view (its own frame) and the index of its
/// nearest target point of the fixed view.
type Matches = Vec<(Point3<f64>, u32)>;

/// Matches of the ordered pair (a onto b) at `poses`: each of a's pair points (evenly strided
/// from its sample) with its nearest target point of b within `max_distance`.
fn pair_matches(
    a: &Prepared,
    b: &Prepared,
    pose_a: &Isometry3<f64>,
    pose_b: &Isometry3<f64>,
    max_distance: f64,
) -> Matches {
    let rel = pose_b.inverse() * pose_a;
    let mut out = Vec::new();
    strided(&a.sample, PAIR_POINTS)
        .into_iter()
        .filter_map(|p| {
            b.index.knn(&(rel * p), 1, max_distance, &mut out);
            out.first().map(|&(_, j)| (p, j))
        })
        .collect()
}

/// Rows of the ordered pair (a onto b) at `poses` from its `matches`, in the first view's
/// frame.
fn pair_rows(
    matches: &Matches,
    b: &Prepared,
    pose_a: &Isometry3<f64>,
    pose_b: &Isometry3<f64>,
) -> Vec<Row> {
    let rel = pose_b.inverse() * pose_a;
    matches
        .iter()
        .map(|&(p, j)| {
            let world = pose_b * (rel * p);
            let t = pose_b * b.target[j as usize];
            let n: Vector3<f64> = pose_b.rotation * b.normals[j as usize];
            let r = n.dot(&(world - t));
            let jac =
                Vector6::from_iterator(world.coords.cross(&n).iter().chain(n.iter()).copied());
            (jac, r)
        })
        .collect()
}

/// Ordered pairs (a, b) of positions in `views` at `poses`: each view's partners of largest
/// overlap among the [`PAIR_CANDIDATES`] views nearest to it in turn (the angle of the
/// rotation between their poses; ties to the lower position).
pub(super) fn pairs(
    views: &[&Prepared],
    poses: &[Isometry3<f64>],
    cfg: &MergeConfig,
) -> Vec<(usize, usize)> {
    let per_view = (0..views.len()).into_par_iter().map(|a| {
        let turn = |b: usize| poses[a].rotation.angle_to(&poses[b].rotation);
        let mut nearest: Vec<usize> = (0..views.len()).filter(|&b| b != a).collect();
        nearest.sort_by(|&x, &y| turn(x).total_cmp(&turn(y)).then(x.cmp(&y)));
        nearest.truncate(PAIR_CANDIDATES);
        let mut shares: Vec<(f64, usize)> = nearest
            .into_iter()
            .map(|b| {
                let rel = poses[b].inverse() * poses[a];
                let s = overlap(views[a], views[b], &rel, cfg.final_distance, OVERLAP_EVERY);
                (s, b)
            })
            .filter(|&(s, _)| s >= MIN_PAIR_OVERLAP)
            .collect();
        shares.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        shares
            .iter()
            .take(MAX_PARTNERS)
            .map(|&(_, b)| (a, b))
            .collect::<Vec<_>>()
    });
    per_view.collect::<Vec<_>>().concat()
}

/// Geman–McClure weight with squared scale `k2`, as in the register stage's ICP.
fn weight(r: f64, k2: f64) -> f64 {
    let d = k2 + r * r;
    (k2 / d) * (k2 / d)
}

/// Median of |r| over all rows.
fn median_abs(rows: &[Vec<Row>]) -> f64 {
    let mut v: Vec<f64> = rows.iter().flatten().map(|r| r.1.abs()).collect();
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Refines `poses` (view-to-first, position 0 fixed) of `views` jointly: the robust
/// point-to-plane residuals of every ordered overlapping pair are minimised over all poses at
/// once (Gauss–Newton, each pose updated by a small motion in the first view's frame). `edges`:
/// the ordered pairs ([`pairs`]). None when there is none.
pub(super) fn refine(
    views: &[&Prepared],
    poses: &mut [Isometry3<f64>],
    edges: &[(usize, usize)],
    cfg: &MergeConfig,
) -> Option<(GlobalRefinement, Vec<ViewResidual>)> {
    let m = views.len();
    if edges.is_empty() || m < 2 {
        return None;
    }
    let start = poses.to_vec();
    let mr = views.iter().map(|v| v.spacing).fold(0.0, f64::max);
    let mut iterations = 0;
    let search = |poses: &[Isometry3<f64>]| -> Vec<Matches> {
        edges
            .par_iter()
            .map(|&(a, b)| {
                let d = cfg.final_distance * views[a].spacing.max(views[b].spacing);
                pair_matches(views[a], views[b], &poses[a], &poses[b], d)
            })
            .collect()
    };
    let rows_at = |matches: &[Matches], poses: &[Isometry3<f64>]| -> Vec<Vec<Row>> {
        edges
            .par_iter()
            .zip(matches)
            .map(|(&(a, b), m)| pair_rows(m, views[b], &poses[a], &poses[b]))
            .collect()
    };
    let mut matches = search(poses);
    let mut rows = rows_at(&matches, poses);
    let rms_before = rms(rows.iter().flatten());
    let mut searches = 1;
    for _ in 0..ITERATIONS {
        // Gauss–Newton steps on this search's matches until they settle.
        let mut first_largest = f64::INFINITY;
        for step in 0..STEPS_PER_SEARCH {
            let k = (3.0 * 1.4826 * median_abs(&rows)).max(1e-3 * mr);
            let Some(x) = solve(edges, &rows, m, k * k) else {
                break;
            };
            iterations += 1;
            let largest = apply(poses, &x);
            if step == 0 {
                first_largest = largest;
            }
            rows = rows_at(&matches, poses);
            if largest < CONVERGED {
                break;
            }
        }
        if first_largest.is_infinite() {
            // No step could be solved on fresh matches: the rows stand as they are.
            break;
        }
        matches = search(poses);
        rows = rows_at(&matches, poses);
        searches += 1;
        // Converged: the first step on fresh matches moved no pose by more than CONVERGED.
        if first_largest < CONVERGED {
            break;
        }
    }
    let largest_move = start
        .iter()
        .zip(poses.iter())
        .fold([0.0f64; 2], |acc, (a, b)| {
            let (dr, dt) = crate::cloud::transform::pose_difference(a, b);
            [acc[0].max(dr), acc[1].max(dt)]
        });
    let mut per_view = vec![ViewResidual::default(); m];
    for (&(a, b), r) in edges.iter().zip(&rows) {
        per_view[a].partners.push(b);
        per_view[a].points += r.len();
    }
    for (p, v) in per_view.iter_mut().enumerate() {
        v.rms_mm = rms(edges
            .iter()
            .zip(&rows)
            .filter(|(e, _)| e.0 == p)
            .flat_map(|(_, r)| r));
    }
    let summary = GlobalRefinement {
        pairs: edges.len(),
        iterations,
        searches,
        rms_before_mm: rms_before,
        rms_after_mm: rms(rows.iter().flatten()),
        largest_move,
    };
    Some((summary, per_view))
}

/// Moves every pose but the first by its motion in `x` (rotation vector, then translation,
/// six per view from position 1; applied in the first view's frame): the largest rotation
/// (degrees) or translation (mm).
fn apply(poses: &mut [Isometry3<f64>], x: &DVector<f64>) -> f64 {
    let mut largest: f64 = 0.0;
    for (p, pose) in poses.iter_mut().enumerate().skip(1) {
        let s = x.rows(6 * (p - 1), 6);
        let (w, v) = (
            Vector3::new(s[0], s[1], s[2]),
            Vector3::new(s[3], s[4], s[5]),
        );
        *pose = Isometry3::new(v, w) * *pose;
        largest = largest.max(w.norm().to_degrees()).max(v.norm());
    }
    largest
}

/// RMS of the residuals of `rows` (NaN when empty).
fn rms<'a>(rows: impl Iterator<Item = &'a Row>) -> f64 {
    let (n, sum) = rows.fold((0usize, 0.0), |(n, s), r| (n + 1, s + r.1 * r.1));
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

/// One Gauss–Newton step of all poses but the first: the motions (rotation vector, then
/// translation, six per view from position 1) minimising the weighted residuals to first
/// order. A matched point of pair (a, b) has Jacobian `J` for a's motion and `-J` for b's.
fn solve(edges: &[(usize, usize)], rows: &[Vec<Row>], m: usize, k2: f64) -> Option<DVector<f64>> {
    let n = 6 * (m - 1);
    let mut h = DMatrix::<f64>::zeros(n, n);
    let mut g = DVector::<f64>::zeros(n);
    for (&(a, b), r) in edges.iter().zip(rows) {
        let (mut s, mut t) = (Matrix6::<f64>::zeros(), Vector6::<f64>::zeros());
        for (jac, res) in r {
            let w = weight(*res, k2);
            s += jac * jac.transpose() * w;
            t += jac * (w * res);
        }
        let sides = [(a, 1.0), (b, -1.0)];
        for &(p, sp) in sides.iter().filter(|x| x.0 > 0) {
            let ip = 6 * (p - 1);
            let mut gp = g.rows_mut(ip, 6);
            gp += t * sp;
            for &(q, sq) in sides.iter().filter(|x| x.0 > 0) {
                let mut block = h.slice_mut((ip, 6 * (q - 1)), (6, 6));
                block += s * (sp * sq);
            }
        }
    }
    let damping = DAMPING * (h.trace() / n as f64).max(f64::MIN_POSITIVE);
    for i in 0..n {
        h[(i, i)] += damping;
    }
    h.cholesky().map(|c| c.solve(&(-g)))
}

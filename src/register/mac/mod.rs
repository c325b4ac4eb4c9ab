//! MAC coarse registration (Zhang et al., "3D Registration with Maximal Cliques", CVPR 2023):
//! compatibility graphs, maximal cliques with node-guided selection, one weighted-SVD pose per
//! clique, MAE scoring over all correspondences, iterative re-weighted refinement.
pub mod cliques;
pub mod graph;
pub mod pose;

use std::time::{Duration, Instant};

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;
use serde::Serialize;

use cliques::CliqueLimits;

/// Settings of the MAC stage with lengths already resolved (mm).
#[derive(Debug, Clone)]
pub struct MacParams {
    /// Scale `d_cs` of the compatibility score `exp(-d² / (2 d_cs²))`.
    pub compat_sigma: f64,
    /// First-order edges scoring below this are cut.
    pub compat_min_score: f64,
    /// Inlier threshold `tau` of the MAE score and the refinement.
    pub inlier_threshold: f64,
    /// Smallest clique.
    pub min_clique: usize,
    /// Cap on enumerated maximal cliques.
    pub max_cliques: usize,
    /// Time budget of the clique search.
    pub time_budget: Duration,
    /// Selected cliques kept (heaviest first).
    pub top_k: usize,
    /// Cap on the second-order graph's work (sum of squared degrees); a denser first-order
    /// graph is thinned by dropping the correspondences of largest feature distance.
    pub max_graph_work: u64,
    /// Distinct refined hypotheses returned.
    pub hypotheses_out: usize,
}

/// A candidate pose with its MAE score and inlier count over all correspondences.
#[derive(Debug, Clone, Copy)]
pub struct Hypothesis {
    /// Scan-to-reference pose.
    pub pose: Isometry3<f64>,
    /// MAE score.
    pub score: f64,
    /// Correspondences within the inlier threshold.
    pub inliers: usize,
}

/// Counters of the MAC stage.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MacStats {
    /// Correspondences in the graph (after any thinning).
    pub graph_nodes: usize,
    /// First-order graph edges.
    pub graph_edges: usize,
    /// Second-order graph edges.
    pub second_order_edges: usize,
    /// Maximal cliques enumerated.
    pub cliques_found: usize,
    /// True when the clique cap or time budget stopped enumeration.
    pub cliques_truncated: bool,
    /// Cliques kept by node-guided selection.
    pub cliques_selected: usize,
    /// Pose hypotheses scored.
    pub hypotheses: usize,
    /// Seconds building both graphs.
    pub graph_seconds: f64,
    /// Seconds enumerating cliques.
    pub clique_seconds: f64,
    /// Seconds computing and scoring hypotheses.
    pub hypothesis_seconds: f64,
}

/// Runs MAC on correspondences `src[i] <-> dst[i]` (ordered best first, so thinning keeps a
/// prefix). Returns distinct refined hypotheses, best score first.
pub fn mac(src: &[Point3<f64>], dst: &[Point3<f64>], p: &MacParams) -> (Vec<Hypothesis>, MacStats) {
    let mut stats = MacStats::default();
    let t0 = Instant::now();
    let mut n = src.len();
    let mut g1 = graph::first_order(src, dst, p.compat_sigma, p.compat_min_score);
    while g1.work() > p.max_graph_work && n > 50 {
        let shrink = (p.max_graph_work as f64 / g1.work() as f64).powf(1.0 / 3.0);
        n = ((n as f64 * shrink.min(0.9)) as usize).max(50);
        g1 = graph::first_order(&src[..n], &dst[..n], p.compat_sigma, p.compat_min_score);
    }
    let g2 = graph::second_order(&g1);
    stats.graph_nodes = n;
    stats.graph_edges = g1.edges();
    stats.second_order_edges = g2.edges();
    stats.graph_seconds = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let limits = CliqueLimits {
        min_size: p.min_clique,
        max_cliques: p.max_cliques,
        deadline: Some(t1 + p.time_budget),
    };
    let sel = cliques::node_guided(&g2, limits, p.top_k);
    stats.cliques_found = sel.found;
    stats.cliques_truncated = sel.truncated;
    stats.cliques_selected = sel.cliques.len();
    stats.clique_seconds = t1.elapsed().as_secs_f64();

    let t2 = Instant::now();
    let mut hyps: Vec<Hypothesis> = sel
        .cliques
        .par_iter()
        .filter_map(|(c, _)| {
            let s: Vec<Point3<f64>> = c.iter().map(|&i| src[i as usize]).collect();
            let d: Vec<Point3<f64>> = c.iter().map(|&i| dst[i as usize]).collect();
            // Node weight: its share of the clique's second-order edge weight.
            let w: Vec<f64> = c
                .iter()
                .map(|&i| {
                    c.iter()
                        .filter_map(|&j| g2.weight(i as usize, j as usize))
                        .map(f64::from)
                        .sum::<f64>()
                })
                .collect();
            let pose = pose::weighted_svd(&s, &d, &w)?;
            let (score, inliers) = pose::mae_score(&pose, src, dst, p.inlier_threshold);
            Some(Hypothesis {
                pose,
                score,
                inliers,
            })
        })
        .collect();
    stats.hypotheses = hyps.len();
    hyps.sort_by(|a, b| b.score.total_cmp(&a.score));
    // Refine the best candidates and keep the distinct ones.
    let refined: Vec<Hypothesis> = hyps
        .par_iter()
        .take(4 * p.hypotheses_out)
        .map(|h| {
            let pose = pose::refine(&h.pose, src, dst, p.inlier_threshold, 30);
            let (score, inliers) = pose::mae_score(&pose, src, dst, p.inlier_threshold);
            Hypothesis {
                pose,
                score,
                inliers,
            }
        })
        .collect();
    let mut out: Vec<Hypothesis> = Vec::new();
    let mut sorted = refined;
    sorted.sort_by(|a, b| b.score.total_cmp(&a.score));
    for h in sorted {
        let distinct = out.iter().all(|o| {
            let d = o.pose.inverse() * h.pose;
            d.rotation.angle() > 2f64.to_radians()
                || d.translation.vector.norm() > 2.0 * p.inlier_threshold
        });
        if distinct && out.len() < p.hypotheses_out {
            out.push(h);
        }
    }
    stats.hypothesis_seconds = t2.elapsed().as_secs_f64();
    (out, stats)
}

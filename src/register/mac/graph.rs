//! Compatibility graphs of MAC: the first-order graph from the rigid-distance constraint and
//! the second-order graph `W ⊙ (W × W)`, both sparse (sorted adjacency lists with weights).
use nalgebra::Point3;
use rayon::prelude::*;

/// An undirected weighted graph as sorted adjacency lists.
#[derive(Debug, Clone, Default)]
pub struct Graph {
    /// `adj[i]`: neighbours of node `i`, sorted by index, with edge weights.
    pub adj: Vec<Vec<(u32, f32)>>,
}

impl Graph {
    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.adj.len()
    }

    /// True when the graph has no nodes.
    pub fn is_empty(&self) -> bool {
        self.adj.is_empty()
    }

    /// Number of undirected edges.
    pub fn edges(&self) -> usize {
        self.adj.iter().map(Vec::len).sum::<usize>() / 2
    }

    /// Weight of edge (i, j), or None.
    pub fn weight(&self, i: usize, j: usize) -> Option<f32> {
        let row = &self.adj[i];
        row.binary_search_by_key(&(j as u32), |e| e.0)
            .ok()
            .map(|k| row[k].1)
    }

    /// Sum of squared degrees: the cost of building the second-order graph.
    pub fn work(&self) -> u64 {
        self.adj.iter().map(|r| (r.len() as u64).pow(2)).sum()
    }
}

/// First-order graph: correspondences `i`, `j` (scan point `s`, reference point `t`) score
/// `exp(-d² / (2 sigma²))` with `d = | |s_i - s_j| - |t_i - t_j| |`; edges scoring below
/// `min_score` are cut.
pub fn first_order(
    scan: &[Point3<f64>],
    reference: &[Point3<f64>],
    sigma: f64,
    min_score: f64,
) -> Graph {
    let n = scan.len();
    // exp(-d²/(2σ²)) >= min_score means d² <= -2σ² ln(min_score): that (widened a hair for
    // rounding) skips the exponential on the pairs that are cut anyway.
    let cut_d2 = -2.0 * sigma * sigma * min_score.ln() * (1.0 + 1e-9);
    let upper: Vec<Vec<(u32, f32)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let mut row = Vec::new();
            for j in i + 1..n {
                let d = ((scan[i] - scan[j]).norm() - (reference[i] - reference[j]).norm()).abs();
                if d * d > cut_d2 {
                    continue;
                }
                let s = (-d * d / (2.0 * sigma * sigma)).exp();
                if s >= min_score {
                    row.push((j as u32, s as f32));
                }
            }
            row
        })
        .collect();
    Graph { adj: mirror(upper) }
}

/// Full adjacency lists from the upper triangle (`upper[i]`: neighbours `j > i`, sorted):
/// the weights of both directions are the same number, so each edge is computed once.
fn mirror(upper: Vec<Vec<(u32, f32)>>) -> Vec<Vec<(u32, f32)>> {
    let mut lower: Vec<Vec<(u32, f32)>> = vec![Vec::new(); upper.len()];
    for (i, row) in upper.iter().enumerate() {
        for &(j, w) in row {
            lower[j as usize].push((i as u32, w));
        }
    }
    lower
        .into_iter()
        .zip(upper)
        .map(|(mut row, up)| {
            row.extend(up);
            row
        })
        .collect()
}

/// Second-order graph: `W2_ij = W_ij * sum_k W_ik W_kj` over common neighbours `k`; edges
/// without a common neighbour (W2 = 0) are dropped. Each edge is computed once (i < j).
pub fn second_order(w: &Graph) -> Graph {
    let adj = (0..w.len())
        .into_par_iter()
        .map(|i| {
            let ri = &w.adj[i];
            ri.iter()
                .filter(|e| e.0 as usize > i)
                .filter_map(|&(j, wij)| {
                    let rj = &w.adj[j as usize];
                    let (mut a, mut b, mut s) = (0, 0, 0.0f32);
                    while a < ri.len() && b < rj.len() {
                        match ri[a].0.cmp(&rj[b].0) {
                            std::cmp::Ordering::Less => a += 1,
                            std::cmp::Ordering::Greater => b += 1,
                            std::cmp::Ordering::Equal => {
                                s += ri[a].1 * rj[b].1;
                                a += 1;
                                b += 1;
                            }
                        }
                    }
                    (s > 0.0).then_some((j, wij * s))
                })
                .collect()
        })
        .collect();
    Graph { adj: mirror(adj) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn second_order_equals_dense_product() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let n = 40;
        let mut dense = vec![vec![0.0f32; n]; n];
        for i in 0..n {
            for j in i + 1..n {
                if rng.gen_bool(0.3) {
                    let v = rng.gen_range(0.1..1.0);
                    dense[i][j] = v;
                    dense[j][i] = v;
                }
            }
        }
        let w = Graph {
            adj: dense
                .iter()
                .map(|r| {
                    r.iter()
                        .enumerate()
                        .filter(|e| *e.1 > 0.0)
                        .map(|(j, &v)| (j as u32, v))
                        .collect()
                })
                .collect(),
        };
        let w2 = second_order(&w);
        for i in 0..n {
            for j in 0..n {
                let prod: f32 = (0..n).map(|k| dense[i][k] * dense[k][j]).sum();
                let want = dense[i][j] * prod;
                let got = w2.weight(i, j).unwrap_or(0.0);
                assert!((want - got).abs() < 1e-5, "{i},{j}: {want} vs {got}");
            }
        }
    }

    #[test]
    fn rigid_pairs_are_compatible() {
        let s = [Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0)];
        let t = [Point3::new(5.0, 5.0, 5.0), Point3::new(5.0, 6.0, 5.0)];
        let g = first_order(&s, &t, 0.1, 0.5);
        assert_eq!(g.edges(), 1);
        let t_bad = [Point3::new(5.0, 5.0, 5.0), Point3::new(5.0, 7.0, 5.0)];
        assert_eq!(first_order(&s, &t_bad, 0.1, 0.5).edges(), 0);
    }
}

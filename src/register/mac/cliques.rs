//! Maximal cliques (Bron–Kerbosch with Tomita pivoting, outer loop over a degeneracy order,
//! parallel over start vertices) and MAC's node-guided clique selection.
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use rayon::prelude::*;

use super::graph::Graph;

/// A fixed-size bit set.
#[derive(Clone)]
struct Bits(Vec<u64>);

impl Bits {
    fn new(n: usize) -> Bits {
        Bits(vec![0; n.div_ceil(64)])
    }
    fn set(&mut self, i: usize) {
        self.0[i / 64] |= 1 << (i % 64);
    }
    fn clear(&mut self, i: usize) {
        self.0[i / 64] &= !(1 << (i % 64));
    }
    fn is_empty(&self) -> bool {
        self.0.iter().all(|&w| w == 0)
    }
    fn count(&self) -> usize {
        self.0.iter().map(|w| w.count_ones() as usize).sum()
    }
    fn and(&self, o: &Bits) -> Bits {
        Bits(self.0.iter().zip(&o.0).map(|(a, b)| a & b).collect())
    }
    fn and_count(&self, o: &Bits) -> usize {
        self.0
            .iter()
            .zip(&o.0)
            .map(|(a, b)| (a & b).count_ones() as usize)
            .sum()
    }
    fn and_not(&self, o: &Bits) -> Bits {
        Bits(self.0.iter().zip(&o.0).map(|(a, b)| a & !b).collect())
    }
    fn or(&self, o: &Bits) -> Bits {
        Bits(self.0.iter().zip(&o.0).map(|(a, b)| a | b).collect())
    }
    fn iter(&self) -> impl Iterator<Item = usize> + '_ {
        self.0.iter().enumerate().flat_map(|(k, &w)| {
            let mut w = w;
            std::iter::from_fn(move || {
                (w != 0).then(|| {
                    let b = w.trailing_zeros() as usize;
                    w &= w - 1;
                    k * 64 + b
                })
            })
        })
    }
}

/// Start vertices enumerated between two checks of the clique cap ([`node_guided`]).
const CAP_CHUNK: usize = 16;

/// Limits that keep enumeration bounded on dense graphs.
#[derive(Debug, Clone, Copy)]
pub struct CliqueLimits {
    /// Smallest clique reported.
    pub min_size: usize,
    /// Stop after this many maximal cliques.
    pub max_cliques: usize,
    /// Stop at this instant.
    pub deadline: Option<Instant>,
}

/// Shared stop state of one enumeration.
struct Budget {
    limits: CliqueLimits,
    found: AtomicUsize,
    stopped: AtomicBool,
    /// Set when some start vertex hit `per_vertex`.
    capped: AtomicBool,
    /// Cap on the cliques of one start vertex, so that one dense neighbourhood cannot take
    /// the whole budget.
    per_vertex: usize,
}

impl Budget {
    fn new(limits: CliqueLimits, vertices: usize) -> Budget {
        Budget {
            limits,
            found: AtomicUsize::new(0),
            stopped: AtomicBool::new(false),
            capped: AtomicBool::new(false),
            per_vertex: (limits.max_cliques / vertices.max(1)).max(64),
        }
    }

    fn exhausted(&self, local: usize) -> bool {
        if local >= self.per_vertex {
            self.capped.store(true, Ordering::Relaxed);
            return true;
        }
        if self.stopped.load(Ordering::Relaxed) {
            return true;
        }
        // The clique cap is applied between chunks of start vertices ([`node_guided`]), so
        // that which cliques are found does not depend on the threads' timing.
        let out = self.limits.deadline.is_some_and(|d| Instant::now() >= d);
        if out {
            self.stopped.store(true, Ordering::Relaxed);
        }
        out
    }
}

/// Degeneracy order (repeatedly remove a vertex of smallest remaining degree): position of
/// each vertex in the order.
fn degeneracy_positions(g: &Graph) -> Vec<usize> {
    let n = g.len();
    let mut deg: Vec<usize> = g.adj.iter().map(Vec::len).collect();
    let maxd = deg.iter().copied().max().unwrap_or(0);
    let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); maxd + 1];
    for (v, &d) in deg.iter().enumerate() {
        buckets[d].push(v);
    }
    let mut removed = vec![false; n];
    let mut pos = vec![0; n];
    let mut d: usize = 0;
    for k in 0..n {
        d = d.saturating_sub(1);
        let v = loop {
            while buckets[d].is_empty() {
                d += 1;
            }
            let v = buckets[d].pop().expect("non-empty");
            if !removed[v] && deg[v] == d {
                break v;
            }
        };
        removed[v] = true;
        pos[v] = k;
        for &(u, _) in &g.adj[v] {
            let u = u as usize;
            if !removed[u] {
                deg[u] -= 1;
                buckets[deg[u]].push(u);
            }
        }
    }
    pos
}

/// Enumerates the maximal cliques containing `v` as their earliest vertex in the order,
/// calling `report` with each (global indices) and its weight (sum of edge weights).
/// `local` is scratch of one entry per vertex, all `u32::MAX`, and is left so.
fn cliques_from(
    g: &Graph,
    pos: &[usize],
    v: usize,
    budget: &Budget,
    local: &mut [u32],
    report: &mut dyn FnMut(&[u32], f64),
) {
    let nb: Vec<u32> = g.adj[v].iter().map(|e| e.0).collect();
    let d = nb.len();
    if d + 1 < budget.limits.min_size {
        return;
    }
    // N(u) ∩ N(v) for every u in N(v), by looking each of N(u) up in N(v)'s local indices
    // (a merge of the two sorted lists branches unpredictably at every step).
    for (k, &u) in nb.iter().enumerate() {
        local[u as usize] = k as u32;
    }
    let local_adj: Vec<Bits> = nb
        .iter()
        .map(|&u| {
            let mut b = Bits::new(d);
            for e in &g.adj[u as usize] {
                let k = local[e.0 as usize] as usize;
                if k < d {
                    b.set(k);
                }
            }
            b
        })
        .collect();
    for &u in &nb {
        local[u as usize] = u32::MAX;
    }
    let (mut p, mut x) = (Bits::new(d), Bits::new(d));
    for (k, &u) in nb.iter().enumerate() {
        if pos[u as usize] > pos[v] {
            p.set(k);
        } else {
            x.set(k);
        }
    }
    let mut r = vec![v as u32];
    let mut local = |clique: &[usize], r: &mut Vec<u32>, w: f64| {
        r.truncate(1);
        r.extend(clique.iter().map(|&k| nb[k]));
        report(r, w);
    };
    // Weight an edge (v or a local node, local node): looked up in the global lists.
    let weight_to = |a: Option<usize>, b: usize| {
        let ga = a.map_or(v, |k| nb[k] as usize);
        g.weight(ga, nb[b] as usize).unwrap_or(0.0) as f64
    };
    let mut stack = Vec::new();
    let ctx = Ctx {
        adj: &local_adj,
        budget,
        weight: &weight_to,
        local_found: std::cell::Cell::new(0),
    };
    bron_kerbosch(&ctx, &mut stack, 0.0, p, x, &mut local, &mut r);
}

/// Receives a clique found in a neighbourhood: local members, scratch, weight.
type LocalReport<'a> = dyn FnMut(&[usize], &mut Vec<u32>, f64) + 'a;

/// What the recursion needs besides its sets.
struct Ctx<'a> {
    adj: &'a [Bits],
    budget: &'a Budget,
    /// Edge weight between the start vertex (None) or a local node and a local node.
    weight: &'a dyn Fn(Option<usize>, usize) -> f64,
    /// Cliques reported from this start vertex.
    local_found: std::cell::Cell<usize>,
}

/// Bron–Kerbosch with Tomita pivoting on local bit sets; `r` holds the clique so far (without
/// the start vertex) and `w` its edge-weight sum.
fn bron_kerbosch(
    ctx: &Ctx,
    r: &mut Vec<usize>,
    w: f64,
    mut p: Bits,
    mut x: Bits,
    report: &mut LocalReport,
    scratch: &mut Vec<u32>,
) {
    let (adj, budget) = (ctx.adj, ctx.budget);
    if budget.exhausted(ctx.local_found.get()) {
        return;
    }
    if p.is_empty() {
        if x.is_empty() && r.len() + 1 >= budget.limits.min_size {
            budget.found.fetch_add(1, Ordering::Relaxed);
            ctx.local_found.set(ctx.local_found.get() + 1);
            report(r, scratch, w);
        }
        return;
    }
    if r.len() + 1 + p.count() < budget.limits.min_size {
        return;
    }
    let pivot = p
        .or(&x)
        .iter()
        .max_by_key(|&u| p.and_count(&adj[u]))
        .expect("P is not empty");
    let candidates: Vec<usize> = p.and_not(&adj[pivot]).iter().collect();
    for c in candidates {
        let added =
            (ctx.weight)(None, c) + r.iter().map(|&k| (ctx.weight)(Some(k), c)).sum::<f64>();
        r.push(c);
        bron_kerbosch(
            ctx,
            r,
            w + added,
            p.and(&adj[c]),
            x.and(&adj[c]),
            report,
            scratch,
        );
        r.pop();
        p.clear(c);
        x.set(c);
    }
}

/// Every maximal clique of at least `min_size` nodes (sorted node lists), unbounded: for tests
/// and small graphs.
pub fn maximal_cliques(g: &Graph, min_size: usize) -> Vec<Vec<u32>> {
    let mut budget = Budget::new(
        CliqueLimits {
            min_size,
            max_cliques: usize::MAX,
            deadline: None,
        },
        g.len(),
    );
    budget.per_vertex = usize::MAX;
    let pos = degeneracy_positions(g);
    let mut out = Vec::new();
    let mut local = vec![u32::MAX; g.len()];
    for v in 0..g.len() {
        cliques_from(g, &pos, v, &budget, &mut local, &mut |c, _| {
            let mut c = c.to_vec();
            c.sort_unstable();
            out.push(c);
        });
    }
    out
}

/// The outcome of node-guided clique search.
#[derive(Debug, Clone, Default)]
pub struct Selection {
    /// Selected cliques (sorted node lists) with their weight, heaviest first.
    pub cliques: Vec<(Vec<u32>, f64)>,
    /// Maximal cliques enumerated.
    pub found: usize,
    /// True when the clique cap or the time budget stopped the enumeration.
    pub truncated: bool,
}

/// Weight of a clique: the sum of its edge weights.
#[cfg(test)]
fn clique_weight(g: &Graph, c: &[u32]) -> f64 {
    let mut s = 0.0;
    for (a, &i) in c.iter().enumerate() {
        for &j in &c[a + 1..] {
            s += g.weight(i as usize, j as usize).unwrap_or(0.0) as f64;
        }
    }
    s
}

/// Per-node best clique, as kept by one worker.
struct NodeBest {
    weight: Vec<f64>,
    index: Vec<u32>,
    store: Vec<(Vec<u32>, f64)>,
}

impl NodeBest {
    fn new(n: usize) -> NodeBest {
        NodeBest {
            weight: vec![f64::NEG_INFINITY; n],
            index: vec![u32::MAX; n],
            store: Vec::new(),
        }
    }
    fn offer(&mut self, clique: &[u32], w: f64) {
        if clique.iter().any(|&v| w > self.weight[v as usize]) {
            let mut clique = clique.to_vec();
            clique.sort_unstable();
            let id = self.store.len() as u32;
            for &v in &clique {
                if w > self.weight[v as usize] {
                    self.weight[v as usize] = w;
                    self.index[v as usize] = id;
                }
            }
            self.store.push((clique, w));
        }
    }
    fn merge(mut self, other: NodeBest) -> NodeBest {
        for v in 0..self.weight.len() {
            let id = other.index[v];
            if id != u32::MAX && other.weight[v] > self.weight[v] {
                let (c, w) = &other.store[id as usize];
                self.offer(c, *w);
            }
        }
        self
    }
}

/// MAC's node-guided selection: enumerate maximal cliques (in parallel over start vertices,
/// within `limits`), keep for every node its heaviest clique, remove duplicates and return the
/// `top_k` heaviest.
pub fn node_guided(g: &Graph, limits: CliqueLimits, top_k: usize) -> Selection {
    let n = g.len();
    let budget = Budget::new(limits, n);
    let pos = degeneracy_positions(g);
    // Start vertices in chunks, in order; the cap is checked after each chunk: the cliques
    // found are the same from run to run (a shared counter checked inside the recursion let
    // the threads' timing choose them).
    let mut best = NodeBest::new(n);
    let mut capped = false;
    for start in (0..n).step_by(CAP_CHUNK) {
        if budget.found.load(Ordering::Relaxed) >= limits.max_cliques {
            capped = true;
            break;
        }
        let chunk = (start..(start + CAP_CHUNK).min(n))
            .into_par_iter()
            .fold(
                || (NodeBest::new(n), vec![u32::MAX; n]),
                |(mut acc, mut local), v| {
                    cliques_from(g, &pos, v, &budget, &mut local, &mut |c, w| {
                        acc.offer(c, w);
                    });
                    (acc, local)
                },
            )
            .map(|(acc, _)| acc)
            .reduce(|| NodeBest::new(n), NodeBest::merge);
        best = best.merge(chunk);
    }
    let mut ids: Vec<u32> = best
        .index
        .iter()
        .copied()
        .filter(|&i| i != u32::MAX)
        .collect();
    ids.sort_unstable();
    ids.dedup();
    let mut cliques: Vec<(Vec<u32>, f64)> = ids
        .iter()
        .map(|&i| best.store[i as usize].clone())
        .collect();
    cliques.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    cliques.dedup_by(|a, b| a.0 == b.0);
    cliques.truncate(top_k);
    Selection {
        cliques,
        found: budget.found.load(Ordering::Relaxed),
        truncated: capped
            || budget.stopped.load(Ordering::Relaxed)
            || budget.capped.load(Ordering::Relaxed),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_graph(n: usize, p: f64, seed: u64) -> Graph {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut adj = vec![Vec::new(); n];
        for i in 0..n {
            for j in i + 1..n {
                if rng.gen_bool(p) {
                    let w = rng.gen_range(0.1f32..1.0);
                    adj[i].push((j as u32, w));
                    adj[j].push((i as u32, w));
                }
            }
        }
        adj.iter_mut().for_each(|r| r.sort_by_key(|e| e.0));
        Graph { adj }
    }

    /// All maximal cliques by checking every subset.
    fn brute_force(g: &Graph, min_size: usize) -> Vec<Vec<u32>> {
        let n = g.len();
        let linked = |a: usize, b: usize| g.weight(a, b).is_some();
        let is_clique = |m: u32| {
            (0..n)
                .all(|a| m & (1 << a) == 0 || (a + 1..n).all(|b| m & (1 << b) == 0 || linked(a, b)))
        };
        let mut out = Vec::new();
        for m in 1u32..(1 << n) {
            if (m.count_ones() as usize) < min_size || !is_clique(m) {
                continue;
            }
            let maximal = (0..n).all(|v| m & (1 << v) != 0 || !is_clique(m | (1 << v)));
            if maximal {
                out.push((0..n as u32).filter(|&v| m & (1 << v) != 0).collect());
            }
        }
        out
    }

    #[test]
    fn enumeration_matches_brute_force_on_random_graphs() {
        for seed in 0..40 {
            let n = 6 + (seed as usize % 9);
            let p = [0.2, 0.5, 0.8][seed as usize % 3];
            let g = random_graph(n, p, seed);
            for min_size in [1, 3] {
                let mut got = maximal_cliques(&g, min_size);
                got.sort();
                let mut want = brute_force(&g, min_size);
                want.sort();
                assert_eq!(got, want, "seed {seed} min_size {min_size}");
            }
        }
    }

    #[test]
    fn node_guided_keeps_each_nodes_heaviest_clique() {
        let g = random_graph(14, 0.6, 99);
        let all = maximal_cliques(&g, 3);
        let sel = node_guided(
            &g,
            CliqueLimits {
                min_size: 3,
                max_cliques: usize::MAX,
                deadline: None,
            },
            usize::MAX,
        );
        assert_eq!(sel.found, all.len());
        assert!(!sel.truncated);
        for v in 0..14u32 {
            let best = all
                .iter()
                .filter(|c| c.contains(&v))
                .map(|c| clique_weight(&g, c))
                .fold(f64::NEG_INFINITY, f64::max);
            if best.is_finite() {
                assert!(sel
                    .cliques
                    .iter()
                    .any(|(c, w)| c.contains(&v) && (w - best).abs() < 1e-9));
            }
        }
        assert!(sel.cliques.windows(2).all(|w| w[0].1 >= w[1].1));
    }

    #[test]
    fn clique_cap_stops_enumeration() {
        let g = random_graph(60, 0.7, 7);
        let sel = node_guided(
            &g,
            CliqueLimits {
                min_size: 3,
                max_cliques: 50,
                deadline: None,
            },
            10,
        );
        assert!(sel.truncated);
        // The cap is checked after each chunk of start vertices: the enumeration stops within
        // one chunk of reaching it, short of every clique.
        let all = maximal_cliques(&g, 3).len();
        assert!(sel.found >= 50 && sel.found < all, "{} of {all}", sel.found);
    }

    /// The same cliques, the same count, whatever the threads do (a shared counter checked
    /// inside the recursion let their timing decide which cliques a capped search found).
    #[test]
    fn capped_search_is_repeatable() {
        let g = random_graph(200, 0.3, 11);
        let limits = CliqueLimits {
            min_size: 3,
            max_cliques: 500,
            deadline: None,
        };
        let first = node_guided(&g, limits, 20);
        assert!(first.truncated);
        for _ in 0..20 {
            let again = node_guided(&g, limits, 20);
            assert_eq!(again.found, first.found);
            assert_eq!(again.cliques, first.cliques);
        }
    }
}

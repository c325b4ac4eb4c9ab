//! Nearest-neighbour queries over a fixed set of points (kiddo's immutable k-d tree).
//!
//! Results are ordered by distance, ties by point index, and the distances are recomputed from
//! the coordinates as `(dx² + dy²) + dz²` (the order FLANN/nanoflann use), so answers do not
//! depend on the tree's internal layout. When several points tie at the k-th distance, the
//! lowest indices are taken.
use std::num::NonZeroUsize;

use kiddo::{Eytzinger, ImmutableKdTree, QueryScratch, SquaredEuclidean};
use nalgebra::Point3;
use rayon::prelude::*;

use super::{dist2, in_index_order};

/// One neighbour: its index in the indexed points and its squared distance to the query.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbour {
    /// Index into the points the index was built from.
    pub index: usize,
    /// Squared Euclidean distance (mm²).
    pub dist2: f64,
}

/// Per-worker reusable state of [`Neighbours::knn_dist2_into`].
#[derive(Default)]
pub struct KnnScratch {
    stack: QueryScratch<Eytzinger, f64, 3>,
    previous: Option<([f64; 3], f64)>,
    k: usize,
}

/// A k-d tree over points, for k-nearest, radius and nearest-one queries.
pub struct Neighbours {
    tree: ImmutableKdTree<f64, 3>,
    points: Vec<[f64; 3]>,
}

impl std::fmt::Debug for Neighbours {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Neighbours({} points)", self.points.len())
    }
}

fn ordered(mut found: Vec<Neighbour>) -> Vec<Neighbour> {
    found.sort_unstable_by(|a, b| a.dist2.total_cmp(&b.dist2).then(a.index.cmp(&b.index)));
    found
}

impl Neighbours {
    /// Indexes `points` (any number, including none; coordinates must be finite).
    pub fn new(points: &[Point3<f64>]) -> Self {
        let points: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = ImmutableKdTree::new_from_slice(&points)
            .expect("more than u32::MAX points cannot be indexed");
        Neighbours { tree, points }
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when no point is indexed.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    fn measured(&self, q: &[f64; 3], items: impl Iterator<Item = u32>) -> Vec<Neighbour> {
        items
            .map(|i| Neighbour {
                index: i as usize,
                dist2: dist2(q, &self.points[i as usize]),
            })
            .collect()
    }

    /// The `k` nearest points to `q` (fewer when the index holds fewer), nearest first; a query
    /// point that is itself indexed comes back at distance 0.
    pub fn knn(&self, q: &Point3<f64>, k: usize) -> Vec<Neighbour> {
        self.knn_within(q, k, f64::INFINITY)
    }

    /// The `k` nearest points to `q` within `radius` (inclusive), nearest first.
    pub fn knn_within(&self, q: &Point3<f64>, k: usize, radius: f64) -> Vec<Neighbour> {
        let Some(want) = NonZeroUsize::new(k.min(self.len())) else {
            return Vec::new();
        };
        let q = [q.x, q.y, q.z];
        // One extra answer tells whether the k-th distance is tied with the next.
        let extra = NonZeroUsize::new((want.get() + 1).min(self.len())).unwrap_or(want);
        let r2 = radius * radius;
        let raw = self
            .tree
            .query(&q)
            .nearest_n::<SquaredEuclidean<f64>>(extra)
            .execute();
        let mut found = ordered(self.measured(&q, raw.iter().map(|r| r.item)));
        found.retain(|n| n.dist2 <= r2);
        if found.len() > want.get() {
            let kth = found[want.get() - 1].dist2;
            if found[want.get()].dist2 == kth {
                // A tie at the cut: take every point at that distance, keep the lowest indices.
                found = self.within2(&q, kth);
            }
            found.truncate(want.get());
        }
        found
    }

    /// Point indices in the tree's leaf order: neighbouring points come close together, so
    /// queries issued in this order reuse the cache (several times faster on shuffled clouds).
    pub fn spatial_order(&self) -> Vec<usize> {
        self.tree.iter().map(|(i, _)| i as usize).collect()
    }

    /// `f(scratch, i)` for every indexed point `i`, in parallel (rayon), visited in
    /// [`spatial_order`](Self::spatial_order) for speed; results come back in index order.
    /// `init` makes each worker's scratch.
    pub fn par_map_points<R, S, I, F>(&self, init: I, f: F) -> Vec<R>
    where
        R: Send,
        I: Fn() -> S + Sync + Send,
        F: Fn(&mut S, usize) -> R + Sync + Send,
    {
        let order = self.spatial_order();
        let values: Vec<R> = order.par_iter().map_init(init, |s, &i| f(s, i)).collect();
        in_index_order(order.into_iter(), values)
    }

    /// The indexed point `i`.
    pub fn point(&self, i: usize) -> Point3<f64> {
        Point3::from(self.points[i])
    }

    /// Squared distances to the `k` nearest points, ascending, into `out` (cleared first). The
    /// fast path for statistics that need distances only (no tie resolution is needed: the
    /// k smallest distances are the same whichever tied point is taken). `scratch` carries
    /// the previous query of the same worker: its k-th distance plus the step between the
    /// two queries bounds this query's search (triangle inequality), which is exact and saves
    /// much of the search when queries come in [`spatial_order`](Self::spatial_order).
    pub fn knn_dist2_into(
        &self,
        q: &Point3<f64>,
        k: usize,
        scratch: &mut KnnScratch,
        out: &mut Vec<f64>,
    ) {
        out.clear();
        let Some(want) = NonZeroUsize::new(k.min(self.len())) else {
            return;
        };
        let q = [q.x, q.y, q.z];
        let bound = match scratch.previous {
            Some((p, kth2)) if scratch.k == want.get() => {
                let r = kth2.sqrt() + dist2(&p, &q).sqrt();
                // Slack for rounding: a bound a little too wide costs nothing.
                r * r * (1.0 + 1e-9) + f64::MIN_POSITIVE
            }
            _ => f64::INFINITY,
        };
        let raw = self
            .tree
            .query(&q)
            .nearest_n::<SquaredEuclidean<f64>>(want)
            .within(bound)
            .with_scratch(&mut scratch.stack)
            .execute();
        out.extend(raw.iter().map(|r| dist2(&q, &self.points[r.item as usize])));
        out.sort_unstable_by(f64::total_cmp);
        scratch.k = want.get();
        scratch.previous = out.last().map(|&d| (q, d));
    }

    /// Every point within `radius` of `q` (inclusive), nearest first.
    pub fn within(&self, q: &Point3<f64>, radius: f64) -> Vec<Neighbour> {
        self.within2(&[q.x, q.y, q.z], radius * radius)
    }

    /// Every point within `radius` of `q` (inclusive), in the tree's order (cheaper than
    /// [`Neighbours::within`] when the caller does not need the distance order; still
    /// deterministic for a given index).
    pub fn within_unsorted(&self, q: &Point3<f64>, radius: f64) -> Vec<Neighbour> {
        self.within_raw(&[q.x, q.y, q.z], radius * radius)
    }

    fn within2(&self, q: &[f64; 3], r2: f64) -> Vec<Neighbour> {
        ordered(self.within_raw(q, r2))
    }

    fn within_raw(&self, q: &[f64; 3], r2: f64) -> Vec<Neighbour> {
        if self.is_empty() || r2.is_nan() || r2 < 0.0 {
            return Vec::new();
        }
        // Widen kiddo's bound a hair so our own (re-computed) distances decide the boundary.
        let raw = self
            .tree
            .query(q)
            .within::<SquaredEuclidean<f64>>(r2 * (1.0 + 1e-12) + f64::MIN_POSITIVE)
            .unsorted()
            .execute();
        let mut found = self.measured(q, raw.iter().map(|r| r.item));
        found.retain(|n| n.dist2 <= r2);
        found
    }

    /// The nearest point to `q` (lowest index on a tie); None when the index is empty.
    pub fn nearest(&self, q: &Point3<f64>) -> Option<Neighbour> {
        self.knn(q, 1).into_iter().next()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::fixtures::lattice_and_noise;

    fn brute(points: &[Point3<f64>], q: &Point3<f64>) -> Vec<Neighbour> {
        let all = points
            .iter()
            .enumerate()
            .map(|(i, p)| Neighbour {
                index: i,
                dist2: dist2(&[q.x, q.y, q.z], &[p.x, p.y, p.z]),
            })
            .collect();
        ordered(all)
    }

    #[test]
    fn knn_and_radius_match_brute_force_with_ties() {
        // A grid (many exact ties) plus random points.
        let points = lattice_and_noise(7, 300);
        let index = Neighbours::new(&points);
        for q in points.iter().step_by(5) {
            let all = brute(&points, q);
            for k in [1, 6, 7, 19, 27] {
                assert_eq!(index.knn(q, k), all[..k].to_vec());
            }
            let r = 1.5;
            let inside: Vec<_> = all.iter().copied().filter(|n| n.dist2 <= r * r).collect();
            assert_eq!(index.within(q, r), inside);
            let capped = index.knn_within(q, 4, r);
            assert_eq!(capped, inside[..inside.len().min(4)].to_vec());
        }
        assert_eq!(index.nearest(&Point3::new(0.1, 0.0, 0.0)).unwrap().index, 0);
        let mut order = index.spatial_order();
        order.sort_unstable();
        assert_eq!(order, (0..points.len()).collect::<Vec<_>>());
    }

    #[test]
    fn empty_and_small_indexes() {
        let empty = Neighbours::new(&[]);
        assert!(empty.knn(&Point3::origin(), 3).is_empty());
        assert!(empty.within(&Point3::origin(), 1.0).is_empty());
        assert!(empty.nearest(&Point3::origin()).is_none());
        let two = Neighbours::new(&[Point3::origin(), Point3::new(1.0, 0.0, 0.0)]);
        assert_eq!(two.knn(&Point3::origin(), 5).len(), 2);
    }
}

//! The k nearest points of many queries at once, exactly as [`Grid::knn`] answers each.
//!
//! The queries are taken row by row from a second grid (or the same one), in runs of about a
//! cell along x. A run gathers its candidates once: the points in its bounding box widened by
//! a halo. Each query then keeps the candidates within its proof radius, the distance from the
//! query to the nearest side of that box (nothing beyond it is closer), tightened by the
//! previous query's k-th distance plus the step between the two (triangle inequality). A
//! query left with fewer than k such candidates searches a box around itself alone, as wide
//! as the k-th candidate distance (an upper bound) or, with too few candidates, twice as wide
//! each time.
use std::ops::Range;

use nalgebra::Point3;
use rayon::prelude::*;

use super::candidates::{settle, Area, Candidates, Limits};
use super::Grid;
use crate::spatial::{dist2, in_index_order};

/// Halo around a run, in units of the typical k-th distance (larger: fewer queries need a
/// search of their own; smaller: fewer candidates per run). The outlier filter (k = 21) of
/// the 303k-point peer scan: 1.3 took 0.245 s, 1.1 0.185 s, 1.0 0.195 s (medians of 8
/// interleaved runs); of the synthetic 300k / 1M peer clouds 0.18 / 0.73 s at 1.3, 0.17 /
/// 0.70 s at 1.1.
const HALO: f64 = 1.1;
/// A query's k-th squared distance is first guessed as this times the previous query's.
const GUESS: f64 = 1.2;

/// What every query of a batch asks: its `k` nearest points within `max_radius` (`max2` its
/// square), candidates gathered `halo` around each run; `f` makes the answer from them.
struct Ask<'a, F> {
    k: usize,
    max_radius: f64,
    max2: f64,
    halo: f64,
    f: &'a F,
}

/// Per-worker buffers.
#[derive(Default)]
struct Scratch {
    ranges: Vec<Range<usize>>,
    /// Per row of this grid near the query row: slice start, slice end, row end, and
    /// whether the row lies inside the run's box across x.
    cursors: Vec<(usize, usize, usize, bool)>,
    /// Candidates of the current run.
    run: Candidates,
    /// Candidates of a single query's own search.
    single: Candidates,
    /// Sort keys (see `candidates::sort`).
    keys: Vec<u64>,
    /// Sorted neighbours being assembled.
    sorted: Vec<(f64, u32)>,
    found: Vec<(f64, u32)>,
}

impl Grid {
    /// `f(point, neighbours)` for every point of `points`, where `neighbours` are its `k`
    /// nearest among `points` within `max_radius` (inclusive; infinity for no limit), as
    /// [`Grid::knn_each`] gives them (the point itself included, nearest first, ties to the
    /// lowest index); results in the order of `points`.
    pub fn knn_among<R, F>(points: &[Point3<f64>], k: usize, max_radius: f64, f: F) -> Vec<R>
    where
        R: Send,
        F: Fn(usize, &[(f64, u32)]) -> R + Sync,
    {
        let (grid, halo) = Grid::for_knn(points, k);
        grid.knn_each(&grid, k, max_radius, halo.min(max_radius), f)
    }

    /// A grid over `points` for their own `k`-nearest-neighbour queries, and the halo to give
    /// [`Grid::knn_each`]: both follow the k-th neighbour distance (only the speed depends on
    /// them).
    fn for_knn(points: &[Point3<f64>], k: usize) -> (Grid, f64) {
        let grid = Grid::for_points(points);
        let typical = grid.typical_kth(points, k);
        if !(typical > 0.0 && typical.is_finite()) {
            let cell = grid.cell;
            return (grid, cell);
        }
        // A cell of about the typical k-th distance; the provisional one when close.
        let halo = typical * HALO;
        if (0.7..1.4).contains(&(typical / grid.cell)) {
            (grid, halo)
        } else {
            (Grid::new(points, typical), halo)
        }
    }

    /// The 90th percentile of the k-th neighbour distance (in this grid) of up to 1,000
    /// evenly spread `queries` (0 when there are none; in parallel): a halo for
    /// [`Grid::knn_each`].
    pub fn typical_kth(&self, queries: &[Point3<f64>], k: usize) -> f64 {
        let step = (queries.len() / 1000).max(1);
        let mut kth: Vec<f64> = (0..queries.len().div_ceil(step))
            .into_par_iter()
            .map_init(Vec::new, |found, i| {
                self.knn(&queries[i * step], k, f64::INFINITY, found);
                found.last().map(|e| e.0.sqrt())
            })
            .flatten()
            .collect();
        kth.sort_by(f64::total_cmp);
        kth.get(kth.len() * 9 / 10).copied().unwrap_or(0.0)
    }

    /// `f(query, neighbours)` for every point of `queries` (`query`: its index in the points
    /// `queries` was built from), where `neighbours` are the `k` nearest points of this grid
    /// within `max_radius` (inclusive; infinity for no limit) as (squared distance, index),
    /// nearest first, ties to the lowest index: exactly what [`Grid::knn`] returns. In
    /// parallel; results in the order of the points `queries` was built from. `halo` (mm):
    /// how far around a run of queries candidates are gathered, about the typical k-th
    /// distance (any positive value gives the same answers).
    pub fn knn_each<R, F>(
        &self,
        queries: &Grid,
        k: usize,
        max_radius: f64,
        halo: f64,
        f: F,
    ) -> Vec<R>
    where
        R: Send,
        F: Fn(usize, &[(f64, u32)]) -> R + Sync,
    {
        // A halo of nothing would leave every query to its own search.
        let halo = if halo > 0.0 && halo.is_finite() {
            halo
        } else {
            self.cell
        };
        let ask = Ask {
            k,
            max_radius,
            max2: max_radius * max_radius,
            halo,
            f: &f,
        };
        let planes = queries.dims[2].max(0) as usize;
        let stored: Vec<R> = (0..planes)
            .into_par_iter()
            .flat_map_iter(|z| {
                let mut scratch = Scratch::default();
                let mut out = Vec::new();
                for y in 0..queries.dims[1] {
                    let r = (y + queries.dims[1] * z as isize) as usize;
                    let rows = queries.rows[r] as usize..queries.rows[r + 1] as usize;
                    let cell = (y, z as isize);
                    self.knn_row(queries, cell, rows, &ask, &mut scratch, &mut out);
                }
                out
            })
            .collect();
        if queries.numbered_in_storage_order() {
            return stored;
        }
        in_index_order(queries.ids.iter().map(|&i| i as usize), stored)
    }

    /// One row of queries (row `cell` of `queries`, its stored points `row`), appending
    /// `ask.f`'s results.
    fn knn_row<R, F>(
        &self,
        queries: &Grid,
        cell: (isize, isize),
        row: Range<usize>,
        ask: &Ask<'_, F>,
        scratch: &mut Scratch,
        out: &mut Vec<R>,
    ) where
        F: Fn(usize, &[(f64, u32)]) -> R,
    {
        let halo = ask.halo;
        let mut area = self.row_box(queries, cell, halo, &mut scratch.cursors);
        // The previous query and its k-th squared distance, while it had k neighbours.
        let mut previous: Option<([f64; 3], f64)> = None;
        let mut start = row.start;
        while start < row.end {
            // A run: the queries within one cell along x.
            let x_end = queries.xs[start] + queries.cell;
            let mut end = start + 1;
            while end < row.end && queries.xs[end] <= x_end {
                end += 1;
            }
            let run = &queries.pts[start..end];
            let (lo, hi) = (queries.xs[start] - halo, queries.xs[end - 1] + halo);
            (area.lo[0], area.hi[0]) = (lo, hi);
            (area.lo_open[0], area.hi_open[0]) = (lo < self.origin[0], hi > self.hi[0]);
            self.gather_run(&area, &mut scratch.cursors, &mut scratch.run);
            for (q, &id) in run.iter().zip(&queries.ids[start..end]) {
                self.knn_in_run(q, &area, ask, &mut previous, scratch);
                out.push((ask.f)(id as usize, &scratch.found));
            }
            start = end;
        }
    }

    /// The box of a row of queries (row `cell` of `queries`) across x: its cells widened by
    /// `halo`, sides open where no point of this grid lies beyond (x is set per run). Sets
    /// `cursors` to this grid's rows that meet it, each with a cursor pair (start and end of
    /// the slice of the current run, see [`Grid::gather_run`]) and whether the row lies inside
    /// the box (with rounding slack) and is taken whole.
    fn row_box(
        &self,
        queries: &Grid,
        cell: (isize, isize),
        halo: f64,
        cursors: &mut Vec<(usize, usize, usize, bool)>,
    ) -> Area {
        let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
        for (a, i) in [(1, cell.0), (2, cell.1)] {
            lo[a] = queries.origin[a] + i as f64 * queries.cell - halo;
            hi[a] = queries.origin[a] + (i + 1) as f64 * queries.cell + halo;
        }
        let band = |a: usize| {
            (
                self.coord(lo[a], a).max(0),
                self.coord(hi[a], a).min(self.dims[a] - 1),
            )
        };
        let ((y0, y1), (z0, z1)) = (band(1), band(2));
        let slack = |a: usize| {
            1e-9 * self.cell + 1e-12 * (self.origin[a].abs() + self.dims[a] as f64 * self.cell)
        };
        let side = |a: usize, i: isize| self.origin[a] + i as f64 * self.cell;
        let inside = |a: usize, i: isize| {
            side(a, i) - slack(a) >= lo[a] && side(a, i + 1) + slack(a) <= hi[a]
        };
        cursors.clear();
        for z in z0..=z1 {
            for y in y0..=y1 {
                let r = (y + self.dims[1] * z) as usize;
                let (a, b) = (self.rows[r] as usize, self.rows[r + 1] as usize);
                if a < b {
                    cursors.push((a, a, b, inside(1, y) && inside(2, z)));
                }
            }
        }
        let (mut lo_open, mut hi_open) = ([false; 3], [false; 3]);
        for a in 1..3 {
            (lo_open[a], hi_open[a]) = (lo[a] < self.origin[a], hi[a] > self.hi[a]);
        }
        Area {
            lo,
            hi,
            lo_open,
            hi_open,
        }
    }

    /// The candidates of a run whose box is `area`, into `c`: each cursor pair moves forward
    /// to the slice of its row with x in the box; points of a row not taken whole are kept
    /// only when inside the box across x (fewer candidates per query).
    fn gather_run(
        &self,
        area: &Area,
        cursors: &mut [(usize, usize, usize, bool)],
        c: &mut Candidates,
    ) {
        let (lo, hi) = (&area.lo, &area.hi);
        c.clear();
        for (a, b, e, whole) in cursors.iter_mut() {
            while *a < *e && self.xs[*a] < lo[0] {
                *a += 1;
            }
            *b = (*b).max(*a);
            while *b < *e && self.xs[*b] <= hi[0] {
                *b += 1;
            }
            match whole {
                true => c.push(self, *a..*b),
                false => c.push_within(self, *a..*b, lo, hi),
            }
        }
    }

    /// The neighbours of query `q` into `scratch.found`: among its run's candidates (box
    /// `area`) when they prove to hold them, bounded by the `previous` query's k-th distance
    /// plus the step between the two; otherwise by a search around `q` alone, widened until it
    /// settles. Updates `previous`.
    fn knn_in_run<F>(
        &self,
        q: &[f64; 3],
        area: &Area,
        ask: &Ask<'_, F>,
        previous: &mut Option<([f64; 3], f64)>,
        scratch: &mut Scratch,
    ) {
        let (bound, guess) = match *previous {
            Some((p, kth2)) => {
                let r = kth2.sqrt() + dist2(&p, q).sqrt();
                (r * r * (1.0 + 1e-9) + f64::MIN_POSITIVE, kth2 * GUESS)
            }
            None => (f64::INFINITY, f64::INFINITY),
        };
        let Scratch {
            ranges,
            run: run_candidates,
            single,
            keys,
            found,
            sorted,
            ..
        } = scratch;
        let limits = Limits {
            k: ask.k,
            max2: ask.max2,
            bound,
            guess,
        };
        let mut outcome = settle(q, area, run_candidates, &limits, keys, found, sorted);
        let mut r = ask.halo;
        let alone = Limits {
            bound: f64::INFINITY,
            guess: f64::INFINITY,
            ..limits
        };
        while let Err(hint) = outcome {
            r = hint.unwrap_or(2.0 * r).min(ask.max_radius) * (1.0 + 1e-6) + f64::MIN_POSITIVE;
            let lo = q.map(|v| v - r);
            let hi = q.map(|v| v + r);
            self.gather(&lo, &hi, ranges, single);
            let area = Area::new(self, lo, hi);
            outcome = settle(q, &area, single, &alone, keys, found, sorted);
        }
        let k = ask.k;
        *previous = (found.len() == k).then(|| (*q, found[k - 1].0));
    }

    /// The points of the rows that meet the box [lo, hi], with x in [lo.x, hi.x], into
    /// `out` (`ranges`: scratch).
    fn gather(
        &self,
        lo: &[f64; 3],
        hi: &[f64; 3],
        ranges: &mut Vec<Range<usize>>,
        out: &mut Candidates,
    ) {
        self.slices(lo, hi, ranges);
        out.clear();
        for range in ranges.iter() {
            out.push(self, range.clone());
        }
    }

    /// The stored-point slices of the rows that meet the box [lo, hi], each cut to x in
    /// [lo.x, hi.x], into `out` (cleared first).
    fn slices(&self, lo: &[f64; 3], hi: &[f64; 3], out: &mut Vec<Range<usize>>) {
        out.clear();
        let (y0, y1) = (self.coord(lo[1], 1).max(0), self.coord(hi[1], 1));
        let (z0, z1) = (self.coord(lo[2], 2).max(0), self.coord(hi[2], 2));
        for z in z0..=z1.min(self.dims[2] - 1) {
            for y in y0..=y1.min(self.dims[1] - 1) {
                let range = self.row(y, z, lo[0], hi[0]);
                if !range.is_empty() {
                    out.push(range);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::fixtures::{lattice, uniform};
    use rand::{Rng, SeedableRng};

    #[test]
    fn batch_knn_equals_single_queries() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        // A lattice (exact ties, duplicates) plus a noisy sheet and scattered points.
        let mut points: Vec<Point3<f64>> = lattice().into_iter().map(|p| p * 0.5).collect();
        points.extend_from_within(..40);
        points.extend((0..3000).map(|_| {
            let (u, v): (f64, f64) = (rng.gen(), rng.gen());
            Point3::new(
                u * 6.0,
                v * 6.0,
                0.3 * (u * 5.0).sin() + rng.gen::<f64>() * 0.01,
            )
        }));
        points.extend(uniform(&mut rng, 60, 9.0));
        let queries = uniform(&mut rng, 800, 8.0);
        for cell in [0.05, 0.2, 0.7] {
            let grid = Grid::new(&points, cell);
            let other = Grid::new(&queries, cell * 1.3);
            for (k, max_radius, halo) in [(1, f64::INFINITY, 0.1), (8, 0.4, 0.2), (21, 9.0, 0.05)] {
                let mut want = Vec::new();
                let own = grid.knn_each(&grid, k, max_radius, halo, |_, n| {
                    (n.len(), n.last().copied().unwrap_or((-1.0, 0)))
                });
                for (i, p) in points.iter().enumerate() {
                    grid.knn(p, k, max_radius, &mut want);
                    let w = (want.len(), want.last().copied().unwrap_or((-1.0, 0)));
                    assert_eq!(own[i], w, "own point {i}, cell {cell}, k {k}");
                }
                let sums = grid.knn_each(&other, k, max_radius, halo, |_, n| {
                    n.iter().map(|e| e.0 + e.1 as f64).sum::<f64>()
                });
                for (i, q) in queries.iter().enumerate() {
                    grid.knn(q, k, max_radius, &mut want);
                    let w: f64 = want.iter().map(|e| e.0 + e.1 as f64).sum();
                    assert_eq!(sums[i], w, "query {i}, cell {cell}, k {k}");
                }
                // Queries renumbered in storage order: answers per slot.
                let mut renumbered = Grid::new(&queries, cell * 1.3);
                let original = renumbered.renumber();
                assert!(renumbered.numbered_in_storage_order());
                let slot_sums = grid.knn_each(&renumbered, k, max_radius, halo, |_, n| {
                    n.iter().map(|e| e.0 + e.1 as f64).sum::<f64>()
                });
                for (slot, &i) in original.iter().enumerate() {
                    assert_eq!(slot_sums[slot], sums[i as usize], "slot {slot}, k {k}");
                }
            }
        }
    }
}

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

use super::{dist2, Grid};

/// Halo around a run, in units of the typical k-th distance (larger: fewer queries need a
/// search of their own; smaller: fewer candidates per run). The outlier filter (k = 21) of
/// the 303k-point peer scan: 1.3 took 0.245 s, 1.1 0.185 s, 1.0 0.195 s (medians of 8
/// interleaved runs); of the synthetic 300k / 1M peer clouds 0.18 / 0.73 s at 1.3, 0.17 /
/// 0.70 s at 1.1.
const HALO: f64 = 1.1;
/// A query's k-th squared distance is first guessed as this times the previous query's.
const GUESS: f64 = 1.2;

/// Candidate points, coordinates apart (the distance loop vectorises).
#[derive(Default)]
struct Candidates {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    id: Vec<u32>,
}

impl Candidates {
    fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.id.clear();
    }

    /// Appends the stored points `range` of `grid`.
    #[inline]
    fn push(&mut self, grid: &Grid, range: Range<usize>) {
        self.x.extend_from_slice(&grid.xs[range.clone()]);
        self.y.extend_from_slice(&grid.ys[range.clone()]);
        self.z.extend_from_slice(&grid.zs[range.clone()]);
        self.id.extend_from_slice(&grid.ids[range]);
    }

    /// Appends those of the stored points `range` of `grid` whose y and z lie within
    /// `lo`..=`hi` (indices 1 and 2; x is not looked at).
    #[inline]
    fn push_within(&mut self, grid: &Grid, range: Range<usize>, lo: &[f64; 3], hi: &[f64; 3]) {
        for i in range {
            let (y, z) = (grid.ys[i], grid.zs[i]);
            if y >= lo[1] && y <= hi[1] && z >= lo[2] && z <= hi[2] {
                self.x.push(grid.xs[i]);
                self.y.push(y);
                self.z.push(z);
                self.id.push(grid.ids[i]);
            }
        }
    }
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
    /// Squared distances from the query to each candidate.
    /// Sort keys (see [`sort`]).
    keys: Vec<u64>,
    /// Sorted neighbours being assembled.
    sorted: Vec<(f64, u32)>,
    found: Vec<(f64, u32)>,
}

/// Orders neighbours by distance, then index (as [`Grid::knn`]): squared distances are
/// never negative, so their bits order as they do.
#[inline]
fn key(e: &(f64, u32)) -> u128 {
    (e.0.to_bits() as u128) << 32 | e.1 as u128
}

/// Bits of a squared distance given over to a position in [`sort`].
const POSITION_BITS: u32 = 12;

/// `found` in [`key`] order, into `sorted`. The sort runs on single integers (cheaper than
/// pairs): a squared distance's bits (ordered as the values, never negative) with the lowest
/// bits replaced by the element's position; an insertion pass then settles the order of
/// distances that agreed in all other bits (it moves nothing on ordered input).
fn sort(found: &[(f64, u32)], keys: &mut Vec<u64>, sorted: &mut Vec<(f64, u32)>) {
    sorted.clear();
    if found.len() >= 1 << POSITION_BITS {
        sorted.extend_from_slice(found);
        sorted.sort_unstable_by_key(key);
        return;
    }
    let low = (1u64 << POSITION_BITS) - 1;
    keys.clear();
    keys.extend(
        found
            .iter()
            .enumerate()
            .map(|(i, e)| e.0.to_bits() & !low | i as u64),
    );
    keys.sort_unstable();
    sorted.extend(keys.iter().map(|&h| found[(h & low) as usize]));
    for i in 1..sorted.len() {
        let e = sorted[i];
        let mut j = i;
        while j > 0 && key(&sorted[j - 1]) > key(&e) {
            sorted[j] = sorted[j - 1];
            j -= 1;
        }
        sorted[j] = e;
    }
}

/// The candidates within `threshold` (squared distance) of `q`, into `found` in their order:
/// one pass over all of them (cheaper than pruning by row for the few dozen a query has),
/// four at a time where the CPU has AVX2.
fn take_under(q: &[f64; 3], c: &Candidates, threshold: f64, found: &mut Vec<(f64, u32)>) {
    found.clear();
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 was just detected on this CPU.
        let done = unsafe { take_under_avx2(q, c, threshold, found) };
        return take_under_from(done, q, c, threshold, found);
    }
    take_under_from(0, q, c, threshold, found)
}

/// [`take_under`]'s pass from candidate `first` on (appending).
fn take_under_from(
    first: usize,
    q: &[f64; 3],
    c: &Candidates,
    threshold: f64,
    found: &mut Vec<(f64, u32)>,
) {
    let n = c.id.len();
    let (xs, ys, zs, ids) = (&c.x[..n], &c.y[..n], &c.z[..n], &c.id[..n]);
    for j in first..n {
        // The summation order of `dist2` (FLANN's): bit-identical distances.
        let (dx, dy, dz) = (q[0] - xs[j], q[1] - ys[j], q[2] - zs[j]);
        let d = dx * dx + dy * dy + dz * dz;
        if d <= threshold {
            found.push((d, ids[j]));
        }
    }
}

/// [`take_under`]'s pass over the candidates in groups of four with AVX2 (the same
/// operations in the same order as the portable pass, no FMA: bit-identical distances);
/// returns how many candidates it went through (the rest, fewer than four, are left).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn take_under_avx2(
    q: &[f64; 3],
    c: &Candidates,
    threshold: f64,
    found: &mut Vec<(f64, u32)>,
) -> usize {
    use std::arch::x86_64::*;
    let n = c.id.len();
    let (xs, ys, zs, ids) = (&c.x[..n], &c.y[..n], &c.z[..n], &c.id[..n]);
    let (qx, qy, qz) = (
        _mm256_set1_pd(q[0]),
        _mm256_set1_pd(q[1]),
        _mm256_set1_pd(q[2]),
    );
    let limit = _mm256_set1_pd(threshold);
    let mut d = [0.0; 4];
    let groups = n / 4 * 4;
    for j in (0..groups).step_by(4) {
        // SAFETY: j + 4 <= n, the length of each coordinate slice.
        let (x, y, z) = unsafe {
            (
                _mm256_loadu_pd(xs.as_ptr().add(j)),
                _mm256_loadu_pd(ys.as_ptr().add(j)),
                _mm256_loadu_pd(zs.as_ptr().add(j)),
            )
        };
        let (dx, dy, dz) = (
            _mm256_sub_pd(qx, x),
            _mm256_sub_pd(qy, y),
            _mm256_sub_pd(qz, z),
        );
        let dist = _mm256_add_pd(
            _mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
            _mm256_mul_pd(dz, dz),
        );
        // Ordered compare: a NaN distance is not taken, as in the portable pass.
        let mut mask = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(dist, limit));
        if mask != 0 {
            // SAFETY: d holds four f64.
            unsafe { _mm256_storeu_pd(d.as_mut_ptr(), dist) };
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                found.push((d[lane], ids[j + lane]));
                mask &= mask - 1;
            }
        }
    }
    groups
}

/// A box that candidates were gathered from; sides beyond the grid's points are open
/// (nothing lies past them).
struct Area {
    lo: [f64; 3],
    hi: [f64; 3],
    lo_open: [bool; 3],
    hi_open: [bool; 3],
}

impl Area {
    fn new(grid: &Grid, lo: [f64; 3], hi: [f64; 3]) -> Area {
        Area {
            lo,
            hi,
            lo_open: [0, 1, 2].map(|a| lo[a] < grid.origin[a]),
            hi_open: [0, 1, 2].map(|a| hi[a] > grid.hi[a]),
        }
    }

    /// Distance from `q` to the nearest closed side (0 when outside).
    #[inline]
    fn margin(&self, q: &[f64; 3]) -> f64 {
        let mut margin = f64::INFINITY;
        for (a, &v) in q.iter().enumerate() {
            if !self.lo_open[a] {
                margin = margin.min(v - self.lo[a]);
            }
            if !self.hi_open[a] {
                margin = margin.min(self.hi[a] - v);
            }
        }
        margin.max(0.0)
    }
}

/// What a query may take: `k` neighbours within `max2` (squared); `bound`: a proven upper
/// bound on the k-th squared distance; `guess`: a likely one, tried first.
struct Limits {
    k: usize,
    max2: f64,
    bound: f64,
    guess: f64,
}

/// The nearest `candidates` of `area` to `q` (see [`Limits`]) into `s.found`, when they are
/// provably the nearest of all points: those within the distance from `q` to the area's
/// closed sides. Otherwise an upper bound on the k-th distance when the candidates give one.
fn settle(
    q: &[f64; 3],
    area: &Area,
    c: &Candidates,
    lim: &Limits,
    keys: &mut Vec<u64>,
    found: &mut Vec<(f64, u32)>,
    sorted: &mut Vec<(f64, u32)>,
) -> Result<(), Option<f64>> {
    let k = lim.k;
    let margin = area.margin(q);
    // Every point whose computed squared distance is <= `proven` is a candidate.
    let proven = margin * margin * (1.0 - 1e-12);
    let limit = proven.min(lim.bound).min(lim.max2);
    // With fewer than k points within `max2`, all of them when `max2` is the binding limit.
    let all_within_max = lim.max2 <= proven && lim.max2 <= lim.bound;
    let guess = lim.guess.min(limit);
    let thresholds = [guess, limit];
    let tries = if guess < limit {
        &thresholds[..]
    } else {
        &thresholds[1..]
    };
    for &threshold in tries {
        take_under(q, c, threshold, found);
        let n = found.len();
        if n >= k || (threshold == limit && all_within_max) {
            sort(found, keys, sorted);
            std::mem::swap(found, sorted);
            found.truncate(k);
            return Ok(());
        }
    }
    let m = c.id.len();
    keys.clear();
    keys.extend((0..m).map(|j| dist2(q, &[c.x[j], c.y[j], c.z[j]]).to_bits()));
    // The k-th distance among all candidates bounds the true one.
    if m < k {
        return Err(None);
    }
    let kth = f64::from_bits(*keys.select_nth_unstable(k - 1).1);
    Err(Some(kth.sqrt()))
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
                    self.knn_row(
                        queries,
                        cell,
                        rows,
                        k,
                        max_radius,
                        halo,
                        &mut scratch,
                        &f,
                        &mut out,
                    );
                }
                out
            })
            .collect();
        if queries.numbered_in_storage_order() {
            return stored;
        }
        let mut slots: Vec<Option<R>> = stored.iter().map(|_| None).collect();
        for (&i, v) in queries.ids.iter().zip(stored) {
            slots[i as usize] = Some(v);
        }
        slots
            .into_iter()
            .map(|v| v.expect("every query answered"))
            .collect()
    }

    /// One row of queries (row `cell` of `queries`, its stored points `row`), appending
    /// `f`'s results.
    #[allow(clippy::too_many_arguments)]
    fn knn_row<R, F>(
        &self,
        queries: &Grid,
        cell: (isize, isize),
        row: Range<usize>,
        k: usize,
        max_radius: f64,
        halo: f64,
        scratch: &mut Scratch,
        f: &F,
        out: &mut Vec<R>,
    ) where
        F: Fn(usize, &[(f64, u32)]) -> R,
    {
        let max2 = max_radius * max_radius;
        // The run's box across x: the query row's cells widened by the halo.
        let (mut lo, mut hi) = ([0.0; 3], [0.0; 3]);
        for (a, i) in [(1, cell.0), (2, cell.1)] {
            lo[a] = queries.origin[a] + i as f64 * queries.cell - halo;
            hi[a] = queries.origin[a] + (i + 1) as f64 * queries.cell + halo;
        }
        // This grid's rows that meet it, each with a cursor pair (start and end of the slice
        // of the current run) that only moves forward. Points of those rows outside the box
        // are left out (fewer candidates per query); a row inside it (with rounding slack) is
        // taken whole.
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
        let cursors = &mut scratch.cursors;
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
        // Sides open where no point lies beyond.
        let (mut lo_open, mut hi_open) = ([false; 3], [false; 3]);
        for a in 1..3 {
            (lo_open[a], hi_open[a]) = (lo[a] < self.origin[a], hi[a] > self.hi[a]);
        }
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
            (lo[0], hi[0]) = (queries.xs[start] - halo, queries.xs[end - 1] + halo);
            (lo_open[0], hi_open[0]) = (lo[0] < self.origin[0], hi[0] > self.hi[0]);
            let c = &mut scratch.run;
            c.clear();
            for (a, b, e, whole) in scratch.cursors.iter_mut() {
                while *a < *e && self.xs[*a] < lo[0] {
                    *a += 1;
                }
                *b = (*b).max(*a);
                while *b < *e && self.xs[*b] <= hi[0] {
                    *b += 1;
                }
                match whole {
                    true => c.push(self, *a..*b),
                    false => c.push_within(self, *a..*b, &lo, &hi),
                }
            }
            let area = Area {
                lo,
                hi,
                lo_open,
                hi_open,
            };
            for (q, &id) in run.iter().zip(&queries.ids[start..end]) {
                let (bound, guess) = match previous {
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
                    k,
                    max2,
                    bound,
                    guess,
                };
                let mut outcome = settle(q, &area, run_candidates, &limits, keys, found, sorted);
                let mut r = halo;
                let alone = Limits {
                    bound: f64::INFINITY,
                    guess: f64::INFINITY,
                    ..limits
                };
                while let Err(hint) = outcome {
                    r = hint.unwrap_or(2.0 * r).min(max_radius) * (1.0 + 1e-6) + f64::MIN_POSITIVE;
                    let lo = q.map(|v| v - r);
                    let hi = q.map(|v| v + r);
                    self.gather(&lo, &hi, ranges, single);
                    let area = Area::new(self, lo, hi);
                    outcome = settle(q, &area, single, &alone, keys, found, sorted);
                }
                previous = (found.len() == k).then(|| (*q, found[k - 1].0));
                out.push(f(id as usize, found));
            }
            start = end;
        }
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
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_vector_pass_takes_what_the_portable_pass_takes() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let (mut fast, mut portable) = (Vec::new(), Vec::new());
        for n in 0..40 {
            let mut c = Candidates::default();
            for i in 0..n {
                // Some candidates at exactly the threshold's distance.
                let p: [f64; 3] = match i % 5 {
                    0 => [0.5, 0.0, 0.0],
                    _ => [rng.gen(), rng.gen(), rng.gen()],
                };
                c.x.push(p[0]);
                c.y.push(p[1]);
                c.z.push(p[2]);
                c.id.push(i as u32 * 3);
            }
            take_under(&[0.0; 3], &c, 0.25, &mut fast);
            portable.clear();
            take_under_from(0, &[0.0; 3], &c, 0.25, &mut portable);
            assert_eq!(fast, portable, "{n} candidates");
            assert!(n < 10 || !fast.is_empty());
        }
    }

    #[test]
    fn batch_knn_equals_single_queries() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        // A lattice (exact ties, duplicates) plus a noisy sheet and scattered points.
        let mut points: Vec<Point3<f64>> = (0..343)
            .map(|i| Point3::new((i % 7) as f64, ((i / 7) % 7) as f64, (i / 49) as f64) * 0.5)
            .collect();
        points.extend_from_within(..40);
        points.extend((0..3000).map(|_| {
            let (u, v): (f64, f64) = (rng.gen(), rng.gen());
            Point3::new(
                u * 6.0,
                v * 6.0,
                0.3 * (u * 5.0).sin() + rng.gen::<f64>() * 0.01,
            )
        }));
        points.extend((0..60).map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()) * 9.0));
        let queries: Vec<Point3<f64>> = (0..800)
            .map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()) * 8.0)
            .collect();
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

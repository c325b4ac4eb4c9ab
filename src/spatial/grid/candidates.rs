//! The candidates of a run of queries and how one query settles on its k nearest among them
//! (see `batch`): a vectorised distance pass, a sort on integer keys, and the proof that no
//! point outside the gathered box is nearer.
use std::ops::Range;

use super::Grid;
use crate::spatial::dist2;

/// Candidate points, coordinates apart (the distance loop vectorises).
#[derive(Default)]
pub(super) struct Candidates {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    id: Vec<u32>,
}

impl Candidates {
    pub(super) fn clear(&mut self) {
        self.x.clear();
        self.y.clear();
        self.z.clear();
        self.id.clear();
    }

    /// Appends the stored points `range` of `grid`.
    #[inline]
    pub(super) fn push(&mut self, grid: &Grid, range: Range<usize>) {
        self.x.extend_from_slice(&grid.xs[range.clone()]);
        self.y.extend_from_slice(&grid.ys[range.clone()]);
        self.z.extend_from_slice(&grid.zs[range.clone()]);
        self.id.extend_from_slice(&grid.ids[range]);
    }

    /// Appends those of the stored points `range` of `grid` whose y and z lie within
    /// `lo`..=`hi` (indices 1 and 2; x is not looked at).
    #[inline]
    pub(super) fn push_within(
        &mut self,
        grid: &Grid,
        range: Range<usize>,
        lo: &[f64; 3],
        hi: &[f64; 3],
    ) {
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
pub(super) struct Area {
    pub(super) lo: [f64; 3],
    pub(super) hi: [f64; 3],
    pub(super) lo_open: [bool; 3],
    pub(super) hi_open: [bool; 3],
}

impl Area {
    pub(super) fn new(grid: &Grid, lo: [f64; 3], hi: [f64; 3]) -> Area {
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
pub(super) struct Limits {
    pub(super) k: usize,
    pub(super) max2: f64,
    pub(super) bound: f64,
    pub(super) guess: f64,
}

/// The nearest `candidates` of `area` to `q` (see [`Limits`]) into `s.found`, when they are
/// provably the nearest of all points: those within the distance from `q` to the area's
/// closed sides. Otherwise an upper bound on the k-th distance when the candidates give one.
pub(super) fn settle(
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
}

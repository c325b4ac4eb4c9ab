//! Exact nearest neighbours among FPFH descriptors by a blocked brute-force scan.
//!
//! In 33 dimensions a k-d tree visits nearly every leaf anyway (measured: kiddo's 33-D tree
//! was no faster than a plain scan), so the scan is made cheap instead: descriptors are packed
//! eight at a time dimension-major (one SIMD register per dimension), four queries share each
//! load, and the reference descriptors are walked in tiles that stay in the L2 cache. On x86-64
//! CPUs with AVX2 and FMA a compiled-for-AVX2 copy of the same loop runs (chosen at run time);
//! elsewhere the portable copy runs (vectorised for the baseline target).
//!
//! Distances are sums of squared differences in f32, in dimension order; ties go to the lowest
//! index.
use rayon::prelude::*;

use super::fpfh::{Fpfh, FPFH_BINS};

/// Descriptors per packed chunk (one AVX register of f32).
const LANES: usize = 8;
/// Queries sharing one pass over the descriptors.
const GROUP: usize = 4;
/// Chunks per cache tile: 256 chunks x 33 x 8 x 4 bytes = 270 KB.
const TILE_CHUNKS: usize = 256;
/// Query groups handed to one rayon task.
const GROUPS_PER_TASK: usize = 16;

/// One packed chunk: `chunk[d][l]` is dimension `d` of descriptor `8 c + l`.
type Chunk = [[f32; LANES]; FPFH_BINS];

/// Descriptors packed for [`PackedFeatures::nearest_all`].
pub struct PackedFeatures {
    chunks: Vec<Chunk>,
    len: usize,
}

/// Best distance and index per lane of one query, across the chunks seen so far.
#[derive(Clone, Copy)]
struct LaneBest {
    dist: [f32; LANES],
    index: [u32; LANES],
}

impl LaneBest {
    const EMPTY: LaneBest = LaneBest {
        dist: [f32::INFINITY; LANES],
        index: [u32::MAX; LANES],
    };

    /// The smallest distance over the lanes, lowest index on a tie.
    fn best(&self) -> (u32, f32) {
        let mut out = (u32::MAX, f32::INFINITY);
        for l in 0..LANES {
            let (d, i) = (self.dist[l], self.index[l]);
            if d < out.1 || (d == out.1 && i < out.0) {
                out = (i, d);
            }
        }
        out
    }
}

/// Updates `best` of four queries over `chunks`, whose first descriptor has index `first`
/// (portable code).
fn scan_portable(
    queries: &[[f32; FPFH_BINS]; GROUP],
    chunks: &[Chunk],
    first: usize,
    best: &mut [LaneBest; GROUP],
) {
    for (c, chunk) in chunks.iter().enumerate() {
        for (q, b) in queries.iter().zip(best.iter_mut()) {
            for l in 0..LANES {
                let dist = chunk
                    .iter()
                    .zip(q)
                    .fold(0.0f32, |acc, (r, q)| acc + (r[l] - q) * (r[l] - q));
                if dist < b.dist[l] {
                    b.dist[l] = dist;
                    b.index[l] = (first + c * LANES + l) as u32;
                }
            }
        }
    }
}

/// [`scan_portable`] with AVX2 and FMA intrinsics: per chunk, eight independent FMA chains
/// (four queries, even and odd dimensions), then a masked update of the lane bests. The sums
/// differ from the portable ones only in rounding (FMA, and the even/odd split).
///
/// # Safety
/// The CPU must support AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn scan_avx2(
    queries: &[[f32; FPFH_BINS]; GROUP],
    chunks: &[Chunk],
    first: usize,
    best: &mut [LaneBest; GROUP],
) {
    use std::arch::x86_64::*;
    let lane_offsets = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    for (c, chunk) in chunks.iter().enumerate() {
        let mut even = [_mm256_setzero_ps(); GROUP];
        let mut odd = [_mm256_setzero_ps(); GROUP];
        for d in (0..FPFH_BINS - 1).step_by(2) {
            // SAFETY: chunk[d] and chunk[d + 1] are arrays of LANES = 8 f32.
            let (r0, r1) = unsafe {
                (
                    _mm256_loadu_ps(chunk[d].as_ptr()),
                    _mm256_loadu_ps(chunk[d + 1].as_ptr()),
                )
            };
            for k in 0..GROUP {
                let x0 = _mm256_sub_ps(r0, _mm256_set1_ps(queries[k][d]));
                let x1 = _mm256_sub_ps(r1, _mm256_set1_ps(queries[k][d + 1]));
                even[k] = _mm256_fmadd_ps(x0, x0, even[k]);
                odd[k] = _mm256_fmadd_ps(x1, x1, odd[k]);
            }
        }
        if FPFH_BINS % 2 == 1 {
            let d = FPFH_BINS - 1;
            // SAFETY: as above.
            let r = unsafe { _mm256_loadu_ps(chunk[d].as_ptr()) };
            for k in 0..GROUP {
                let x = _mm256_sub_ps(r, _mm256_set1_ps(queries[k][d]));
                even[k] = _mm256_fmadd_ps(x, x, even[k]);
            }
        }
        let index = _mm256_add_epi32(_mm256_set1_epi32((first + c * LANES) as i32), lane_offsets);
        for k in 0..GROUP {
            let b = &mut best[k];
            let dist = _mm256_add_ps(even[k], odd[k]);
            // SAFETY: b.dist and b.index are arrays of 8 f32 / 8 u32 (32 bytes each).
            unsafe {
                let old = _mm256_loadu_ps(b.dist.as_ptr());
                let closer = _mm256_cmp_ps::<_CMP_LT_OQ>(dist, old);
                _mm256_storeu_ps(b.dist.as_mut_ptr(), _mm256_blendv_ps(old, dist, closer));
                let old_index = _mm256_loadu_si256(b.index.as_ptr().cast());
                let new_index = _mm256_blendv_epi8(old_index, index, _mm256_castps_si256(closer));
                _mm256_storeu_si256(b.index.as_mut_ptr().cast(), new_index);
            }
        }
    }
}

/// Updates `best` of four queries over `chunks` with the fastest copy this CPU runs.
fn scan_best(
    queries: &[[f32; FPFH_BINS]; GROUP],
    chunks: &[Chunk],
    first: usize,
    best: &mut [LaneBest; GROUP],
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: both features were just detected on this CPU.
        unsafe { scan_avx2(queries, chunks, first, best) };
        return;
    }
    scan_portable(queries, chunks, first, best)
}

fn to_f32(f: &Fpfh) -> [f32; FPFH_BINS] {
    f.map(|v| v as f32)
}

impl PackedFeatures {
    /// Packs `descriptors` (the set searched into). Padding lanes are infinitely far away.
    pub fn new(descriptors: &[Fpfh]) -> Self {
        let chunks = descriptors
            .chunks(LANES)
            .map(|group| {
                let mut chunk = [[f32::INFINITY; LANES]; FPFH_BINS];
                for (l, f) in group.iter().enumerate() {
                    for (d, lanes) in chunk.iter_mut().enumerate() {
                        lanes[l] = f[d] as f32;
                    }
                }
                chunk
            })
            .collect();
        PackedFeatures {
            chunks,
            len: descriptors.len(),
        }
    }

    /// Number of packed descriptors.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no descriptor is packed.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// For each query, the index of the nearest packed descriptor and the Euclidean distance
    /// (None for every query when nothing is packed).
    pub fn nearest_all(&self, queries: &[Fpfh]) -> Vec<Option<(usize, f64)>> {
        if self.is_empty() {
            return vec![None; queries.len()];
        }
        let groups: Vec<[[f32; FPFH_BINS]; GROUP]> = queries
            .chunks(GROUP)
            .map(|g| std::array::from_fn(|k| to_f32(&g[k.min(g.len() - 1)])))
            .collect();
        let best: Vec<LaneBest> = groups
            .par_chunks(GROUPS_PER_TASK)
            .flat_map_iter(|task| {
                let mut best = vec![[LaneBest::EMPTY; GROUP]; task.len()];
                for (t, tile) in self.chunks.chunks(TILE_CHUNKS).enumerate() {
                    let first = t * TILE_CHUNKS * LANES;
                    for (q, b) in task.iter().zip(best.iter_mut()) {
                        scan_best(q, tile, first, b);
                    }
                }
                best.into_iter().flatten()
            })
            .collect();
        best.iter()
            .take(queries.len())
            .map(|b| {
                let (i, d) = b.best();
                Some((i as usize, (d as f64).sqrt()))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Against a plain f64 scan, over sizes that leave partial chunks, groups and tiles, with
    /// duplicated descriptors (ties go to the lowest index).
    #[test]
    fn equals_a_plain_scan() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut f = || -> Fpfh { std::array::from_fn(|_| rng.gen_range(0.0..100.0)) };
        let mut set: Vec<Fpfh> = (0..2_301).map(|_| f()).collect();
        set[1_900] = set[17];
        let mut queries: Vec<Fpfh> = (0..203).map(|_| f()).collect();
        queries[5] = set[17];
        queries[6] = set[2_300];
        let packed = PackedFeatures::new(&set);
        let dist2 = |a: &Fpfh, b: &Fpfh| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
        for (q, found) in queries.iter().zip(packed.nearest_all(&queries)) {
            let (i, d) = found.unwrap();
            let plain: Vec<f64> = set.iter().map(|s| dist2(q, s)).collect();
            let min = plain.iter().copied().fold(f64::INFINITY, f64::min);
            let first = plain.iter().position(|&x| x == min).unwrap();
            assert_eq!(i, first);
            assert!((d - min.sqrt()).abs() <= 1e-4 * (1.0 + min.sqrt()));
        }
        assert!(PackedFeatures::new(&[]).nearest_all(&queries[..2]) == vec![None, None]);
    }
}

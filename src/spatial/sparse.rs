//! Hashed cells over a set of points of any extent, for "is any point within r of this one?"
//! (synth's defect placement asks it of sharp-edge samples and of the articular surface).
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

use nalgebra::Point3;

use super::ifloor;

/// Multiplier of [`CellHasher`] (FxHash's, rustc's hasher: an odd constant with its bits
/// spread, so a product mixes every bit of a word into the high bits).
const CELL_HASH_MUL: u64 = 0x51_7c_c1_b7_27_22_0a_95;

/// Rotation of [`CellHasher`]'s state before it is handed out, bits (26, as rustc-hash 2:
/// the product's well-mixed high bits moved down to where the table takes its bucket index).
const CELL_HASH_ROTATE: u32 = 26;

/// The hash of a cell's integer key: multiply and rotate (FxHash), not the standard library's
/// SipHash. The keys are the grid's own cell coordinates, never an adversary's, and SipHash
/// was most of [`SparseGrid::any_within`]'s time (27 lookups per query: the demo's synth and
/// the loop's removal registration ask it of every core point). The answers do not depend on
/// the hash: the map is only looked up, never iterated.
#[derive(Default, Clone, Copy)]
struct CellHasher(u64);

impl CellHasher {
    fn add(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(CELL_HASH_MUL);
    }
}

impl Hasher for CellHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.add(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, i: u64) {
        self.add(i);
    }

    fn write_i64(&mut self, i: i64) {
        self.add(i as u64);
    }

    fn write_usize(&mut self, i: usize) {
        self.add(i as u64);
    }

    fn finish(&self) -> u64 {
        self.0.rotate_left(CELL_HASH_ROTATE)
    }
}

/// Points bucketed into cubic cells of edge `cell`, only the occupied cells stored.
pub struct SparseGrid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<Point3<f64>>, BuildHasherDefault<CellHasher>>,
}

impl SparseGrid {
    /// Buckets `points` into cubes of edge `cell` (mm, positive).
    pub fn new(cell: f64, points: impl IntoIterator<Item = Point3<f64>>) -> SparseGrid {
        let mut g = SparseGrid {
            cell,
            cells: HashMap::default(),
        };
        for p in points {
            g.cells.entry(g.key(&p)).or_default().push(p);
        }
        g
    }

    fn key(&self, p: &Point3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|i| ifloor(p[i] / self.cell) as i64)
    }

    /// Whether some point lies within `r` of `p` (inclusive, by the Euclidean norm).
    pub fn any_within(&self, p: &Point3<f64>, r: f64) -> bool {
        let reach = (r / self.cell).ceil() as i64;
        let k = self.key(p);
        for dx in -reach..=reach {
            for dy in -reach..=reach {
                for dz in -reach..=reach {
                    if let Some(pts) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        if pts.iter().any(|q| (q - p).norm() <= r) {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::fixtures::uniform;
    use nalgebra::Vector3;
    use rand::SeedableRng;

    #[test]
    fn any_within_matches_brute_force() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        // Both signs of every coordinate (cells below zero floor away from it).
        let shift = |p: Point3<f64>, by: f64| p - Vector3::repeat(by);
        let points: Vec<Point3<f64>> = uniform(&mut rng, 400, 20.0)
            .into_iter()
            .map(|p| shift(p, 10.0))
            .collect();
        let queries = uniform(&mut rng, 300, 24.0);
        for cell in [0.5, 2.0, 7.0] {
            let grid = SparseGrid::new(cell, points.iter().copied());
            for q in queries.iter().map(|&q| shift(q, 12.0)) {
                for r in [0.3, 1.0, 2.5] {
                    let want = points.iter().any(|p| (p - q).norm() <= r);
                    assert_eq!(grid.any_within(&q, r), want, "cell {cell} r {r} q {q}");
                }
            }
            // A point exactly at the radius counts.
            let q = points[0] + Vector3::new(1.0, 0.0, 0.0);
            assert!(grid.any_within(&q, (q - points[0]).norm()));
        }
        assert!(!SparseGrid::new(1.0, []).any_within(&Point3::origin(), 5.0));
    }
}

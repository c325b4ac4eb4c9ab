//! A uniform grid over a point cloud for two queries: the k nearest points (exact, ties to the
//! lowest index, like [`Neighbours::knn`](crate::spatial::Neighbours::knn); one query here,
//! many at once in `batch`) and the points inside a cylinder (`axis`: M3C2's with py4dgeo
//! 1.2's semantics, see [`Grid::cylinder`]).
//!
//! Space is cut into rows along x of square cross-section (edge `cell`); the points are stored
//! row by row, sorted by x within a row, so the points of a row between two x values are one
//! contiguous slice found by two binary searches. A query walks the rows near it, takes the
//! x interval a row can contribute, and never allocates (the caller owns the output buffers).
use nalgebra::Point3;
use rayon::prelude::*;

use super::{dist2, ifloor};

mod axis;
mod batch;
mod candidates;

pub use axis::Member;

/// Most rows (the cell grows when the box would need more: an empty row costs four bytes).
const MAX_ROWS: f64 = 4.0e6;

/// Points bucketed into rows along x.
pub struct Grid {
    cell: f64,
    /// Smallest coordinates of the points (the grid's corner).
    origin: [f64; 3],
    /// Largest coordinates of the points.
    hi: [f64; 3],
    /// Cells along each axis (along x only for the spatial order).
    dims: [isize; 3],
    /// Start of each row's points in `pts` (row y + dims[1]·z; one more entry than rows).
    rows: Vec<u32>,
    /// x of each stored point (sorted within a row).
    xs: Vec<f64>,
    /// y and z of each stored point (the batched k-NN reads coordinates apart).
    ys: Vec<f64>,
    zs: Vec<f64>,
    /// Coordinates, row by row.
    pts: Vec<[f64; 3]>,
    /// Original index of each sorted point.
    ids: Vec<u32>,
}

impl Grid {
    /// Edge of the rows' square cross-section (mm).
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// A grid over `points` with the [`provisional_cell`](Self::provisional_cell).
    pub fn for_points(points: &[Point3<f64>]) -> Grid {
        Grid::new(points, Grid::provisional_cell(points))
    }

    /// A first cell for points of unknown density: about four points per cell if the points
    /// covered the faces of their bounding box.
    pub fn provisional_cell(points: &[Point3<f64>]) -> f64 {
        let Some(bbox) = crate::cloud::Aabb::of(points) else {
            return 1.0;
        };
        let e = bbox.extent();
        let area = 2.0 * (e.x * e.y + e.y * e.z + e.z * e.x);
        let cell = (4.0 * area / points.len() as f64).sqrt();
        if cell > 0.0 && cell.is_finite() {
            cell
        } else {
            1.0
        }
    }

    /// Buckets `points` (finite coordinates) into rows of cross-section `cell` × `cell` (mm;
    /// enlarged when the bounding box would need more than four million rows).
    pub fn new(points: &[Point3<f64>], cell: f64) -> Grid {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in points {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if points.is_empty() {
            (lo, hi) = ([0.0; 3], [0.0; 3]);
        }
        let extent = [0, 1, 2].map(|a| hi[a] - lo[a]);
        let area = (extent[1] + cell) * (extent[2] + cell);
        let cell = if area / (cell * cell) > MAX_ROWS {
            (area / MAX_ROWS).sqrt()
        } else {
            cell
        };
        let dims = [0, 1, 2].map(|a| ifloor(extent[a] / cell) + 1);
        let mut grid = Grid {
            cell,
            origin: lo,
            hi,
            dims,
            rows: Vec::new(),
            xs: Vec::new(),
            ys: Vec::new(),
            zs: Vec::new(),
            pts: Vec::new(),
            ids: Vec::new(),
        };
        let nrows = (dims[1] * dims[2]) as usize;
        let keys: Vec<u32> = points
            .par_iter()
            .map(|p| {
                let y = grid.coord(p.y, 1).clamp(0, dims[1] - 1);
                let z = grid.coord(p.z, 2).clamp(0, dims[2] - 1);
                (y + dims[1] * z) as u32
            })
            .collect();
        let mut rows = vec![0u32; nrows + 1];
        for &k in &keys {
            rows[k as usize + 1] += 1;
        }
        for i in 0..nrows {
            rows[i + 1] += rows[i];
        }
        let mut next = rows.clone();
        let mut order = vec![0u32; points.len()];
        for (i, &k) in keys.iter().enumerate() {
            order[next[k as usize] as usize] = i as u32;
            next[k as usize] += 1;
        }
        // Each row by x, rows in parallel (a single grid is otherwise built on one core).
        let mut row_slices: Vec<&mut [u32]> = Vec::with_capacity(nrows);
        let mut rest = &mut order[..];
        for w in rows.windows(2) {
            let (row, tail) = rest.split_at_mut((w[1] - w[0]) as usize);
            row_slices.push(row);
            rest = tail;
        }
        row_slices.par_iter_mut().with_min_len(64).for_each(|row| {
            row.sort_unstable_by(|&a, &b| points[a as usize].x.total_cmp(&points[b as usize].x))
        });
        grid.pts = order
            .par_iter()
            .map(|&i| {
                let p = &points[i as usize];
                [p.x, p.y, p.z]
            })
            .collect();
        grid.xs = grid.pts.par_iter().map(|p| p[0]).collect();
        grid.ys = grid.pts.par_iter().map(|p| p[1]).collect();
        grid.zs = grid.pts.par_iter().map(|p| p[2]).collect();
        grid.ids = order;
        grid.rows = rows;
        grid
    }

    /// Cell index of coordinate `x` along axis `a` (unclamped).
    #[inline]
    fn coord(&self, x: f64, a: usize) -> isize {
        ifloor((x - self.origin[a]) / self.cell)
    }

    /// Stored-point range of row (y, z) (in range) with x in [x0, x1].
    #[inline]
    fn row(&self, y: isize, z: isize, x0: f64, x1: f64) -> std::ops::Range<usize> {
        let r = (y + self.dims[1] * z) as usize;
        let (a, b) = (self.rows[r] as usize, self.rows[r + 1] as usize);
        let xs = &self.xs[a..b];
        a + xs.partition_point(|&x| x < x0)..a + xs.partition_point(|&x| x <= x1)
    }

    /// Indices of `points` in the Morton (Z-curve) order of their cells: queries made in this
    /// order touch memory that the previous query touched (several times faster than the
    /// random order of a sampled cloud).
    pub fn spatial_order(&self, points: &[Point3<f64>]) -> Vec<usize> {
        let spread = |mut v: u64| {
            // Bits of v (21 used) moved to every third position.
            v &= 0x1f_ffff;
            v = (v | v << 32) & 0x1f00000000ffff;
            v = (v | v << 16) & 0x1f0000ff0000ff;
            v = (v | v << 8) & 0x100f00f00f00f00f;
            v = (v | v << 4) & 0x10c30c30c30c30c3;
            (v | v << 2) & 0x1249249249249249
        };
        let mut keyed: Vec<(u64, usize)> = points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let c = [0, 1, 2].map(|a| self.coord(p[a], a).clamp(0, self.dims[a] - 1) as u64);
                (spread(c[0]) | spread(c[1]) << 1 | spread(c[2]) << 2, i)
            })
            .collect();
        keyed.sort_unstable();
        keyed.into_iter().map(|(_, i)| i).collect()
    }

    /// Makes every stored point's index its storage slot and returns the indices it had (the
    /// original index of each slot): for callers that reorder their cloud into storage order,
    /// which is spatially coherent, so per-point lookups near a query stay in cache.
    pub fn renumber(&mut self) -> Vec<u32> {
        let slots = (0..self.ids.len() as u32).collect();
        std::mem::replace(&mut self.ids, slots)
    }

    /// Whether every stored point's index is its storage slot (as after
    /// [`renumber`](Grid::renumber)): results per slot are then results per index.
    pub fn numbered_in_storage_order(&self) -> bool {
        self.ids.iter().enumerate().all(|(s, &i)| s == i as usize)
    }

    /// Original index of the point at each storage slot.
    pub fn slot_ids(&self) -> &[u32] {
        &self.ids
    }

    /// Coordinates of the point at storage slot `s`.
    #[inline]
    pub fn slot_point(&self, s: usize) -> &[f64; 3] {
        &self.pts[s]
    }

    /// The `k` nearest points to `q` within `max_radius` (inclusive; infinity for no limit),
    /// into `out` as (squared distance, index), nearest first, ties to the lowest index.
    pub fn knn(&self, q: &Point3<f64>, k: usize, max_radius: f64, out: &mut Vec<(f64, u32)>) {
        // A nearest point is usually well inside a cell, eight of them about a cell away.
        let start = if k == 1 { 0.5 } else { 1.0 } * self.cell;
        self.knn_from(q, k, max_radius, start, out);
    }

    /// [`Grid::knn`] whose first search cube has half-width `start` (it doubles from there).
    fn knn_from(
        &self,
        q: &Point3<f64>,
        k: usize,
        max_radius: f64,
        start: f64,
        out: &mut Vec<(f64, u32)>,
    ) {
        out.clear();
        if k == 0 || self.pts.is_empty() {
            return;
        }
        let qa = [q.x, q.y, q.z];
        let max2 = max_radius * max_radius;
        let consider = |range: std::ops::Range<usize>, out: &mut Vec<(f64, u32)>| {
            for s in range {
                let d2 = dist2(&qa, &self.pts[s]);
                if d2 > max2 {
                    continue;
                }
                let item = (d2, self.ids[s]);
                if out.len() == k {
                    let last = out[k - 1];
                    if (item.0, item.1) >= (last.0, last.1) {
                        continue;
                    }
                    out.pop();
                }
                let at = out.partition_point(|e| (e.0, e.1) < (item.0, item.1));
                out.insert(at, item);
            }
        };
        // Search the cube of half-width r around q, doubling r until the k-th distance is
        // inside it (every closer point has then been seen).
        let mut r = start;
        loop {
            let r_use = r.min(max_radius);
            out.clear();
            let (z0, z1) = (self.coord(qa[2] - r_use, 2), self.coord(qa[2] + r_use, 2));
            let (y0, y1) = (self.coord(qa[1] - r_use, 1), self.coord(qa[1] + r_use, 1));
            for z in z0.max(0)..=z1.min(self.dims[2] - 1) {
                for y in y0.max(0)..=y1.min(self.dims[1] - 1) {
                    consider(self.row(y, z, qa[0] - r_use, qa[0] + r_use), out);
                }
            }
            let whole = (0..3).all(|a| {
                qa[a] - r_use <= self.origin[a]
                    && qa[a] + r_use >= self.origin[a] + self.dims[a] as f64 * self.cell
            });
            let done = out.len() == k && out[k - 1].0 <= r_use * r_use;
            if done || whole || r_use >= max_radius {
                return;
            }
            r *= 2.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::fixtures::lattice_and_noise;
    use crate::spatial::Neighbours;

    #[test]
    fn knn_matches_the_kd_tree() {
        // A grid (exact ties) plus random points, and queries inside and far outside.
        let points = lattice_and_noise(5, 700);
        let index = Neighbours::new(&points);
        let grid = Grid::new(&points, 0.6);
        let mut out = Vec::new();
        let far = [Point3::new(30.0, -4.0, 2.0), Point3::new(3.5, 3.5, 90.0)];
        for q in points.iter().step_by(7).chain(&far) {
            for k in [1, 8, 27] {
                grid.knn(q, k, f64::INFINITY, &mut out);
                let want: Vec<(f64, u32)> = index
                    .knn(q, k)
                    .iter()
                    .map(|n| (n.dist2, n.index as u32))
                    .collect();
                assert_eq!(out, want, "q {q} k {k}");
                grid.knn(q, k, 1.1, &mut out);
                let capped: Vec<_> = want.into_iter().filter(|w| w.0 <= 1.1 * 1.1).collect();
                assert_eq!(out, capped, "q {q} k {k} capped");
            }
        }
    }
}

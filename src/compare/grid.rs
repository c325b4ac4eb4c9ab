//! A uniform grid over a point cloud for the comparison's two queries: the points inside an
//! M3C2 cylinder (py4dgeo 1.2's semantics, see [`Grid::cylinder`]) and the k nearest points
//! (exact, ties to the lowest index, like `cloud::Neighbours::knn`).
//!
//! Points are stored sorted by cell in a dense x-fastest array, so one row of cells along x
//! is one contiguous slice: a query walks rows, prunes cells that cannot touch the cylinder,
//! and never allocates (the caller owns the output buffers).
use nalgebra::{Point3, Vector3};

/// Most cells of the dense array (the cell grows when the box would need more).
const MAX_CELLS: f64 = 16.0e6;

/// A point inside a cylinder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Member {
    /// Index into the searched cloud.
    pub index: usize,
    /// Signed offset along the axis from the core point, mm.
    pub t: f64,
    /// Squared distance from the axis, mm².
    pub rho2: f64,
}

/// Points bucketed into cubic cells.
pub struct Grid {
    cell: f64,
    origin: [f64; 3],
    dims: [isize; 3],
    /// Start of each cell's points in `pts` (one more entry than cells).
    starts: Vec<u32>,
    /// Coordinates, sorted by cell.
    pts: Vec<[f64; 3]>,
    /// Original index of each sorted point.
    ids: Vec<u32>,
}

/// Squared distance in FLANN's summation order (as `cloud::neighbours::dist2`).
#[inline]
fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

impl Grid {
    /// Buckets `points` (finite coordinates) into cells of edge `cell` (mm; enlarged when the
    /// bounding box would need more than 16 million cells).
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
        let extent: Vec<f64> = (0..3).map(|a| hi[a] - lo[a]).collect();
        let volume: f64 = extent.iter().map(|e| e + cell).product();
        let cell = if volume / cell.powi(3) > MAX_CELLS {
            (volume / MAX_CELLS).cbrt()
        } else {
            cell
        };
        let dims = [0, 1, 2].map(|a| (extent[a] / cell).floor() as isize + 1);
        let mut grid = Grid {
            cell,
            origin: lo,
            dims,
            starts: Vec::new(),
            pts: Vec::new(),
            ids: Vec::new(),
        };
        let cells = (dims[0] * dims[1] * dims[2]) as usize;
        let keys: Vec<u32> = points
            .iter()
            .map(|p| {
                let c = [0, 1, 2].map(|a| grid.coord(p[a], a).clamp(0, dims[a] - 1));
                grid.key(c) as u32
            })
            .collect();
        let mut starts = vec![0u32; cells + 1];
        for &k in &keys {
            starts[k as usize + 1] += 1;
        }
        for i in 0..cells {
            starts[i + 1] += starts[i];
        }
        let mut next = starts.clone();
        let mut pts = vec![[0.0; 3]; points.len()];
        let mut ids = vec![0u32; points.len()];
        for (i, (&k, p)) in keys.iter().zip(points).enumerate() {
            let slot = next[k as usize] as usize;
            next[k as usize] += 1;
            pts[slot] = [p.x, p.y, p.z];
            ids[slot] = i as u32;
        }
        grid.starts = starts;
        grid.pts = pts;
        grid.ids = ids;
        grid
    }

    /// Cell index of coordinate `x` along axis `a` (unclamped).
    #[inline]
    fn coord(&self, x: f64, a: usize) -> isize {
        ((x - self.origin[a]) / self.cell).floor() as isize
    }

    #[inline]
    fn key(&self, c: [isize; 3]) -> usize {
        (c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])) as usize
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

    /// Sorted-point range of the cells x0..=x1 of row (y, z) (all in range).
    #[inline]
    fn row(&self, x0: isize, x1: isize, y: isize, z: isize) -> std::ops::Range<usize> {
        let a = self.key([x0, y, z]);
        let b = self.key([x1, y, z]);
        self.starts[a] as usize..self.starts[b + 1] as usize
    }

    /// Appends to `out` the points inside the M3C2 cylinder of radius `radius` around the axis
    /// through `core` along the unit vector `axis`, with py4dgeo 1.2's semantics: the cylinder
    /// extends L = max(max_distance, radius) both ways and is cut into N = ceil(L / radius)
    /// slabs (N = 1 when max_distance <= radius), each of which py4dgeo searches with a ball
    /// of radius sqrt(r² + (L/N)²) around its midpoint; a point belongs when it is in that
    /// ball, its squared distance to the axis is <= r² and its distance along the axis from
    /// the slab's midpoint is < L/N. Offsets and distances are computed from the slab
    /// midpoint exactly as py4dgeo does, so membership matches it bit for bit.
    pub fn cylinder(
        &self,
        core: &Point3<f64>,
        axis: &Vector3<f64>,
        radius: f64,
        max_distance: f64,
        out: &mut Vec<Member>,
    ) {
        if self.pts.is_empty() || !(radius > 0.0) {
            return;
        }
        let (length, slabs) = if max_distance > radius {
            (max_distance, (max_distance / radius).ceil())
        } else {
            (radius, 1.0)
        };
        let half = length / slabs;
        let ball = (radius * radius + half * half).sqrt();
        let ball2 = ball * ball;
        let r2 = radius * radius;
        let nslabs = slabs as isize;
        // Loose bounds for the cheap pre-test (exact tests follow per slab).
        let slack = 1e-9 * (length + radius) + 1e-12;
        let (reach_t, reach_r) = (length + slack, radius + slack);
        let hd = self.cell * 0.5 * 3f64.sqrt();
        let c = [core.x, core.y, core.z];
        let mut lo = [0isize; 3];
        let mut hi = [0isize; 3];
        for a in 0..3 {
            let ext = length * axis[a].abs() + radius * (1.0 - axis[a] * axis[a]).max(0.0).sqrt();
            lo[a] = self.coord(c[a] - ext - slack, a).max(0);
            hi[a] = self.coord(c[a] + ext + slack, a).min(self.dims[a] - 1);
            if lo[a] > hi[a] {
                return;
            }
        }
        let (ct, cr) = (reach_t + hd, reach_r + hd);
        let keep_cell = |x: isize, y: isize, z: isize| {
            let v = Vector3::new(
                self.origin[0] + (x as f64 + 0.5) * self.cell - c[0],
                self.origin[1] + (y as f64 + 0.5) * self.cell - c[1],
                self.origin[2] + (z as f64 + 0.5) * self.cell - c[2],
            );
            let t = v.dot(axis);
            t.abs() <= ct && v.norm_squared() - t * t <= cr * cr
        };
        let mut visit = |range: std::ops::Range<usize>| {
            for s in range {
                let p = &self.pts[s];
                let d = Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
                let t0 = d.dot(axis);
                if t0.abs() > reach_t || d.norm_squared() - t0 * t0 > reach_r * reach_r {
                    continue;
                }
                // Slabs whose interval can hold t0.
                let k = ((t0 + length) / (2.0 * half)).floor() as isize;
                for i in (k - 1).max(0)..=(k + 1).min(nslabs - 1) {
                    let offset = (2.0 * i as f64 + 1.0 - slabs) / slabs * length;
                    let mid = core + axis * offset;
                    let m = [mid.x, mid.y, mid.z];
                    if dist2(&m, p) > ball2 {
                        continue;
                    }
                    let d = Point3::from(*p) - mid;
                    let along = d.dot(axis);
                    let rho2 = (d - axis * along).norm_squared();
                    if rho2 <= r2 && along.abs() < half {
                        out.push(Member {
                            index: self.ids[s] as usize,
                            t: along + offset,
                            rho2,
                        });
                    }
                }
            }
        };
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                let mut run: Option<isize> = None;
                for x in lo[0]..=hi[0] + 1 {
                    let keep = x <= hi[0] && keep_cell(x, y, z);
                    match (keep, run) {
                        (true, None) => run = Some(x),
                        (false, Some(x0)) => {
                            visit(self.row(x0, x - 1, y, z));
                            run = None;
                        }
                        _ => {}
                    }
                }
            }
        }
    }

    /// The `k` nearest points to `q` within `max_radius` (inclusive; infinity for no limit),
    /// into `out` as (squared distance, index), nearest first, ties to the lowest index.
    pub fn knn(&self, q: &Point3<f64>, k: usize, max_radius: f64, out: &mut Vec<(f64, u32)>) {
        out.clear();
        if k == 0 || self.pts.is_empty() {
            return;
        }
        let qa = [q.x, q.y, q.z];
        let max2 = max_radius * max_radius;
        let c = [0, 1, 2].map(|a| self.coord(qa[a], a));
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
        let mut s = 0isize;
        loop {
            // Cells at Chebyshev distance s from c, clipped to the grid.
            let (z0, z1) = ((c[2] - s).max(0), (c[2] + s).min(self.dims[2] - 1));
            let (y0, y1) = ((c[1] - s).max(0), (c[1] + s).min(self.dims[1] - 1));
            let (x0, x1) = ((c[0] - s).max(0), (c[0] + s).min(self.dims[0] - 1));
            for z in z0..=z1 {
                for y in y0..=y1 {
                    if x0 > x1 {
                        continue;
                    }
                    if (z - c[2]).abs() == s || (y - c[1]).abs() == s {
                        consider(self.row(x0, x1, y, z), out);
                    } else {
                        for x in [c[0] - s, c[0] + s] {
                            if (0..self.dims[0]).contains(&x) {
                                consider(self.row(x, x, y, z), out);
                            }
                        }
                    }
                }
            }
            // Every point closer than `safe` has been seen.
            let mut safe = f64::INFINITY;
            let mut whole = true;
            for a in 0..3 {
                let lo = self.origin[a] + (c[a] - s) as f64 * self.cell;
                let hi = self.origin[a] + (c[a] + s + 1) as f64 * self.cell;
                safe = safe.min(qa[a] - lo).min(hi - qa[a]);
                whole &= c[a] - s <= 0 && c[a] + s >= self.dims[a] - 1;
            }
            let done = out.len() == k && out[k - 1].0 <= safe * safe;
            if done || whole || safe >= max_radius {
                return;
            }
            s += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::Neighbours;
    use rand::{Rng, SeedableRng};

    #[test]
    fn cylinder_matches_a_brute_force_cylinder() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let points: Vec<Point3<f64>> = (0..5000)
            .map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()) * 4.0)
            .collect();
        let core = Point3::new(2.0, 2.0, 2.0);
        let axis = Vector3::new(1.0, 2.0, 2.0).normalize();
        for cell in [0.1, 0.35, 2.0] {
            let grid = Grid::new(&points, cell);
            for (r, l) in [(0.3, 1.0), (0.5, 0.2), (0.4, 1.9), (0.2, 3.0)] {
                let mut found = Vec::new();
                grid.cylinder(&core, &axis, r, l, &mut found);
                let mut got: Vec<usize> = found.iter().map(|m| m.index).collect();
                got.sort();
                let len = if l > r { l } else { r };
                let want: Vec<usize> = (0..points.len())
                    .filter(|&i| {
                        let d = points[i] - core;
                        let t = d.dot(&axis);
                        (d - axis * t).norm() <= r && t.abs() < len
                    })
                    .collect();
                assert_eq!(got, want, "cell {cell} r {r} l {l}");
                for m in &found {
                    let d = points[m.index] - core;
                    assert!((m.t - d.dot(&axis)).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn knn_matches_the_kd_tree() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // A grid (exact ties) plus random points, and queries inside and far outside.
        let mut points: Vec<Point3<f64>> = (0..343)
            .map(|i| Point3::new((i % 7) as f64, ((i / 7) % 7) as f64, (i / 49) as f64))
            .collect();
        points.extend((0..700).map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()) * 7.0));
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

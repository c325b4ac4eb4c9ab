//! Cylinder queries over the row grid: the points inside an M3C2 cylinder with py4dgeo 1.2's
//! slabs ([`Grid::cylinder`]) and inside a plain cylinder ([`Grid::near_axis`]). Both walk only
//! the rows that can meet the cylinder and test each of their points exactly.
use nalgebra::{Point3, Vector3};

use super::Grid;
use crate::spatial::{dist2, ifloor};

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

/// Rounding slack of a cylinder's bounds (length and radius in mm).
#[inline]
fn slack(length: f64, radius: f64) -> f64 {
    1e-9 * (length + radius) + 1e-12
}

impl Grid {
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
        if self.pts.is_empty() || radius.is_nan() || radius <= 0.0 {
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
        let slack = slack(length, radius);
        let c = [core.x, core.y, core.z];
        let reach = (length + slack, radius + slack);
        self.rows_near_axis(core, axis, radius, length, |range| {
            for s in range {
                let p = &self.pts[s];
                let d = Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
                let t0 = d.dot(axis);
                if t0.abs() > reach.0 || d.norm_squared() - t0 * t0 > reach.1 * reach.1 {
                    continue;
                }
                // Slabs whose interval can hold t0.
                let k = ifloor((t0 + length) / (2.0 * half));
                for i in (k - 1).max(0)..=(k + 1).min(nslabs - 1) {
                    let offset = (2.0 * i as f64 + 1.0 - slabs) / slabs * length;
                    if (t0 - offset).abs() > half + slack {
                        continue;
                    }
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
        });
    }

    /// Calls `f(slot, t, rho2)` for every stored point (`slot`: its position in the grid's
    /// storage order, see [`Grid::slot_ids`]) whose offset t along the unit vector `axis` from
    /// `core` has |t| < `half_length` and whose squared distance rho2 from the axis line is
    /// <= `radius`², in storage order. A plain cylinder (the adaptive variant's), without
    /// py4dgeo's slabs.
    pub fn near_axis(
        &self,
        core: &Point3<f64>,
        axis: &Vector3<f64>,
        radius: f64,
        half_length: f64,
        mut f: impl FnMut(usize, f64, f64),
    ) {
        if self.pts.is_empty() || !(radius > 0.0 && half_length >= 0.0) {
            return;
        }
        let c = [core.x, core.y, core.z];
        let r2 = radius * radius;
        self.rows_near_axis(core, axis, radius, half_length, |range| {
            for s in range {
                let p = &self.pts[s];
                let d = Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
                let t = d.dot(axis);
                let rho2 = (d - axis * t).norm_squared();
                if rho2 <= r2 && t.abs() < half_length {
                    f(s, t, rho2);
                }
            }
        });
    }

    /// Calls `visit` with the stored-point range of every row that can hold a point within
    /// `radius` of the axis through `core` along the unit vector `axis` and within `length`
    /// of `core` along it (a superset: each caller tests its points exactly).
    fn rows_near_axis(
        &self,
        core: &Point3<f64>,
        axis: &Vector3<f64>,
        radius: f64,
        length: f64,
        mut visit: impl FnMut(std::ops::Range<usize>),
    ) {
        // Loose bounds (exact tests follow per point).
        let slack = slack(length, radius);
        let (reach_t, reach_r) = (length + slack, radius + slack);
        // Points of a row are within this of the line through the row's centre.
        let hd = self.cell * std::f64::consts::FRAC_1_SQRT_2 + slack;
        let c = [core.x, core.y, core.z];
        // The cylinder's bounding box: rows (y, z) and an x range.
        let (mut lo, mut hi) = ([0isize; 3], [0isize; 3]);
        let ext = [0, 1, 2].map(|a| {
            length * axis[a].abs() + radius * (1.0 - axis[a] * axis[a]).max(0.0).sqrt() + slack
        });
        for a in 0..3 {
            lo[a] = self.coord(c[a] - ext[a], a).max(0);
            hi[a] = self.coord(c[a] + ext[a], a).min(self.dims[a] - 1);
            if lo[a] > hi[a] {
                return;
            }
        }
        let (box0, box1) = (c[0] - ext[0], c[0] + ext[0]);
        // A row of cells along x can hold a member only where its centre line is within
        // (reach + half the cell's face diagonal) of the axis, and of the core along it: an
        // interval of x.
        let (ct, cr) = (reach_t + hd, reach_r + hd);
        let row_span = |y: isize, z: isize| -> Option<(f64, f64)> {
            let a = self.origin[1] + (y as f64 + 0.5) * self.cell - c[1];
            let b = self.origin[2] + (z as f64 + 0.5) * self.cell - c[2];
            // With u the centre's x offset from the core: t = n0 u + k and
            // perp² = (1 - n0²) u² - 2 n0 k u + a² + b² - k².
            let (n0, k) = (axis[0], axis[1] * a + axis[2] * b);
            let (mut u0, mut u1) = (f64::NEG_INFINITY, f64::INFINITY);
            let qa = 1.0 - n0 * n0;
            let qb = -2.0 * n0 * k;
            let qc = a * a + b * b - k * k - cr * cr;
            if qa > 1e-12 {
                let disc = qb * qb - 4.0 * qa * qc;
                if disc < 0.0 {
                    return None;
                }
                let root = disc.sqrt();
                (u0, u1) = ((-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa));
            } else if qc > 0.0 {
                return None;
            }
            if n0.abs() > 1e-12 {
                let (e0, e1) = ((-ct - k) / n0, (ct - k) / n0);
                u0 = u0.max(e0.min(e1));
                u1 = u1.min(e0.max(e1));
            } else if k.abs() > ct {
                return None;
            }
            // Slack for rounding in the interval ends.
            let pad = 1e-9 * self.cell;
            let (x0, x1) = ((c[0] + u0 - pad).max(box0), (c[0] + u1 + pad).min(box1));
            (x0 <= x1).then_some((x0, x1))
        };
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                if let Some((x0, x1)) = row_span(y, z) {
                    visit(self.row(y, z, x0, x1));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::fixtures::uniform;
    use rand::SeedableRng;

    #[test]
    fn cylinder_matches_a_brute_force_cylinder() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let points = uniform(&mut rng, 5000, 4.0);
        let core = Point3::new(2.0, 2.0, 2.0);
        let axes = [
            Vector3::new(1.0, 2.0, 2.0).normalize(),
            Vector3::x(),
            -Vector3::z(),
            Vector3::new(0.0, 1.0, -1e-13).normalize(),
        ];
        for (cell, axis) in [0.1, 0.35, 2.0]
            .into_iter()
            .flat_map(|c| axes.map(|a| (c, a)))
        {
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
                let mut near = Vec::new();
                grid.near_axis(&core, &axis, r, len, |s, t, rho2| {
                    let i = grid.slot_ids()[s] as usize;
                    let d = points[i] - core;
                    assert_eq!(grid.slot_point(s), &[points[i].x, points[i].y, points[i].z]);
                    assert!((t - d.dot(&axis)).abs() < 1e-12);
                    assert!((rho2 - (d - axis * t).norm_squared()).abs() < 1e-12);
                    near.push(i);
                });
                near.sort();
                assert_eq!(near, want, "near_axis: cell {cell} r {r} l {l}");
            }
        }
    }
}

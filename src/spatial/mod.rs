//! Neighbour search, at the ground floor beside `cloud`: every stage that asks "which points
//! are near this one?" imports its index from here.
//!
//! Three indexes, one per kind of question:
//! - [`Grid`]: rows of cells along x over a fixed cloud. Exact k nearest points of one query
//!   ([`Grid::knn`]) or of many at once ([`Grid::knn_among`], [`Grid::knn_each`]), and the
//!   points inside a cylinder (M3C2's [`Grid::cylinder`], the plain [`Grid::near_axis`]).
//!   The fastest for the batch k-nearest searches of the outlier filter, normals, voxel
//!   down-sampling, FPFH, ICP and the comparison.
//! - [`Neighbours`]: kiddo's immutable k-d tree over a fixed cloud, for k-nearest, radius and
//!   nearest-one queries one at a time.
//! - [`SparseGrid`]: hashed cells over a set of points of any extent, for "anything within r?".
//!
//! All of them measure squared distances with [`dist2`] (FLANN's summation order) and break
//! distance ties by the lowest index, so their answers agree to the bit.
mod grid;
mod sparse;
mod tree;

pub use grid::{Grid, Member};
pub use sparse::SparseGrid;
pub use tree::{KnnScratch, Neighbour, Neighbours};

/// Squared distance in FLANN's summation order (`(dx² + dy²) + dz²`).
#[inline]
pub fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let (dx, dy, dz) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    dx * dx + dy * dy + dz * dz
}

/// ⌊x⌋ as an integer (saturating; 0 for NaN, as `x.floor() as isize`), without a libm call.
#[inline]
fn ifloor(x: f64) -> isize {
    let f = x as isize;
    if (f as f64) > x {
        f.saturating_sub(1)
    } else {
        f
    }
}

/// Two unit tangents `(a, b)` of the unit normal `n`, right-handed with it (`b = n x a`):
/// `a` is `n x X`, or `n x Y` where `n` is within 30 degrees of X (the cross product's norm
/// under 0.5).
pub fn tangent_basis(
    n: &nalgebra::Vector3<f64>,
) -> (nalgebra::Vector3<f64>, nalgebra::Vector3<f64>) {
    let a = n.cross(&nalgebra::Vector3::x());
    let a = if a.norm() < 0.5 {
        n.cross(&nalgebra::Vector3::y())
    } else {
        a
    }
    .normalize();
    (a, n.cross(&a))
}

/// `values` (the answer for each of some points, in a visiting order) put back in index
/// order: `order[j]` is the index of the point whose answer is `values[j]`; `order` must be a
/// permutation of `0..values.len()`.
pub fn in_index_order<R>(order: impl Iterator<Item = usize>, values: Vec<R>) -> Vec<R> {
    let mut slots: Vec<Option<R>> = values.iter().map(|_| None).collect();
    for (i, v) in order.zip(values) {
        slots[i] = Some(v);
    }
    slots
        .into_iter()
        .map(|v| v.expect("a permutation"))
        .collect()
}

/// Point sets the index tests share.
#[cfg(test)]
mod fixtures {
    use nalgebra::Point3;
    use rand::{Rng, SeedableRng};

    /// The 7 × 7 × 7 lattice of unit spacing from the origin (many exact distance ties).
    pub fn lattice() -> Vec<Point3<f64>> {
        (0..343)
            .map(|i| Point3::new((i % 7) as f64, ((i / 7) % 7) as f64, (i / 49) as f64))
            .collect()
    }

    /// The [`lattice`] and then `n` [`uniform`] points in its cube [0, 7)³ (ChaCha8, `seed`).
    pub fn lattice_and_noise(seed: u64, n: usize) -> Vec<Point3<f64>> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut points = lattice();
        points.extend(uniform(&mut rng, n, 7.0));
        points
    }

    /// `n` points drawn uniformly from the cube [0, `scale`)³.
    pub fn uniform(rng: &mut impl Rng, n: usize, scale: f64) -> Vec<Point3<f64>> {
        (0..n)
            .map(|_| Point3::new(rng.gen(), rng.gen(), rng.gen()) * scale)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ifloor_is_floor_as_an_integer() {
        for x in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            -1.0,
            2.999_999,
            -3.000_001,
            1e300,
            -1e300,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            9.3e18,
            -9.3e18,
        ] {
            assert_eq!(ifloor(x), x.floor() as isize, "x = {x}");
        }
    }

    #[test]
    fn answers_go_back_to_index_order() {
        let order = [2usize, 0, 3, 1];
        let values = vec!["c", "a", "d", "b"];
        assert_eq!(
            in_index_order(order.into_iter(), values),
            ["a", "b", "c", "d"]
        );
    }
}

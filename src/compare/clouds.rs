//! The two clouds as the comparison reads them (each with its grid), their density, and the
//! parallel run over the core points.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::cloud::PointCloud;
use crate::spatial::{in_index_order, Grid};

/// Core points are handed to the threads in chunks of this many (speed only: a chunk shares
/// one scratch buffer).
const CHUNK: usize = 512;

/// The surface density reads the distance to this many nearest neighbours ...
const DENSITY_NEIGHBOURS: usize = 12;

/// ... of up to this many evenly spread points (its median moves by less than a per cent).
const DENSITY_SAMPLES: usize = 1000;

/// Density assumed (points per mm²) when no sampled point has enough neighbours: a few
/// points, whose radii the caller's checks refuse anyway.
const FALLBACK_DENSITY: f64 = 1.0;

/// The clouds a comparison reads and their grids (for the adaptive method, each cloud in its
/// grid's storage order).
pub(crate) struct Clouds<'a> {
    /// The reference cloud.
    pub reference: &'a PointCloud,
    /// The scan cloud.
    pub scan: &'a PointCloud,
    /// The reference's points bucketed into rows along x.
    pub ref_grid: Grid,
    /// The scan's points bucketed into rows along x.
    pub scan_grid: Grid,
    /// The scan's median surface density, points per mm² ([`surface_density`]).
    pub scan_density: f64,
}

/// The points and normals of `cloud` in the order `ids` (scalar fields are not needed here).
pub(crate) fn in_storage_order(cloud: &PointCloud, ids: &[u32]) -> PointCloud {
    PointCloud {
        points: ids.par_iter().map(|&i| cloud.points[i as usize]).collect(),
        normals: cloud
            .normals
            .as_ref()
            .map(|n| ids.par_iter().map(|&i| n[i as usize]).collect()),
        fields: Vec::new(),
    }
}

/// Runs `f` at every core point in parallel (one result each), with a progress bar; `f` gets
/// a scratch value (one per chunk of core points) to reuse. Core points are visited in the
/// grid's spatial order (cache-friendly); the results come back in the core points' order.
pub(crate) fn run<S, T, F>(grid: &Grid, core: &PointCloud, normals: &[Vector3<f64>], f: F) -> Vec<T>
where
    S: Default,
    T: Copy + Send,
    F: Fn(&mut S, &Point3<f64>, &Vector3<f64>) -> T + Sync,
{
    let bar = crate::progress::bar(core.len() as u64, "compare");
    let order = grid.spatial_order(&core.points);
    let done: Vec<T> = order
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            let mut scratch = S::default();
            let done: Vec<T> = chunk
                .iter()
                .map(|&i| f(&mut scratch, &core.points[i], &normals[i]))
                .collect();
            bar.inc(done.len() as u64);
            done
        })
        .collect();
    bar.finish_and_clear();
    in_index_order(order.iter().copied(), done)
}

/// The median surface density (points per mm²) of the points of `grid` (the scan's, or the
/// reference's), from the 12th-neighbour distance of up to 1,000 of them evenly spread over
/// the grid's storage order (spatial: the answer does not depend on the order of the points
/// in the file).
pub(crate) fn surface_density(grid: &Grid) -> f64 {
    let n = grid.slot_ids().len();
    let step = (n / DENSITY_SAMPLES).max(1);
    let mut found = Vec::new();
    let mut densities: Vec<f64> = (0..n)
        .step_by(step)
        .filter_map(|s| {
            grid.knn(
                &Point3::from(*grid.slot_point(s)),
                DENSITY_NEIGHBOURS + 1,
                f64::INFINITY,
                &mut found,
            );
            let d2 = found.last()?.0;
            let k = DENSITY_NEIGHBOURS as f64;
            (found.len() == DENSITY_NEIGHBOURS + 1 && d2 > 0.0)
                .then(|| k / (std::f64::consts::PI * d2))
        })
        .collect();
    if densities.is_empty() {
        return FALLBACK_DENSITY;
    }
    densities.sort_by(f64::total_cmp);
    densities[densities.len() / 2]
}

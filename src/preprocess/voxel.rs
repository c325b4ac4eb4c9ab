//! Voxel down-sampling (one centroid per occupied voxel) and the cloud resolution.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::cloud::{Aabb, PointCloud};
use crate::spatial::Grid;

/// Most voxels along the cloud's longest side. A voxel key is `⌊coordinate / voxel⌋` as an
/// integer: beyond about 9e18 it saturates and every point falls in one voxel (a voxel of
/// 1e-300 mm merged the whole cloud), and beyond 2^53 neighbouring keys can no longer be told
/// apart. A billion voxels across an 80 mm part is 0.08 nm, far below any scanner's noise
/// (micrometres), so a finer voxel is a slip of the exponent, not a setting.
pub const MAX_VOXELS_ACROSS: f64 = 1e9;

/// Refuses a voxel edge that is not a positive finite number, finer than
/// [`MAX_VOXELS_ACROSS`] voxels along the cloud's longest side, or longer than that side (a
/// handful of points would be left of the whole cloud). The message names `option` (how the
/// user set it, e.g. `--voxel`).
pub fn check_voxel(cloud: &PointCloud, voxel_mm: f64, option: &str) -> anyhow::Result<()> {
    check_voxel_value(voxel_mm, option)?;
    let across = Aabb::of(&cloud.points).map_or(0.0, |b| b.extent().max());
    if across / voxel_mm > MAX_VOXELS_ACROSS {
        anyhow::bail!(
            "{option}: a voxel of {voxel_mm:e} mm is absurdly small for a cloud {across:.3} mm across (at most {MAX_VOXELS_ACROSS:e} voxels across it, i.e. at least {:e} mm)",
            across / MAX_VOXELS_ACROSS
        );
    }
    if across > 0.0 && voxel_mm > across {
        anyhow::bail!(
            "{option}: a voxel of {voxel_mm} mm is larger than the whole cloud ({across:.3} mm across): it would merge it into a handful of points"
        );
    }
    Ok(())
}

/// The part of [`check_voxel`] that needs no cloud: the edge is a positive finite number of
/// mm. The message names `option`.
pub fn check_voxel_value(voxel_mm: f64, option: &str) -> anyhow::Result<()> {
    if !(voxel_mm > 0.0 && voxel_mm.is_finite()) {
        anyhow::bail!("{option}: the voxel must be a positive number of mm (got {voxel_mm:?})");
    }
    Ok(())
}

/// Replaces the points of each occupied voxel (edge `voxel_mm`) by their centroid; normals are
/// averaged and renormalised (the first point's normal when they cancel), scalar fields
/// averaged. The grid is Open3D's: voxel (i, j, l) spans
/// `min + voxel * ((i, j, l) - 1/2)` to `+ voxel`, `min` being the bounding-box corner.
/// Output is ordered by voxel (x index, then y, then z). A voxel that is not a positive
/// finite number returns the cloud unchanged; [`check_voxel`] refuses that and voxels absurd
/// for the cloud (the stage front [`super::preprocess`] calls it).
pub fn voxel_downsample(cloud: &PointCloud, voxel_mm: f64) -> PointCloud {
    let Some(bbox) = Aabb::of(&cloud.points) else {
        return cloud.clone();
    };
    if !(voxel_mm > 0.0 && voxel_mm.is_finite()) {
        return cloud.clone();
    }
    let origin = bbox.min - Vector3::repeat(voxel_mm / 2.0);
    let mut keyed: Vec<([i64; 3], usize)> = cloud
        .points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            (
                ((p - origin) / voxel_mm).map(|c| c.floor() as i64).into(),
                i,
            )
        })
        .collect();
    keyed.par_sort_unstable();
    let runs: Vec<&[([i64; 3], usize)]> = keyed.chunk_by(|a, b| a.0 == b.0).collect();
    let mean = |run: &[([i64; 3], usize)], values: &[f64]| {
        run.iter().map(|e| values[e.1]).sum::<f64>() / run.len() as f64
    };
    PointCloud {
        points: runs
            .iter()
            .map(|run| {
                let sum = run
                    .iter()
                    .fold(Vector3::zeros(), |s, e| s + cloud.points[e.1].coords);
                Point3::from(sum / run.len() as f64)
            })
            .collect(),
        normals: cloud.normals.as_ref().map(|normals| {
            runs.iter()
                .map(|run| {
                    let sum = run.iter().fold(Vector3::zeros(), |s, e| s + normals[e.1]);
                    sum.try_normalize(1e-12).unwrap_or(normals[run[0].1])
                })
                .collect()
        }),
        fields: cloud
            .fields
            .iter()
            .map(|f| crate::cloud::ScalarField {
                name: f.name.clone(),
                values: runs.iter().map(|run| mean(run, &f.values)).collect(),
            })
            .collect(),
    }
}

/// Most points whose nearest-neighbour distance enters [`mean_spacing`] (evenly strided): the
/// distances scatter by about half their mean, so 20,000 of them give the mean within about
/// 0.5 %, at a tenth of the cost of every point on a 300k cloud.
pub const SPACING_SAMPLE: usize = 20_000;

/// Mean distance from a point to its nearest other point (the cloud resolution "mr", mm), over
/// every point of a cloud of up to [`SPACING_SAMPLE`] points, else over every ⌈n /
/// SPACING_SAMPLE⌉-th point (at most that many); 0 for fewer than two points.
pub fn mean_spacing(cloud: &PointCloud) -> f64 {
    if cloud.len() < 2 {
        return 0.0;
    }
    mean_spacing_in(&Grid::for_points(&cloud.points), &cloud.points)
}

/// [`mean_spacing`] of `points`, searched in `grid` (a [`Grid`] built over exactly `points`,
/// not renumbered).
pub fn mean_spacing_in(grid: &Grid, points: &[Point3<f64>]) -> f64 {
    if points.len() < 2 {
        return 0.0;
    }
    let step = points.len().div_ceil(SPACING_SAMPLE);
    let sample: Vec<Point3<f64>> = points.iter().step_by(step).copied().collect();
    // All queries at once (exactly the single queries' answers, several times faster); a
    // query grid of the searched grid's cell, each query's candidates gathered a cell around.
    let queries = Grid::new(&sample, grid.cell());
    let nearest: Vec<f64> = grid.knn_each(&queries, 2, f64::INFINITY, grid.cell(), |q, found| {
        // Sample `q` is point `q × step`.
        let i = q * step;
        // The point itself is one of the two (a duplicate of it counts at distance 0).
        found
            .iter()
            .find(|e| e.1 as usize != i)
            .map_or(0.0, |e| e.0.sqrt())
    });
    // Summed in order: the same resolution (and so the same voxels) on every run.
    nearest.iter().sum::<f64>() / nearest.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centroids_normals_and_fields_per_voxel() {
        let mut cloud = PointCloud::from_points(vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.4, 0.0, 0.0),
            Point3::new(2.0, 0.0, 0.0),
            Point3::new(0.2, 0.3, 0.0),
        ]);
        cloud.normals = Some(vec![Vector3::x(), Vector3::y(), Vector3::z(), Vector3::x()]);
        cloud.set_field("intensity", vec![1.0, 2.0, 3.0, 3.0]);
        let down = voxel_downsample(&cloud, 1.0);
        assert_eq!(down.len(), 2);
        assert!((down.points[0] - Point3::new(0.2, 0.1, 0.0)).norm() < 1e-12);
        assert_eq!(down.points[1], Point3::new(2.0, 0.0, 0.0));
        let n0 = down.normals.as_ref().unwrap()[0];
        assert!((n0 - Vector3::new(2.0, 1.0, 0.0).normalize()).norm() < 1e-12);
        assert_eq!(down.field("intensity").unwrap(), &[2.0, 3.0]);
        assert_eq!(voxel_downsample(&cloud, 0.0), cloud);
    }

    #[test]
    fn voxels_absurd_for_the_cloud_are_refused() {
        // 10 mm across: voxels from 1e-8 mm (1e9 across) to 10 mm are fine.
        let cloud = PointCloud::from_points(vec![Point3::origin(), Point3::new(10.0, 2.0, 0.0)]);
        for ok in [2e-8, 0.5, 10.0] {
            assert!(check_voxel(&cloud, ok, "--voxel").is_ok(), "{ok}");
        }
        for bad in [1e-300, 0.9e-8, 10.5, 1e300, 0.0, -1.0, f64::NAN] {
            let err = check_voxel(&cloud, bad, "--voxel").unwrap_err().to_string();
            assert!(err.starts_with("--voxel: "), "{bad}: {err}");
        }
    }

    #[test]
    fn spacing_of_a_grid() {
        let cloud = PointCloud::from_points(
            (0..100)
                .map(|i| Point3::new((i % 10) as f64 * 0.5, (i / 10) as f64 * 0.5, 0.0))
                .collect(),
        );
        assert_eq!(mean_spacing(&cloud), 0.5);
        assert_eq!(mean_spacing(&PointCloud::default()), 0.0);
    }

    #[test]
    fn sampled_spacing_is_within_a_percent_of_every_points_mean() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        // 200,000 random points on a wavy sheet: uneven spacing, as a scan has.
        let cloud = PointCloud::from_points(
            (0..200_000)
                .map(|_| {
                    let (x, y) = (rng.gen_range(0.0..60.0), rng.gen_range(0.0..40.0f64));
                    Point3::new(x, y, 3.0 * (x / 7.0).sin() * (y / 5.0).cos())
                })
                .collect(),
        );
        let every = super::super::sor::mean_distances(&cloud, 1, false);
        let exact = every.iter().sum::<f64>() / every.len() as f64;
        let sampled = mean_spacing(&cloud);
        assert!((sampled / exact - 1.0).abs() < 0.01, "{sampled} vs {exact}");
    }
}

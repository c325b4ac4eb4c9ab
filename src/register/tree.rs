//! Interim preparation helpers (private to `register`).
//!
//! TODO(pre): replace by `preprocess::{voxel_downsample, estimate_normals, mean_spacing}` once
//! the preprocessing stage lands on main.
use std::collections::HashMap;

pub(crate) use crate::cloud::Neighbours as Tree;
use nalgebra::{Matrix3, Point3, Vector3};
use rayon::prelude::*;

/// Mean nearest-neighbour spacing, estimated on up to 20,000 evenly strided points.
pub(crate) fn mean_spacing(points: &[Point3<f64>], tree: &Tree) -> f64 {
    let stride = (points.len() / 20_000).max(1);
    let d: Vec<f64> = points
        .par_iter()
        .step_by(stride)
        .map(|p| tree.knn(p, 2).get(1).map_or(0.0, |r| r.dist2.sqrt()))
        .collect();
    d.iter().sum::<f64>() / d.len().max(1) as f64
}

/// Voxel-grid down-sampling: the centroid of each occupied voxel, with the normalised mean of
/// the voxel's normals when `normals` is given.
pub(crate) fn voxel_downsample(
    points: &[Point3<f64>],
    normals: Option<&[Vector3<f64>]>,
    voxel: f64,
) -> (Vec<Point3<f64>>, Option<Vec<Vector3<f64>>>) {
    let mut cells: HashMap<[i64; 3], usize> = HashMap::new();
    let mut sums: Vec<(Vector3<f64>, Vector3<f64>, usize)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let key = [0, 1, 2].map(|a| (p[a] / voxel).floor() as i64);
        let slot = *cells.entry(key).or_insert_with(|| {
            sums.push((Vector3::zeros(), Vector3::zeros(), 0));
            sums.len() - 1
        });
        let s = &mut sums[slot];
        s.0 += p.coords;
        if let Some(n) = normals {
            s.1 += n[i];
        }
        s.2 += 1;
    }
    let pts = sums
        .iter()
        .map(|s| Point3::from(s.0 / s.2 as f64))
        .collect();
    let nrm = normals.map(|_| {
        sums.iter()
            .map(|s| s.1.try_normalize(1e-12).unwrap_or_else(Vector3::z))
            .collect()
    });
    (pts, nrm)
}

/// PCA normals from up to `k` neighbours within `radius`, oriented away from the centroid of
/// the cloud (a rule that moves with the cloud, so features stay rotation-invariant).
pub(crate) fn pca_normals(
    points: &[Point3<f64>],
    tree: &Tree,
    radius: f64,
    k: usize,
) -> Vec<Vector3<f64>> {
    let centre = points.iter().fold(Vector3::zeros(), |a, p| a + p.coords) / points.len() as f64;
    points
        .par_iter()
        .map(|p| {
            let nb = tree.knn_within(p, k, radius);
            let mut n = if nb.len() < 3 {
                Vector3::z()
            } else {
                let m = nb
                    .iter()
                    .fold(Vector3::zeros(), |a, n| a + points[n.index].coords)
                    / nb.len() as f64;
                let mut c = Matrix3::zeros();
                for n in &nb {
                    let d = points[n.index].coords - m;
                    c += d * d.transpose();
                }
                let e = c.symmetric_eigen();
                let imin = e.eigenvalues.imin();
                e.eigenvectors.column(imin).into_owned()
            };
            if n.dot(&(p.coords - centre)) < 0.0 {
                n = -n;
            }
            n
        })
        .collect()
}

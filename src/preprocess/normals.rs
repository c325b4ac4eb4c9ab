//! Normals and surface variation by PCA over each point's neighbourhood (Open3D's definition:
//! covariance of the neighbourhood including the point, normal = eigenvector of the smallest
//! eigenvalue), then a consistent orientation.
use std::cmp::Ordering;
use std::collections::BinaryHeap;

use anyhow::{bail, Result};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

use crate::cloud::{Neighbours, PointCloud};
use crate::compare::grid::Grid;

/// How the sign of each normal is chosen (PCA gives an axis, not a direction).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "OrientationSpec", into = "OrientationSpec")]
pub enum Orientation {
    /// [`FromExisting`](Self::FromExisting) when the cloud has normals, else
    /// [`Propagate`](Self::Propagate). The default.
    Auto,
    /// Every normal points toward this viewpoint (the scanner position), mm.
    Viewpoint(Point3<f64>),
    /// Hoppe's propagation: a minimum spanning tree over the k-NN graph with edge cost
    /// 1 - |nᵢ·nⱼ|; each connected component is seeded at its highest point (largest z) with
    /// nz >= 0 and every normal is flipped to agree with its parent in the tree.
    Propagate,
    /// Each normal agrees in sign with the input's normal at the same point (scanner or
    /// mesh normals).
    FromExisting,
    /// Away from the cloud's centroid (for a closed, roughly convex part).
    Outward,
    /// The eigen-solver's sign, left as it is (when only the axis matters).
    Unoriented,
}

/// TOML/JSON form of [`Orientation`]: `"auto"`, `"propagate"`, `{ viewpoint = [x, y, z] }`...
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum OrientationSpec {
    Auto,
    Viewpoint([f64; 3]),
    Propagate,
    FromExisting,
    Outward,
    Unoriented,
}

impl From<OrientationSpec> for Orientation {
    fn from(s: OrientationSpec) -> Self {
        match s {
            OrientationSpec::Auto => Orientation::Auto,
            OrientationSpec::Viewpoint(v) => Orientation::Viewpoint(Point3::from(v)),
            OrientationSpec::Propagate => Orientation::Propagate,
            OrientationSpec::FromExisting => Orientation::FromExisting,
            OrientationSpec::Outward => Orientation::Outward,
            OrientationSpec::Unoriented => Orientation::Unoriented,
        }
    }
}

impl From<Orientation> for OrientationSpec {
    fn from(o: Orientation) -> Self {
        match o {
            Orientation::Auto => OrientationSpec::Auto,
            Orientation::Viewpoint(v) => OrientationSpec::Viewpoint([v.x, v.y, v.z]),
            Orientation::Propagate => OrientationSpec::Propagate,
            Orientation::FromExisting => OrientationSpec::FromExisting,
            Orientation::Outward => OrientationSpec::Outward,
            Orientation::Unoriented => OrientationSpec::Unoriented,
        }
    }
}

/// Settings of normal estimation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NormalConfig {
    /// Neighbours in each PCA neighbourhood, the point included (Open3D's `max_nn`). Default 20.
    pub k: usize,
    /// Optional search radius (mm): neighbourhoods are the k nearest within it (Open3D's
    /// hybrid search). Default none (k nearest).
    pub radius: Option<f64>,
    /// Orientation rule. Default [`Orientation::Auto`].
    pub orientation: Orientation,
    /// Neighbours per point in the propagation graph. Default 10.
    pub propagate_k: usize,
}

impl Default for NormalConfig {
    fn default() -> Self {
        NormalConfig {
            k: 20,
            radius: None,
            orientation: Orientation::Auto,
            propagate_k: 10,
        }
    }
}

/// Normals and surface variation of every point.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalEstimate {
    /// Unit normals. A point with fewer than 3 neighbours gets (0, 0, 1), as in Open3D.
    pub normals: Vec<Vector3<f64>>,
    /// Surface variation λ₀ / (λ₀ + λ₁ + λ₂) (λ₀ the smallest eigenvalue; 0 to 1/3).
    pub curvature: Vec<f64>,
    /// The rule actually applied (`Auto` resolved).
    pub orientation: Orientation,
    /// One sentence saying how the normals were oriented.
    pub orientation_note: String,
}

/// PCA normal and surface variation of the points at `idx` (at least 3).
pub fn pca_normal(
    points: &[Point3<f64>],
    idx: impl Iterator<Item = usize> + Clone,
) -> (Vector3<f64>, f64) {
    let n = idx.clone().count() as f64;
    let centroid = idx
        .clone()
        .fold(Vector3::zeros(), |s, i| s + points[i].coords)
        / n;
    let cov = idx.fold(Matrix3::zeros(), |s, i| {
        let d = points[i].coords - centroid;
        s + d * d.transpose()
    }) / n;
    let eig = SymmetricEigen::new(cov);
    let small = eig.eigenvalues.imin();
    let normal = eig.eigenvectors.column(small).normalize();
    let sum = eig.eigenvalues.sum();
    let variation = if sum > 0.0 {
        (eig.eigenvalues[small] / sum).max(0.0)
    } else {
        0.0
    };
    (normal, variation)
}

/// Estimates normals and surface variation, front function. Errors (one line) on an empty
/// cloud, k < 3, a non-positive radius, or `FromExisting` without input normals.
pub fn estimate_normals(cloud: &PointCloud, cfg: &NormalConfig) -> Result<NormalEstimate> {
    if cloud.is_empty() {
        bail!("normals: the cloud is empty");
    }
    if cfg.k < 3 {
        bail!("normals: k must be at least 3 (got {})", cfg.k);
    }
    if let Some(r) = cfg.radius {
        if !(r > 0.0 && r.is_finite()) {
            bail!("normals: radius must be a positive number of mm (got {r})");
        }
    }
    let orientation = match cfg.orientation {
        Orientation::Auto if cloud.normals.is_some() => Orientation::FromExisting,
        Orientation::Auto => Orientation::Propagate,
        Orientation::FromExisting if cloud.normals.is_none() => {
            bail!("normals: orientation from existing normals, but the input has none")
        }
        Orientation::Propagate if cfg.propagate_k == 0 => {
            bail!("normals: propagate_k must be at least 1")
        }
        o => o,
    };
    let radius = cfg.radius.unwrap_or(f64::INFINITY);
    // The k nearest within the radius (nearest first, ties to the lowest index), batched.
    let pca: Vec<(Vector3<f64>, f64)> = Grid::knn_among(&cloud.points, cfg.k, radius, |_, nb| {
        if nb.len() < 3 {
            (Vector3::z(), 0.0)
        } else {
            pca_normal(&cloud.points, nb.iter().map(|&(_, j)| j as usize))
        }
    });
    let (mut normals, curvature): (Vec<_>, Vec<_>) = pca.into_iter().unzip();
    let orientation_note = orient(cloud, &mut normals, orientation, cfg.propagate_k);
    Ok(NormalEstimate {
        normals,
        curvature,
        orientation,
        orientation_note,
    })
}

/// Applies `rule` (never `Auto`) in place; returns the note.
fn orient(
    cloud: &PointCloud,
    normals: &mut [Vector3<f64>],
    rule: Orientation,
    propagate_k: usize,
) -> String {
    let toward = |normals: &mut [Vector3<f64>], dir: &dyn Fn(usize) -> Vector3<f64>| {
        for (i, n) in normals.iter_mut().enumerate() {
            if n.dot(&dir(i)) < 0.0 {
                *n = -*n;
            }
        }
    };
    let p = &cloud.points;
    match rule {
        Orientation::Viewpoint(v) => {
            toward(normals, &|i| v - p[i]);
            format!("toward the viewpoint ({}, {}, {}) mm", v.x, v.y, v.z)
        }
        Orientation::Outward => {
            let c = p.iter().fold(Vector3::zeros(), |s, q| s + q.coords) / p.len() as f64;
            toward(normals, &|i| p[i].coords - c);
            "away from the cloud's centroid".into()
        }
        Orientation::FromExisting => {
            let existing = cloud.normals.as_ref().expect("checked by the caller");
            toward(normals, &|i| existing[i]);
            "agreeing with the input's normals".into()
        }
        Orientation::Propagate => {
            let components = propagate(p, &Neighbours::new(p), normals, propagate_k);
            format!(
                "propagated over a {propagate_k}-NN graph (minimum spanning tree, cost 1-|n·n'|), \
                 {components} component(s), each seeded with nz >= 0 at its highest point"
            )
        }
        Orientation::Unoriented | Orientation::Auto => "unoriented (eigen-solver sign)".into(),
    }
}

/// A graph edge in the propagation heap, cheapest first.
#[derive(PartialEq)]
struct Edge {
    cost: f64,
    from: u32,
    to: u32,
}

impl Eq for Edge {}

impl Ord for Edge {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .cost
            .total_cmp(&self.cost)
            .then(other.to.cmp(&self.to))
            .then(other.from.cmp(&self.from))
    }
}

impl PartialOrd for Edge {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// Prim's minimum spanning tree over the symmetric k-NN graph, flipping each newly reached
/// normal to agree with the one it was reached from. Returns the number of components.
fn propagate(
    points: &[Point3<f64>],
    index: &Neighbours,
    normals: &mut [Vector3<f64>],
    k: usize,
) -> usize {
    let knn: Vec<Vec<u32>> = index.par_map_points(
        || (),
        |_, i| {
            let nb = index.knn(&points[i], k + 1);
            nb.iter()
                .filter(|n| n.index != i)
                .map(|n| n.index as u32)
                .collect()
        },
    );
    let mut adjacency = knn.clone();
    for (i, list) in knn.iter().enumerate() {
        for &j in list {
            adjacency[j as usize].push(i as u32);
        }
    }
    let mut seeds: Vec<usize> = (0..points.len()).collect();
    seeds.sort_by(|&a, &b| points[b].z.total_cmp(&points[a].z).then(a.cmp(&b)));
    let mut done = vec![false; points.len()];
    let mut heap = BinaryHeap::new();
    let mut components = 0;
    for seed in seeds {
        if done[seed] {
            continue;
        }
        components += 1;
        if normals[seed].z < 0.0 {
            normals[seed] = -normals[seed];
        }
        heap.push(Edge {
            cost: 0.0,
            from: seed as u32,
            to: seed as u32,
        });
        while let Some(Edge { from, to, .. }) = heap.pop() {
            let (from, to) = (from as usize, to as usize);
            if done[to] {
                continue;
            }
            done[to] = true;
            if normals[to].dot(&normals[from]) < 0.0 {
                normals[to] = -normals[to];
            }
            for &j in &adjacency[to] {
                if !done[j as usize] {
                    heap.push(Edge {
                        cost: 1.0 - normals[to].dot(&normals[j as usize]).abs(),
                        from: to as u32,
                        to: j,
                    });
                }
            }
        }
    }
    components
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on a sphere of radius 10 (Fibonacci lattice).
    fn sphere(n: usize) -> PointCloud {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        PointCloud::from_points(
            (0..n)
                .map(|i| {
                    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                    let r = (1.0 - z * z).sqrt();
                    let t = golden * i as f64;
                    Point3::new(10.0 * r * t.cos(), 10.0 * r * t.sin(), 10.0 * z)
                })
                .collect(),
        )
    }

    #[test]
    fn sphere_normals_are_radial_and_oriented_outward() {
        let cloud = sphere(4000);
        for orientation in [
            Orientation::Propagate,
            Orientation::Outward,
            Orientation::Viewpoint(Point3::new(0.0, 0.0, 0.0)),
        ] {
            let cfg = NormalConfig {
                orientation,
                ..NormalConfig::default()
            };
            let est = estimate_normals(&cloud, &cfg).unwrap();
            let sign = if matches!(orientation, Orientation::Viewpoint(_)) {
                -1.0
            } else {
                1.0
            };
            for (p, n) in cloud.points.iter().zip(&est.normals) {
                let radial = p.coords.normalize() * sign;
                assert!(n.dot(&radial) > 0.999, "{orientation:?}: {n} at {p}");
            }
            // Surface variation on a sphere sampled at ~0.56 mm spacing is small but not 0.
            assert!(est.curvature.iter().all(|&c| c > 0.0 && c < 0.01));
        }
    }

    #[test]
    fn plane_has_zero_variation_and_bad_settings_fail() {
        let cloud = PointCloud::from_points(
            (0..400)
                .map(|i| Point3::new((i % 20) as f64, (i / 20) as f64, 0.0))
                .collect(),
        );
        let est = estimate_normals(&cloud, &NormalConfig::default()).unwrap();
        assert!(est.normals.iter().all(|n| n.z == 1.0));
        assert!(est.curvature.iter().all(|&c| c.abs() < 1e-12));
        for cfg in [
            NormalConfig {
                k: 2,
                ..NormalConfig::default()
            },
            NormalConfig {
                radius: Some(-1.0),
                ..NormalConfig::default()
            },
            NormalConfig {
                orientation: Orientation::FromExisting,
                ..NormalConfig::default()
            },
        ] {
            let e = estimate_normals(&cloud, &cfg).unwrap_err().to_string();
            assert!(e.starts_with("normals:") && !e.contains('\n'), "{e}");
        }
    }

    #[test]
    fn orientation_reads_from_toml() {
        let cfg: NormalConfig =
            toml::from_str("k = 12\norientation = { viewpoint = [1, 2, 3] }").unwrap();
        assert_eq!(
            cfg.orientation,
            Orientation::Viewpoint(Point3::new(1.0, 2.0, 3.0))
        );
        let cfg: NormalConfig = toml::from_str("orientation = \"propagate\"").unwrap();
        assert_eq!(cfg.orientation, Orientation::Propagate);
    }
}

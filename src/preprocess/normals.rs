//! Normals and surface variation by PCA over each point's neighbourhood (Open3D's definition:
//! covariance of the neighbourhood including the point, normal = eigenvector of the smallest
//! eigenvalue), then a consistent orientation.

use anyhow::{bail, Result};
use nalgebra::{Matrix3, Point3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

use rayon::prelude::*;

use crate::cloud::PointCloud;
use crate::spatial::Grid;

/// How the sign of each normal is chosen (PCA gives an axis, not a direction).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "OrientationSpec", into = "OrientationSpec")]
pub enum Orientation {
    /// [`FromExisting`](Self::FromExisting) when the cloud has normals, else
    /// [`Propagate`](Self::Propagate). The default.
    Auto,
    /// Every normal points toward this viewpoint (the scanner position), mm.
    Viewpoint(Point3<f64>),
    /// Hoppe's propagation: a minimum spanning forest of the k-NN graph with edge cost
    /// 1 - |nᵢ·nⱼ| + |nᵢ·d| + |nⱼ·d| (d the unit edge direction); each tree is walked from its
    /// highest point (largest z) with nz >= 0, every normal flipped to agree with its parent
    /// (outward on a closed surface).
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
    // nalgebra 0.30 can pair an eigenvalue with another one's eigenvector
    // (dimforge/nalgebra#1109; here on a neighbourhood that is exactly planar and square to an
    // axis, the normal came out in the plane): the normal is the eigenvector with the least
    // variance along it (v^T C v), and its eigenvalue is that variance when the index disagrees
    let rayleigh: [f64; 3] = std::array::from_fn(|c| {
        let v = eig.eigenvectors.column(c).normalize();
        v.dot(&(cov * v))
    });
    let least = (0..3)
        .min_by(|&a, &b| rayleigh[a].total_cmp(&rayleigh[b]))
        .unwrap_or(0);
    let small = eig.eigenvalues.imin();
    let value = match least == small {
        true => eig.eigenvalues[small],
        false => rayleigh[least],
    };
    let normal = eig.eigenvectors.column(least).normalize();
    let sum = eig.eigenvalues.sum();
    let variation = if sum > 0.0 {
        (value / sum).max(0.0)
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
            bail!("normals: radius must be a positive number of mm (got {r:?})");
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
            let sheets = propagate(p, normals, propagate_k, f64::INFINITY);
            let components = sheets.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
            format!(
                "propagated over a {propagate_k}-NN graph (minimum spanning tree, cost 1-|n·n'|+|n·d|+|n'·d|), \
                 {components} component(s), each seeded with nz >= 0 at its highest point"
            )
        }
        Orientation::Unoriented | Orientation::Auto => "unoriented (eigen-solver sign)".into(),
    }
}

/// Cost of the propagation edge between points `a` and `b` (normals `na`, `nb`; sign-free):
/// `1 - |na·nb|` (Hoppe), plus how far each normal leans along the edge, `|na·d| + |nb·d|`
/// (d the unit edge direction). Two points facing each other across a thin wall have parallel
/// axes, so Hoppe's term alone makes that edge one of the cheapest; the lean term makes it one
/// of the dearest (the edge runs along both normals) while neighbours on one smooth surface
/// keep a cost near 0.
fn edge_cost(a: &Point3<f64>, na: &Vector3<f64>, b: &Point3<f64>, nb: &Vector3<f64>) -> f64 {
    let d = (b - a).normalize();
    let lean = if d.iter().all(|c| c.is_finite()) {
        na.dot(&d).abs() + nb.dot(&d).abs()
    } else {
        0.0
    };
    1.0 - na.dot(nb).abs() + lean
}

/// The root of `i`'s set (with path halving).
fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let up = parent[parent[i as usize] as usize];
        parent[i as usize] = up;
        i = up;
    }
    i
}

/// How far either normal of an edge leans along it (`max(|na·d|, |nb·d|)`, d the unit edge
/// direction); 0 for coincident points.
fn lean(a: &Point3<f64>, na: &Vector3<f64>, b: &Point3<f64>, nb: &Vector3<f64>) -> f64 {
    let d = (b - a).normalize();
    match d.iter().all(|c| c.is_finite()) {
        true => na.dot(&d).abs().max(nb.dot(&d).abs()),
        false => 0.0,
    }
}

/// Orients `normals` (PCA axes of `points`) sheet by sheet: [`Orientation::Propagate`]'s
/// spanning forest over the `k`-NN graph without the edges along which either normal leans
/// more than `max_lean` (see [`lean`]): an edge that crosses a thin wall (or a gap) runs
/// along both normals and is left out, so propagation never carries a sign from one side of
/// a wall to the other. Returns each point's sheet (tree) index, 0 the sheet of the highest
/// point; each sheet is seeded with nz >= 0 at its highest point, which says nothing of an
/// inner face's outward sign (a caller judges each sheet with its own sign).
pub fn orient_sheets(
    points: &[Point3<f64>],
    normals: &mut [Vector3<f64>],
    k: usize,
    max_lean: f64,
) -> Vec<u32> {
    propagate(points, normals, k.max(1), max_lean)
}

/// Minimum spanning forest of the symmetric k-NN graph under [`edge_cost`] (Kruskal: edges
/// sorted by cost, ties by index; edges leaning more than `max_lean` left out), then each
/// tree is walked from its highest point (largest z; its normal turned up, nz >= 0), every
/// normal flipped to agree with its parent's. Returns each point's tree index, in the order
/// the trees were seeded.
fn propagate(
    points: &[Point3<f64>],
    normals: &mut [Vector3<f64>],
    k: usize,
    max_lean: f64,
) -> Vec<u32> {
    let lists: Vec<Vec<(f64, u32, u32)>> =
        Grid::knn_among(points, k + 1, f64::INFINITY, |i, found| {
            found
                .iter()
                .map(|&(_, j)| j as usize)
                .filter(|&j| j != i)
                .filter(|&j| lean(&points[i], &normals[i], &points[j], &normals[j]) <= max_lean)
                .map(|j| {
                    let (a, b) = (i.min(j), i.max(j));
                    let cost = edge_cost(&points[a], &normals[a], &points[b], &normals[b]);
                    (cost, a as u32, b as u32)
                })
                .collect()
        });
    let mut edges: Vec<(f64, u32, u32)> = lists.into_iter().flatten().collect();
    edges.par_sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2)));
    edges.dedup_by(|x, y| x.1 == y.1 && x.2 == y.2);
    let mut parent: Vec<u32> = (0..points.len() as u32).collect();
    let mut tree: Vec<Vec<u32>> = vec![Vec::new(); points.len()];
    for &(_, a, b) in &edges {
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[ra.max(rb) as usize] = ra.min(rb);
            tree[a as usize].push(b);
            tree[b as usize].push(a);
        }
    }
    let mut seeds: Vec<usize> = (0..points.len()).collect();
    seeds.par_sort_unstable_by(|&a, &b| points[b].z.total_cmp(&points[a].z).then(a.cmp(&b)));
    let mut sheet = vec![u32::MAX; points.len()];
    let mut stack = Vec::new();
    let mut components = 0;
    for seed in seeds {
        if sheet[seed] != u32::MAX {
            continue;
        }
        if normals[seed].z < 0.0 {
            normals[seed] = -normals[seed];
        }
        sheet[seed] = components;
        stack.push(seed);
        while let Some(from) = stack.pop() {
            for &to in &tree[from] {
                let to = to as usize;
                if sheet[to] == u32::MAX {
                    sheet[to] = components;
                    if normals[to].dot(&normals[from]) < 0.0 {
                        normals[to] = -normals[to];
                    }
                    stack.push(to);
                }
            }
        }
        components += 1;
    }
    sheet
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

    /// An exactly planar, axis-square neighbourhood (a 20 x 20 grid's edge point and its 20
    /// nearest, 0.05 mm apart, all at z = -0.01): nalgebra 0.30 pairs the zero eigenvalue with
    /// the in-plane y axis there (dimforge/nalgebra#1109); the normal must be z all the same.
    #[test]
    fn an_exact_plane_square_to_the_axes_gets_its_normal() {
        let at = |x: f64, y: f64| Point3::new(0.05 * x, 0.05 * y, -0.01);
        let mut near = vec![at(11.0, 0.0), at(11.0, 1.0), at(10.0, 0.0), at(12.0, 0.0)];
        near.extend(
            [
                (10.0, 1.0),
                (12.0, 1.0),
                (13.0, 0.0),
                (11.0, 2.0),
                (9.0, 0.0),
            ]
            .map(|(x, y)| at(x, y)),
        );
        near.extend(
            [
                (13.0, 1.0),
                (10.0, 2.0),
                (12.0, 2.0),
                (9.0, 1.0),
                (13.0, 2.0),
            ]
            .map(|(x, y)| at(x, y)),
        );
        near.extend(
            [
                (9.0, 2.0),
                (8.0, 0.0),
                (14.0, 0.0),
                (11.0, 3.0),
                (8.0, 1.0),
                (14.0, 1.0),
            ]
            .map(|(x, y)| at(x, y)),
        );
        let (n, variation) = pca_normal(&near, 0..near.len());
        assert!(n.z.abs() > 1.0 - 1e-12, "{n}");
        assert!(variation.abs() < 1e-12, "{variation}");
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

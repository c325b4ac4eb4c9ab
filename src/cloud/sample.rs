//! Area-uniform random sampling of a triangle mesh (deterministic for a seed).
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::types::{Mesh, PointCloud};

/// Points sampled on a mesh with their facet normals, and the face each came from.
#[derive(Debug, Clone)]
pub struct MeshSample {
    /// Points with unit facet normals.
    pub cloud: PointCloud,
    /// Index of the face each point lies on.
    pub faces: Vec<u32>,
}

/// Samples `n` points uniformly by area. Normals are the facets' (winding order). The same
/// mesh, `n` and `seed` give the same points. Fails on a mesh of zero area.
pub fn sample_mesh(mesh: &Mesh, n: usize, seed: u64) -> anyhow::Result<MeshSample> {
    let mut cumulative = Vec::with_capacity(mesh.faces.len());
    let mut normals = Vec::with_capacity(mesh.faces.len());
    let mut total = 0.0;
    for i in 0..mesh.faces.len() {
        let (normal, area) = mesh.face_normal_area(i);
        total += area;
        cumulative.push(total);
        normals.push(normal);
    }
    if total.is_nan() || total <= 0.0 {
        anyhow::bail!("mesh has zero surface area: nothing to sample");
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points = Vec::with_capacity(n);
    let mut point_normals: Vec<Vector3<f64>> = Vec::with_capacity(n);
    let mut faces = Vec::with_capacity(n);
    for _ in 0..n {
        let r = rng.gen::<f64>() * total;
        let f = cumulative
            .partition_point(|&c| c <= r)
            .min(mesh.faces.len() - 1);
        let [a, b, c] = mesh.faces[f].map(|v| mesh.vertices[v as usize]);
        let (mut u, mut v) = (rng.gen::<f64>(), rng.gen::<f64>());
        if u + v > 1.0 {
            u = 1.0 - u;
            v = 1.0 - v;
        }
        points.push(a + (b - a) * u + (c - a) * v);
        point_normals.push(normals[f]);
        faces.push(f as u32);
    }
    Ok(MeshSample {
        cloud: PointCloud {
            points,
            normals: Some(point_normals),
            fields: Vec::new(),
        },
        faces,
    })
}

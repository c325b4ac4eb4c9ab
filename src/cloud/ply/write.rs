//! Binary PLY writer: the format every cloud, deviation map and mesh is written in.
use crate::cloud::types::PointCloud;

/// Number type for positions and normals in written PLY files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlyPrecision {
    /// 32-bit float.
    F32,
    /// 64-bit float (default: exact round trip of the in-memory values).
    #[default]
    F64,
}

/// Encodes a cloud (and optional triangles) as binary little-endian PLY. Positions and normals
/// use `precision`; scalar fields are written as `float` (what CloudCompare-style readers show).
pub fn write_ply_bytes(
    cloud: &PointCloud,
    faces: Option<&[[u32; 3]]>,
    precision: PlyPrecision,
) -> Vec<u8> {
    let ty = match precision {
        PlyPrecision::F32 => "float",
        PlyPrecision::F64 => "double",
    };
    let mut head =
        String::from("ply\nformat binary_little_endian 1.0\ncomment written by polishbot\n");
    head += &format!("element vertex {}\n", cloud.len());
    for c in ["x", "y", "z"] {
        head += &format!("property {ty} {c}\n");
    }
    if cloud.normals.is_some() {
        for c in ["nx", "ny", "nz"] {
            head += &format!("property {ty} {c}\n");
        }
    }
    for f in &cloud.fields {
        let name: String = f
            .name
            .chars()
            .map(|c| if c.is_whitespace() { '_' } else { c })
            .collect();
        head += &format!("property float {name}\n");
    }
    if let Some(faces) = faces {
        head += &format!(
            "element face {}\nproperty list uchar int vertex_indices\n",
            faces.len()
        );
    }
    head += "end_header\n";
    let per_point = 3 * 8 * 2 + 4 * cloud.fields.len();
    let mut out = Vec::with_capacity(
        head.len() + cloud.len() * per_point + faces.map_or(0, |f| f.len() * 13),
    );
    out.extend_from_slice(head.as_bytes());
    let put = |out: &mut Vec<u8>, v: f64| match precision {
        PlyPrecision::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
        PlyPrecision::F64 => out.extend_from_slice(&v.to_le_bytes()),
    };
    for (i, p) in cloud.points.iter().enumerate() {
        p.coords.iter().for_each(|&v| put(&mut out, v));
        if let Some(n) = &cloud.normals {
            n[i].iter().for_each(|&v| put(&mut out, v));
        }
        for f in &cloud.fields {
            out.extend_from_slice(&(f.values[i] as f32).to_le_bytes());
        }
    }
    for f in faces.unwrap_or(&[]) {
        out.push(3);
        f.iter()
            .for_each(|&v| out.extend_from_slice(&(v as i32).to_le_bytes()));
    }
    out
}

//! Wavefront OBJ reader: `v` positions, `vn` normals (kept for point-only files), `f` polygons
//! (1-based or negative relative indices, `v/t/n` forms). Other statements are ignored.
use nalgebra::{Point3, Vector3};

use super::error::{fail, ParseError, Place};
use super::text;
use super::types::{Geometry, Mesh, PointCloud};

/// Parses an OBJ file.
pub fn read(bytes: &[u8]) -> Result<Geometry, ParseError> {
    if bytes.is_empty() {
        return fail(Place::Byte(0), "empty file");
    }
    let mut points = Vec::new();
    let mut normals = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    for item in text::lines(bytes) {
        let (line_no, _, line) = item?;
        let place = Place::Line(line_no);
        let mut tok = text::tokens(line);
        match tok.next() {
            Some("v") => points.push(Point3::from(xyz(&mut tok, place)?)),
            Some("vn") => normals.push(Vector3::from(xyz(&mut tok, place)?)),
            Some("f") => {
                let mut idx = Vec::new();
                for t in tok {
                    let i = face_corner(t, place)?;
                    let n = points.len() as i64;
                    let abs = if i > 0 { i - 1 } else { n + i };
                    if i == 0 || abs < 0 || abs >= n {
                        return fail(
                            place,
                            format!("face index {i} out of range ({n} vertices so far)"),
                        );
                    }
                    idx.push(abs as u32);
                }
                if idx.len() < 3 {
                    return fail(
                        place,
                        format!("face has {} vertices, needs at least 3", idx.len()),
                    );
                }
                for k in 1..idx.len() - 1 {
                    faces.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if points.is_empty() {
        return fail(Place::File, "no vertices (\"v\" lines)");
    }
    let mut cloud = PointCloud::from_points(points);
    if faces.is_empty() {
        if normals.len() == cloud.len() {
            cloud.normals = Some(normals);
        }
        cloud.check_finite()?;
        return Ok(Geometry::Cloud(cloud));
    }
    cloud.check_finite()?;
    Ok(Geometry::Mesh {
        mesh: Mesh {
            vertices: cloud.points.clone(),
            faces,
        },
        attributes: cloud,
    })
}

/// The vertex index of a face corner `v`, `v/t`, `v//n` or `v/t/n`: every index given must be
/// a non-zero integer (texture and normal indices are not used, but a corner `1/x/1` is not
/// a face this reader understands).
fn face_corner(t: &str, place: Place) -> Result<i64, ParseError> {
    let bad = || ParseError::new(place, format!("bad face corner {:?}", text::shorten(t)));
    let parts: Vec<&str> = t.split('/').collect();
    if parts.len() > 3 {
        return Err(bad());
    }
    let index = |s: &str| s.parse::<i64>().ok().filter(|&i| i != 0);
    for (k, s) in parts.iter().enumerate().skip(1) {
        // `v//n`: the texture index may be left out
        if !(k == 1 && s.is_empty() && parts.len() == 3) && index(s).is_none() {
            return Err(bad());
        }
    }
    parts[0].parse().map_err(|_| bad())
}

fn xyz<'a>(tok: &mut impl Iterator<Item = &'a str>, place: Place) -> Result<[f64; 3], ParseError> {
    let mut c = [0.0; 3];
    for v in &mut c {
        let t = tok
            .next()
            .ok_or_else(|| ParseError::new(place, "expected 3 coordinates"))?;
        *v = text::number(t, place)?;
    }
    Ok(c)
}

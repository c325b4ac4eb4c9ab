//! STL reader (binary and ascii; ascii keywords in any case). Vertices are merged by exact position, so the mesh counts
//! unique vertices; facet normals in the file are ignored (winding defines them).
use std::collections::HashMap;

use nalgebra::Point3;

use super::error::{fail, ParseError, Place};
use super::text::{self, Cursor};
use super::types::{Geometry, Mesh, PointCloud};

/// Merges equal positions into one vertex index.
#[derive(Default)]
struct Welder {
    index: HashMap<[u64; 3], u32>,
    vertices: Vec<Point3<f64>>,
}

impl Welder {
    fn add(&mut self, p: [f64; 3], place: Place) -> Result<u32, ParseError> {
        if !p.iter().all(|c| c.is_finite()) {
            return fail(place, "coordinate is NaN or infinite");
        }
        // +0.0 and -0.0 are the same position.
        let key = p.map(|c| (c + 0.0).to_bits());
        let next = self.vertices.len() as u32;
        let id = *self.index.entry(key).or_insert(next);
        if id == next {
            self.vertices.push(Point3::from(p));
        }
        Ok(id)
    }

    fn finish(self, faces: Vec<[u32; 3]>) -> Geometry {
        let attributes = PointCloud::from_points(self.vertices.clone());
        Geometry::Mesh {
            mesh: Mesh {
                vertices: self.vertices,
                faces,
            },
            attributes,
        }
    }
}

/// Parses an STL file, binary or ascii.
pub fn read(bytes: &[u8]) -> Result<Geometry, ParseError> {
    if bytes.is_empty() {
        return fail(Place::Byte(0), "empty file");
    }
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if 84 + 50 * n == bytes.len() {
            return read_binary(bytes, n);
        }
    }
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(512)]);
    let head = head.trim_start().as_bytes();
    // keywords in any case: CAD exporters write `SOLID`, `FACET NORMAL`, `VERTEX`
    let solid = head.len() >= 5 && head[..5].eq_ignore_ascii_case(b"solid");
    if solid && std::str::from_utf8(bytes).is_ok() {
        return read_ascii(bytes);
    }
    if bytes.len() < 84 {
        return fail(
            Place::Byte(bytes.len()),
            "truncated: a binary STL needs an 84-byte header",
        );
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    fail(
        Place::Byte(80),
        format!(
            "binary STL header says {n} triangles ({} bytes), the file has {} bytes",
            84 + 50 * n,
            bytes.len()
        ),
    )
}

fn read_binary(bytes: &[u8], n: usize) -> Result<Geometry, ParseError> {
    let mut cur = Cursor::new(bytes, 84);
    let mut welder = Welder::default();
    let mut faces = Vec::with_capacity(n);
    for t in 0..n {
        let rec = cur.take(50, "triangle record")?;
        let mut face = [0u32; 3];
        for (k, slot) in face.iter_mut().enumerate() {
            let base = 12 + 12 * k;
            let c = |j: usize| {
                f32::from_le_bytes(rec[base + 4 * j..base + 4 * j + 4].try_into().unwrap()) as f64
            };
            *slot = welder.add([c(0), c(1), c(2)], Place::Face(t))?;
        }
        faces.push(face);
    }
    Ok(welder.finish(faces))
}

/// Where an ascii STL reader stands: `facet` is the line of the open facet, `corners` the
/// vertices of its loop so far, `loop_closed` whether its `endloop` was read.
#[derive(Default)]
struct Facet {
    line: Option<usize>,
    corners: Vec<u32>,
    loop_closed: bool,
}

fn read_ascii(bytes: &[u8]) -> Result<Geometry, ParseError> {
    let mut welder = Welder::default();
    let mut faces = Vec::new();
    let mut open = Facet::default();
    let mut ended = false;
    let mut last_line = 0;
    for item in text::lines(bytes) {
        let (line_no, _, line) = item?;
        last_line = line_no;
        let place = Place::Line(line_no);
        let mut tok = text::tokens(line);
        let first = tok.next();
        let word = first.map(str::to_ascii_lowercase);
        let word = word.as_deref();
        if ended && !matches!(word, None | Some("solid")) {
            return fail(
                place,
                "text after endsolid (another solid must begin with solid)",
            );
        }
        match word {
            Some("facet") => {
                if let Some(l) = open.line {
                    return fail(place, format!("facet inside the facet begun at line {l}"));
                }
                open = Facet {
                    line: Some(line_no),
                    ..Facet::default()
                };
            }
            Some("outer") if open.line.is_none() => return fail(place, "loop outside a facet"),
            Some("vertex") => {
                let mut c = [0.0; 3];
                for v in &mut c {
                    *v = text::number(tok.next().unwrap_or(""), place)?;
                }
                if open.line.is_none() || open.loop_closed {
                    return fail(place, "vertex outside a facet's loop");
                }
                if open.corners.len() == 3 {
                    return fail(place, "facet with more than 3 vertices");
                }
                open.corners.push(welder.add(c, place)?);
            }
            Some("endloop") => {
                if open.corners.len() != 3 || open.loop_closed {
                    return fail(
                        place,
                        format!("facet has {} vertices, needs 3", open.corners.len()),
                    );
                }
                faces.push([open.corners[0], open.corners[1], open.corners[2]]);
                open.loop_closed = true;
            }
            Some("endfacet") => {
                if !open.loop_closed {
                    return fail(place, "endfacet without a complete loop before it");
                }
                open = Facet::default();
            }
            Some("endsolid") => match open.line {
                Some(l) => {
                    return fail(
                        place,
                        format!("endsolid inside the facet begun at line {l}"),
                    )
                }
                None => ended = true,
            },
            Some("solid") => ended = false,
            Some("outer") | None => {}
            Some(_) => {
                let other = first.unwrap_or("");
                return fail(
                    place,
                    format!("unexpected {:?} in ascii STL", text::shorten(other)),
                );
            }
        }
    }
    let end = Place::Line(last_line);
    if let Some(l) = open.line {
        return fail(
            end,
            format!("file ends inside the facet begun at line {l} (cut short?)"),
        );
    }
    if faces.is_empty() {
        return fail(Place::File, "ascii STL has no facets");
    }
    if !ended {
        return fail(end, "file ends without endsolid (cut short?)");
    }
    Ok(welder.finish(faces))
}

//! PLY reader (ascii, binary little and big endian; any scalar type; vertex normals, scalar
//! fields and faces; other elements skipped). The writer is in [`write`].

mod binary;
mod header;
mod write;

pub use write::{write_ply_bytes, PlyPrecision};

use super::error::{fail, ParseError, Place};
use super::text;
use super::types::{Geometry, Mesh, PointCloud, ScalarField};
use header::{
    is_face_list, parse_header, vertex_layout, Body, Element, Encoding, Kind, Scalar, Sink,
};

/// Longest polygon an ascii list may hold (a sanity bound: a million vertices in one face).
const MAX_ASCII_LIST: usize = 1_000_000;

/// Parses a PLY file.
pub fn read(bytes: &[u8]) -> Result<Geometry, ParseError> {
    let header = parse_header(bytes)?;
    let Some(vi) = header.elements.iter().position(|e| e.name == "vertex") else {
        return fail(Place::Line(1), "no vertex element");
    };
    let layout = vertex_layout(&header.elements[vi], 1)?;
    let mut sink = Sink {
        cloud: PointCloud::default(),
        normals: Vec::new(),
        faces: Vec::new(),
        has_faces: false,
    };
    sink.cloud.fields = layout
        .fields
        .iter()
        .map(|(_, name)| ScalarField {
            name: name.clone(),
            values: Vec::new(),
        })
        .collect();
    sink.has_faces = header.elements.iter().any(|el| {
        el.name == "face" && el.count > 0 && el.props.iter().any(|p| is_face_list(el, p))
    });
    let body = Body {
        bytes,
        header: &header,
        vertex: vi,
        layout: &layout,
    };
    match header.encoding {
        Encoding::Ascii => read_ascii(&body, &mut sink)?,
        Encoding::Little | Encoding::Big => binary::read(&body, &mut sink)?,
    }
    let Sink {
        mut cloud,
        normals,
        faces,
        has_faces,
    } = sink;
    if layout.normal.is_some() {
        cloud.normals = Some(normals);
    }
    cloud.check_finite()?;
    if has_faces {
        let mesh = Mesh {
            vertices: cloud.points.clone(),
            faces,
        };
        mesh.check_faces()?;
        Ok(Geometry::Mesh {
            mesh,
            attributes: cloud,
        })
    } else {
        Ok(Geometry::Cloud(cloud))
    }
}

fn read_ascii(body: &Body, sink: &mut Sink) -> Result<(), ParseError> {
    let (bytes, h, vi, layout) = (body.bytes, body.header, body.vertex, body.layout);
    // Blank lines are skipped; every other line is one record.
    let mut lines = text::lines(&bytes[h.body..]).filter_map(|item| match item {
        Ok((_, _, line)) if line.trim().is_empty() => None,
        Ok((n, _, line)) => Some(Ok((h.body_line - 1 + n, line))),
        Err(e) => Some(Err(shift_line(e, h.body_line - 1))),
    });
    let mut values: Vec<f64> = Vec::new();
    let mut line_no = h.body_line - 1;
    for (ei, el) in h.elements.iter().enumerate() {
        for index in 0..el.count {
            let Some(item) = lines.next() else {
                return fail(
                    Place::Line(line_no + 1),
                    format!(
                        "file ends at {} {index} of {} declared in the header",
                        el.name, el.count
                    ),
                );
            };
            let (n, line) = item?;
            line_no = n;
            ascii_record(el, line, Place::Line(n), sink, &mut values)?;
            if ei == vi {
                sink.vertex(layout, &values);
            }
        }
    }
    if let Some(item) = lines.next() {
        let (n, _) = item?;
        let last = h.elements.last().expect("the vertex element exists");
        return fail(
            Place::Line(n),
            format!(
                "more rows than the header declares (it ends with {} {} rows)",
                last.count, last.name
            ),
        );
    }
    Ok(())
}

/// Reads one ascii record of `el` into `values` (NaN for a list), triangulating face lists.
/// Every value must fit its declared type, and the line must hold no more values than the
/// element's properties take.
fn ascii_record(
    el: &Element,
    line: &str,
    place: Place,
    sink: &mut Sink,
    values: &mut Vec<f64>,
) -> Result<(), ParseError> {
    let mut tok = text::tokens(line);
    let mut next = |what: &str, ty: Scalar| -> Result<f64, ParseError> {
        let t = tok
            .next()
            .ok_or_else(|| ParseError::new(place, format!("missing value for {what}")))?;
        let v = text::number(t, place)?;
        if !ty.holds(v) {
            return fail(
                place,
                format!(
                    "{what}: {} does not fit its type {}",
                    text::shorten(t),
                    ty.name()
                ),
            );
        }
        Ok(v)
    };
    values.clear();
    for p in &el.props {
        match p.kind {
            Kind::Scalar(ty) => values.push(next(&p.name, ty)?),
            Kind::List { count, item } => {
                let n = next(&p.name, count)?;
                if !(0.0..=MAX_ASCII_LIST as f64).contains(&n) {
                    return fail(place, format!("bad list length {n}"));
                }
                let items: Vec<f64> = (0..n as usize)
                    .map(|_| next(&p.name, item))
                    .collect::<Result<_, _>>()?;
                if is_face_list(el, p) {
                    sink.polygon(&items, place)?;
                }
                values.push(f64::NAN);
            }
        }
    }
    if tok.next().is_some() {
        return fail(
            place,
            format!(
                "more values than the {} properties of {} declared in the header",
                el.props.len(),
                el.name
            ),
        );
    }
    Ok(())
}

fn shift_line(mut e: ParseError, by: usize) -> ParseError {
    if let Place::Line(n) = e.place {
        e.place = Place::Line(n + by);
    }
    e
}

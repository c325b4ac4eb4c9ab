//! The binary PLY body: fixed-size records decoded column by column, records with lists one
//! by one; nothing may follow the declared elements.
use nalgebra::{Point3, Vector3};

use super::header::{is_face_list, Body, Encoding, Kind, Scalar, Sink, VertexLayout};
use crate::cloud::error::{fail, ParseError, Place};
use crate::cloud::text::{self, Cursor};

/// Reads the body of a binary PLY (either byte order).
pub(super) fn read(body: &Body, sink: &mut Sink) -> Result<(), ParseError> {
    let (bytes, h, vi, layout) = (body.bytes, body.header, body.vertex, body.layout);
    let big = h.encoding == Encoding::Big;
    let mut cur = Cursor::new(bytes, h.body);
    let mut values: Vec<f64> = Vec::new();
    for (ei, el) in h.elements.iter().enumerate() {
        let fixed: Option<Vec<Scalar>> = el
            .props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => Some(s),
                Kind::List { .. } => None,
            })
            .collect();
        if let Some(types) = fixed {
            // Fixed-size records: one bounds check for the whole element.
            let stride: usize = types.iter().map(|s| s.size()).sum();
            let total = stride
                .checked_mul(el.count)
                .ok_or_else(|| ParseError::new(Place::Byte(cur.pos), "element too large"))?;
            let body = cur.take(
                total,
                &format!("{} {} records of {} bytes", el.count, el.name, stride),
            )?;
            if ei == vi {
                read_fixed_vertices(body, &types, el.count, big, layout, sink);
            }
            continue;
        }
        if ei == vi {
            reserve(sink, layout, text::capacity(el.count, cur.remaining(), 1));
        }
        for _ in 0..el.count {
            values.clear();
            let rec_start = cur.pos;
            for p in &el.props {
                match p.kind {
                    Kind::Scalar(s) => values.push(s.decode(cur.take(s.size(), &p.name)?, big)),
                    Kind::List { count, item } => {
                        let n = count.decode(cur.take(count.size(), &p.name)?, big);
                        if n < 0.0 {
                            return fail(
                                Place::Byte(rec_start),
                                format!("negative list length {n}"),
                            );
                        }
                        let raw = cur.take(n as usize * item.size(), &p.name)?;
                        if is_face_list(el, p) {
                            let items: Vec<f64> = raw
                                .chunks_exact(item.size())
                                .map(|b| item.decode(b, big))
                                .collect();
                            sink.polygon(&items, Place::Byte(rec_start))?;
                        }
                        values.push(f64::NAN);
                    }
                }
            }
            if ei == vi {
                sink.vertex(layout, &values);
            }
        }
    }
    let rest = &bytes[cur.pos..];
    if !rest.iter().all(u8::is_ascii_whitespace) {
        return fail(
            Place::Byte(cur.pos),
            format!(
                "{} bytes after the data the header declares (more rows than it says?)",
                rest.len()
            ),
        );
    }
    Ok(())
}

/// Decodes fixed-size vertex records, reading only the columns in use.
fn read_fixed_vertices(
    body: &[u8],
    types: &[Scalar],
    count: usize,
    big: bool,
    layout: &VertexLayout,
    sink: &mut Sink,
) {
    let offsets: Vec<usize> = types
        .iter()
        .scan(0, |off, s| {
            let here = *off;
            *off += s.size();
            Some(here)
        })
        .collect();
    let stride: usize = types.iter().map(|s| s.size()).sum();
    let column = |i: usize| (offsets[i], types[i]);
    let xyz = layout.xyz.map(column);
    let normal = layout.normal.map(|n| n.map(column));
    let fields: Vec<(usize, Scalar)> = layout.fields.iter().map(|(i, _)| column(*i)).collect();
    reserve(sink, layout, count);
    let get = |rec: &[u8], (off, s): (usize, Scalar)| s.decode(&rec[off..off + s.size()], big);
    for rec in body.chunks_exact(stride.max(1)).take(count) {
        sink.cloud.points.push(Point3::new(
            get(rec, xyz[0]),
            get(rec, xyz[1]),
            get(rec, xyz[2]),
        ));
        if let Some(n) = normal {
            sink.normals
                .push(Vector3::new(get(rec, n[0]), get(rec, n[1]), get(rec, n[2])));
        }
        for (f, &col) in sink.cloud.fields.iter_mut().zip(&fields) {
            f.values.push(get(rec, col));
        }
    }
}

fn reserve(sink: &mut Sink, layout: &VertexLayout, n: usize) {
    sink.cloud.points.reserve(n);
    if layout.normal.is_some() {
        sink.normals.reserve(n);
    }
    for f in &mut sink.cloud.fields {
        f.values.reserve(n);
    }
}

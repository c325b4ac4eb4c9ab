//! OFF reader: `OFF` (or `COFF`/`NOFF`) header, counts line, one vertex per line, one polygon
//! per line (`n i0 .. in-1`, extra colour values ignored). `#` starts a comment.
use nalgebra::Point3;

use super::error::{fail, ParseError, Place};
use super::text;
use super::types::{Geometry, Mesh, PointCloud};

/// Parses an OFF file.
pub fn read(bytes: &[u8]) -> Result<Geometry, ParseError> {
    if bytes.is_empty() {
        return fail(Place::Byte(0), "empty file");
    }
    // Non-blank lines with comments cut off, read lazily (a list of them all would cost more
    // memory than the file).
    let mut it = text::lines(bytes).filter_map(|item| match item {
        Ok((n, _, line)) => {
            let line = line.split('#').next().unwrap_or("").trim();
            (!line.is_empty()).then_some(Ok((n, line)))
        }
        Err(e) => Some(Err(e)),
    });
    let end = Place::Line(bytes.split(|&b| b == b'\n').count());
    let (l, head) = it
        .next()
        .ok_or_else(|| ParseError::new(end, "no OFF header"))??;
    let mut head_tok = text::tokens(head);
    if !matches!(head_tok.next(), Some("OFF" | "COFF" | "NOFF" | "CNOFF")) {
        return fail(Place::Line(l), "not an OFF file (first word must be OFF)");
    }
    let rest: Vec<&str> = head_tok.collect();
    let (l, counts) = if rest.is_empty() {
        let (l, line) = it
            .next()
            .ok_or_else(|| ParseError::new(end, "file ends before the counts line"))??;
        (l, text::tokens(line).collect::<Vec<_>>())
    } else {
        (l, rest)
    };
    if counts.len() < 2 {
        return fail(Place::Line(l), "counts line needs vertex and face counts");
    }
    let nv = text::count(counts[0], Place::Line(l))?;
    let nf = text::count(counts[1], Place::Line(l))?;
    let mut points = Vec::with_capacity(text::capacity(nv, bytes.len(), 6));
    for i in 0..nv {
        let (l, line) = it
            .next()
            .ok_or_else(|| ParseError::new(end, format!("file ends at vertex {i} of {nv}")))??;
        let t: Vec<&str> = text::tokens(line).collect();
        if t.len() < 3 {
            return fail(Place::Line(l), "vertex needs 3 coordinates");
        }
        let mut c = [0.0; 3];
        for (v, tok) in c.iter_mut().zip(&t) {
            *v = text::number(tok, Place::Line(l))?;
        }
        points.push(Point3::from(c));
    }
    let mut faces = Vec::with_capacity(text::capacity(nf, bytes.len(), 8));
    for f in 0..nf {
        let (l, line) = it
            .next()
            .ok_or_else(|| ParseError::new(end, format!("file ends at face {f} of {nf}")))??;
        let place = Place::Line(l);
        let t: Vec<&str> = text::tokens(line).collect();
        let n = text::count(t.first().copied().unwrap_or(""), place)?;
        if n < 3 || t.len() <= n {
            return fail(
                place,
                format!("face declares {n} vertices, needs at least 3 and that many indices"),
            );
        }
        let idx: Vec<u32> = t[1..=n]
            .iter()
            .map(|s| {
                let v = text::count(s, place)?;
                if v >= nv {
                    return fail(
                        place,
                        format!("vertex index {v} out of range ({nv} vertices)"),
                    );
                }
                Ok(v as u32)
            })
            .collect::<Result<_, _>>()?;
        for k in 1..n - 1 {
            faces.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    if let Some(item) = it.next() {
        return fail(
            Place::Line(item?.0),
            format!("more lines than the header declares ({nv} vertices, {nf} faces)"),
        );
    }
    let cloud = PointCloud::from_points(points);
    cloud.check_finite()?;
    if faces.is_empty() {
        return Ok(Geometry::Cloud(cloud));
    }
    Ok(Geometry::Mesh {
        mesh: Mesh {
            vertices: cloud.points.clone(),
            faces,
        },
        attributes: cloud,
    })
}

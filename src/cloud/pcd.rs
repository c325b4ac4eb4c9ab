//! PCD reader (Point Cloud Library format v0.7): ascii and binary data; `binary_compressed`
//! is refused with a message. Fields with COUNT > 1 (e.g. descriptors) are skipped.
use super::columns::Columns;
use super::error::{fail, ParseError, Place};
use super::text::{self, Cursor};
use super::types::Geometry;

struct Field {
    name: String,
    size: usize,
    kind: char,
    count: usize,
}

/// The header of a PCD file: its fields, point count, data mode and where the data starts.
struct Header {
    fields: Vec<Field>,
    /// Points the header declares.
    n: usize,
    /// "ascii", "binary" or what else the DATA line says.
    mode: String,
    /// Byte offset of the data.
    body: usize,
    /// Line number of the data's first line.
    body_line: usize,
    /// The DATA line (for header errors found after it).
    data_place: Place,
}

/// Parses a PCD file.
pub fn read(bytes: &[u8]) -> Result<Geometry, ParseError> {
    if bytes.is_empty() {
        return fail(Place::Byte(0), "empty file");
    }
    let h = header(bytes)?;
    // Only single-valued fields become columns.
    let scalar_names: Vec<String> = h
        .fields
        .iter()
        .filter(|f| f.count == 1)
        .map(|f| f.name.clone())
        .collect();
    let layout = Columns::from_names(&scalar_names, h.data_place)?;
    let mut cloud = layout.empty_cloud(text::capacity(h.n, bytes.len() - h.body, 3));
    let mut rows = |row: &[f64]| layout.push(&mut cloud, row);
    match h.mode.as_str() {
        "ascii" => read_ascii(bytes, &h, scalar_names.len(), &mut rows)?,
        "binary" => read_binary(bytes, &h, scalar_names.len(), &mut rows)?,
        other => {
            return fail(
                h.data_place,
                format!("DATA {other:?} is not supported (ascii or binary only)"),
            )
        }
    }
    cloud.check_finite()?;
    Ok(Geometry::Cloud(cloud))
}

/// Reads the header lines up to DATA and checks the fields.
fn header(bytes: &[u8]) -> Result<Header, ParseError> {
    let (mut names, mut sizes, mut kinds, mut counts) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut points: Option<(usize, Place)> = None;
    let (mut width, mut height) = (None, (1usize, None));
    let mut data = None;
    for item in text::lines(bytes) {
        let (line_no, start, line) = item?;
        let place = Place::Line(line_no);
        let mut tok = text::tokens(line);
        let key = tok.next();
        let rest: Vec<&str> = tok.collect();
        match key {
            None => {}
            Some(k) if k.starts_with('#') => {}
            Some("VERSION") | Some("VIEWPOINT") => {}
            Some("FIELDS") => names = rest.iter().map(|s| s.to_string()).collect(),
            Some("SIZE") => {
                sizes = rest
                    .iter()
                    .map(|s| text::count(s, place))
                    .collect::<Result<_, _>>()?
            }
            Some("TYPE") => {
                kinds = rest
                    .iter()
                    .map(|s| s.chars().next().unwrap_or('?'))
                    .collect()
            }
            Some("COUNT") => {
                counts = rest
                    .iter()
                    .map(|s| text::count(s, place))
                    .collect::<Result<_, _>>()?
            }
            Some("WIDTH") => width = Some((text::count(first(&rest), place)?, place)),
            Some("HEIGHT") => height = (text::count(first(&rest), place)?, Some(place)),
            Some("POINTS") => points = Some((text::count(first(&rest), place)?, place)),
            Some("DATA") => {
                let body = (start + line.len() + 1).min(bytes.len());
                data = Some((
                    rest.first().copied().unwrap_or("").to_string(),
                    body,
                    line_no + 1,
                    place,
                ));
                break;
            }
            Some(other) => {
                return fail(
                    place,
                    format!("unknown PCD header keyword {:?}", text::shorten(other)),
                )
            }
        }
    }
    let Some((mode, body, body_line, data_place)) = data else {
        return fail(Place::Byte(bytes.len()), "PCD header has no DATA line");
    };
    if counts.is_empty() {
        counts = vec![1; names.len()];
    }
    if names.is_empty()
        || sizes.len() != names.len()
        || kinds.len() != names.len()
        || counts.len() != names.len()
    {
        return fail(
            data_place,
            "FIELDS, SIZE, TYPE and COUNT must list the same number of entries",
        );
    }
    let fields: Vec<Field> = (0..names.len())
        .map(|i| Field {
            name: names[i].clone(),
            size: sizes[i],
            kind: kinds[i],
            count: counts[i],
        })
        .collect();
    for f in &fields {
        let ok = matches!(
            (f.kind, f.size),
            ('F', 4) | ('F', 8) | ('I' | 'U', 1 | 2 | 4 | 8)
        );
        if !ok {
            return fail(
                data_place,
                format!(
                    "field {} has unsupported TYPE {} SIZE {}",
                    f.name, f.kind, f.size
                ),
            );
        }
    }
    let n = point_count(points, width, height, data_place)?;
    Ok(Header {
        fields,
        n,
        mode,
        body,
        body_line,
        data_place,
    })
}

/// The first token of a header line's values ("" when there is none: refused as a count).
fn first<'a>(rest: &[&'a str]) -> &'a str {
    rest.first().copied().unwrap_or("")
}

/// The points the header declares: `POINTS`, which must equal `WIDTH` × `HEIGHT` when `WIDTH`
/// is given too (a disagreement is refused at the `POINTS` line), else `WIDTH` × `HEIGHT`.
fn point_count(
    points: Option<(usize, Place)>,
    width: Option<(usize, Place)>,
    (height, height_place): (usize, Option<Place>),
    data_place: Place,
) -> Result<usize, ParseError> {
    let area = match width {
        Some((w, place)) => Some(w.checked_mul(height).ok_or_else(|| {
            ParseError::new(height_place.unwrap_or(place), "WIDTH × HEIGHT is too large")
        })?),
        None => None,
    };
    match (points, area) {
        (Some((n, place)), Some(a)) if n != a => fail(
            place,
            format!(
                "POINTS {n} is not WIDTH × HEIGHT ({} × {height} = {a})",
                width.map_or(0, |w| w.0)
            ),
        ),
        (Some((n, _)), _) => Ok(n),
        (None, Some(a)) => Ok(a),
        (None, None) => fail(data_place, "no POINTS or WIDTH"),
    }
}

/// The ascii data: `n` rows of the fields' values, each checked against its type.
fn read_ascii(
    bytes: &[u8],
    h: &Header,
    columns: usize,
    push: &mut dyn FnMut(&[f64]),
) -> Result<(), ParseError> {
    let (fields, n, body, body_line) = (&h.fields, h.n, h.body, h.body_line);
    let data_place = h.data_place;
    let mut row = Vec::with_capacity(columns);
    let mut lines =
        text::lines(&bytes[body..]).filter(|l| !matches!(l, Ok((_, _, s)) if s.trim().is_empty()));
    let width = fields
        .iter()
        .try_fold(0usize, |w, f| w.checked_add(f.count))
        .ok_or_else(|| ParseError::new(data_place, "COUNT total is too large"))?;
    for i in 0..n {
        let (k, _, line) = match lines.next() {
            Some(item) => item?,
            None => return fail(Place::Point(i), format!("file ends at point {i} of {n}")),
        };
        let place = Place::Line(body_line + k - 1);
        let toks = text::row(text::tokens(line), width, place)?;
        row.clear();
        let mut t = 0;
        for f in fields {
            if f.count == 1 {
                let v = text::number(toks[t], place)?;
                if !fits(f, v) {
                    return fail(
                        place,
                        format!(
                            "{}: {} does not fit TYPE {} SIZE {}",
                            f.name,
                            text::shorten(toks[t]),
                            f.kind,
                            f.size
                        ),
                    );
                }
                row.push(v);
            }
            t += f.count;
        }
        push(&row);
    }
    if let Some(item) = lines.next() {
        let (k, _, _) = item?;
        return fail(
            Place::Line(body_line + k - 1),
            format!("more rows than the header's {n} points"),
        );
    }
    Ok(())
}

/// The binary data: `n` packed records of the fields.
fn read_binary(
    bytes: &[u8],
    h: &Header,
    columns: usize,
    push: &mut dyn FnMut(&[f64]),
) -> Result<(), ParseError> {
    let (fields, n, body, data_place) = (&h.fields, h.n, h.body, h.data_place);
    let mut row = Vec::with_capacity(columns);
    let mut cur = Cursor::new(bytes, body);
    for _ in 0..n {
        row.clear();
        for f in fields {
            let len = f
                .size
                .checked_mul(f.count)
                .ok_or_else(|| ParseError::new(data_place, "field too large"))?;
            let raw = cur.take(len, &f.name)?;
            if f.count == 1 {
                row.push(decode(raw, f.kind));
            }
        }
        push(&row);
    }
    if !bytes[cur.pos..].iter().all(u8::is_ascii_whitespace) {
        return fail(
            Place::Byte(cur.pos),
            format!("{} bytes after the header's {n} points", cur.remaining()),
        );
    }
    Ok(())
}

/// Whether an ascii value can be stored in the field's type: whole numbers within range for
/// `I` and `U`, at most `f32::MAX` in magnitude for `F` of size 4 (NaN and infinities pass
/// here: positions and normals are checked for them with their point index).
fn fits(f: &Field, v: f64) -> bool {
    let bits = 8 * f.size as i32;
    match f.kind {
        'F' if f.size == 4 => !v.is_finite() || v.abs() <= f32::MAX as f64,
        'F' => true,
        'U' => v.fract() == 0.0 && v >= 0.0 && v < 2f64.powi(bits),
        _ => v.fract() == 0.0 && v >= -(2f64.powi(bits - 1)) && v < 2f64.powi(bits - 1),
    }
}

fn decode(b: &[u8], kind: char) -> f64 {
    let mut a = [0u8; 8];
    a[..b.len()].copy_from_slice(b);
    match (kind, b.len()) {
        ('F', 4) => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        ('F', _) => f64::from_le_bytes(a),
        ('U', _) => u64::from_le_bytes(a) as f64,
        (_, n) => {
            // Sign-extend an n-byte little-endian integer.
            let shift = 64 - 8 * n as u32;
            ((i64::from_le_bytes(a) << shift) >> shift) as f64
        }
    }
}

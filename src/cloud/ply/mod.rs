//! PLY reader (ascii, binary little and big endian; any scalar type; vertex normals, scalar
//! fields and faces; other elements skipped). The writer is in [`write`].
use nalgebra::{Point3, Vector3};

mod binary;
mod write;

pub use write::{write_ply_bytes, PlyPrecision};

use super::error::{fail, ParseError, Place};
use super::text;
use super::types::{Geometry, Mesh, PointCloud, ScalarField};

/// Longest polygon an ascii list may hold (a sanity bound: a million vertices in one face).
const MAX_ASCII_LIST: usize = 1_000_000;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The name used in headers (for messages).
    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    /// Whether an ascii value can be stored in this type: whole numbers within range for the
    /// integer types, at most `f32::MAX` in magnitude for float (NaN and infinities pass here:
    /// positions and normals are checked for them with their point index).
    fn holds(self, v: f64) -> bool {
        let (lo, hi) = match self {
            Scalar::I8 => (i8::MIN as f64, i8::MAX as f64),
            Scalar::U8 => (0.0, u8::MAX as f64),
            Scalar::I16 => (i16::MIN as f64, i16::MAX as f64),
            Scalar::U16 => (0.0, u16::MAX as f64),
            Scalar::I32 => (i32::MIN as f64, i32::MAX as f64),
            Scalar::U32 => (0.0, u32::MAX as f64),
            Scalar::F32 => return !v.is_finite() || v.abs() <= f32::MAX as f64,
            Scalar::F64 => return true,
        };
        v.fract() == 0.0 && (lo..=hi).contains(&v)
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one value from exactly `self.size()` bytes.
    fn decode(self, b: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => num!(i16, 2),
            Scalar::U16 => num!(u16, 2),
            Scalar::I32 => num!(i32, 4),
            Scalar::U32 => num!(u32, 4),
            Scalar::F32 => num!(f32, 4),
            Scalar::F64 => num!(f64, 8),
        }
    }
}

#[derive(Debug, Clone)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Byte offset where the body starts.
    body: usize,
    /// Line number of the first body line (ascii).
    body_line: usize,
}

fn parse_header(bytes: &[u8]) -> Result<Header, ParseError> {
    if bytes.is_empty() {
        return fail(Place::Byte(0), "empty file");
    }
    if !(bytes.starts_with(b"ply\n") || bytes.starts_with(b"ply\r\n")) {
        return fail(
            Place::Line(1),
            "not a PLY file (first line must be \"ply\")",
        );
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for item in text::lines(bytes) {
        let (line_no, start, line) = item?;
        let place = Place::Line(line_no);
        let mut tok = text::tokens(line);
        match tok.next() {
            None | Some("ply") | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                encoding = Some(match (tok.next(), tok.next()) {
                    (Some("ascii"), Some("1.0")) => Encoding::Ascii,
                    (Some("binary_little_endian"), Some("1.0")) => Encoding::Little,
                    (Some("binary_big_endian"), Some("1.0")) => Encoding::Big,
                    _ => return fail(place, format!("unknown PLY format {:?}", line.trim())),
                });
            }
            Some("element") => {
                let name = tok
                    .next()
                    .ok_or_else(|| ParseError::new(place, "element without a name"))?;
                let count = text::count(tok.next().unwrap_or(""), place)?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            Some("property") => {
                let Some(element) = elements.last_mut() else {
                    return fail(place, "property before any element");
                };
                let ty = tok.next().unwrap_or("");
                let kind = if ty == "list" {
                    let count = scalar_type(tok.next().unwrap_or(""), place)?;
                    let item = scalar_type(tok.next().unwrap_or(""), place)?;
                    if !count.is_integer() {
                        return fail(place, "list count type must be an integer type");
                    }
                    Kind::List { count, item }
                } else {
                    Kind::Scalar(scalar_type(ty, place)?)
                };
                let name = tok
                    .next()
                    .ok_or_else(|| ParseError::new(place, "property without a name"))?;
                element.props.push(Property {
                    name: name.to_string(),
                    kind,
                });
            }
            Some("end_header") => {
                let Some(encoding) = encoding else {
                    return fail(place, "header has no format line");
                };
                let body = start
                    + line.len()
                    + if bytes[start + line.len()..].starts_with(b"\r\n") {
                        2
                    } else {
                        1
                    };
                return Ok(Header {
                    encoding,
                    elements,
                    body: body.min(bytes.len()),
                    body_line: line_no + 1,
                });
            }
            Some(other) => {
                return fail(
                    place,
                    format!("unknown header keyword {:?}", text::shorten(other)),
                )
            }
        }
    }
    fail(Place::Byte(bytes.len()), "header has no end_header line")
}

fn scalar_type(name: &str, place: Place) -> Result<Scalar, ParseError> {
    Scalar::parse(name).ok_or_else(|| {
        ParseError::new(
            place,
            format!("unknown property type {:?}", text::shorten(name)),
        )
    })
}

/// Where the vertex element's properties go.
struct VertexLayout {
    xyz: [usize; 3],
    normal: Option<[usize; 3]>,
    /// (property index, field name) of the other scalar properties.
    fields: Vec<(usize, String)>,
}

fn vertex_layout(el: &Element, line: usize) -> Result<VertexLayout, ParseError> {
    let find = |names: &[&str]| {
        el.props
            .iter()
            .position(|p| names.contains(&p.name.as_str()) && matches!(p.kind, Kind::Scalar(_)))
    };
    let Some((xyz, normal)) = super::columns::locate_xyz_normal(find) else {
        return fail(
            Place::Line(line),
            "vertex element lacks scalar x, y and z properties",
        );
    };
    let fields = el
        .props
        .iter()
        .enumerate()
        .filter(|(i, p)| {
            !super::columns::is_located(xyz, normal, *i) && matches!(p.kind, Kind::Scalar(_))
        })
        .map(|(i, p)| (i, p.name.clone()))
        .collect();
    Ok(VertexLayout {
        xyz,
        normal,
        fields,
    })
}

/// What a body reader needs: the file, its header, which element holds the vertices and
/// where their properties go.
struct Body<'a> {
    bytes: &'a [u8],
    header: &'a Header,
    vertex: usize,
    layout: &'a VertexLayout,
}

/// Collects the parsed body.
struct Sink {
    cloud: PointCloud,
    normals: Vec<Vector3<f64>>,
    faces: Vec<[u32; 3]>,
    has_faces: bool,
}

impl Sink {
    fn vertex(&mut self, layout: &VertexLayout, values: &[f64]) {
        let [x, y, z] = layout.xyz;
        self.cloud
            .points
            .push(Point3::new(values[x], values[y], values[z]));
        if let Some([a, b, c]) = layout.normal {
            self.normals
                .push(Vector3::new(values[a], values[b], values[c]));
        }
        for (k, (i, _)) in layout.fields.iter().enumerate() {
            self.cloud.fields[k].values.push(values[*i]);
        }
    }

    /// Fan-triangulates one polygon.
    fn polygon(&mut self, indices: &[f64], place: Place) -> Result<(), ParseError> {
        if indices.len() < 3 {
            return fail(
                place,
                format!("face has {} vertices, needs at least 3", indices.len()),
            );
        }
        let mut idx = Vec::with_capacity(indices.len());
        for &v in indices {
            if v < 0.0 || v > u32::MAX as f64 || v.fract() != 0.0 {
                return fail(place, format!("bad vertex index {v}"));
            }
            idx.push(v as u32);
        }
        for k in 1..idx.len() - 1 {
            self.faces.push([idx[0], idx[k], idx[k + 1]]);
        }
        Ok(())
    }
}

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

fn is_face_list(el: &Element, p: &Property) -> bool {
    el.name == "face"
        && matches!(p.kind, Kind::List { .. })
        && (p.name == "vertex_indices" || p.name == "vertex_index")
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

//! PLY reader (ascii, binary little and big endian; any scalar type; vertex normals, scalar
//! fields and faces; other elements skipped) and binary PLY writer.
use nalgebra::{Point3, Vector3};

use super::error::{fail, ParseError, Place};
use super::text::{self, Cursor};
use super::types::{Geometry, Mesh, PointCloud, ScalarField};

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
    match header.encoding {
        Encoding::Ascii => read_ascii(bytes, &header, vi, &layout, &mut sink)?,
        Encoding::Little | Encoding::Big => read_binary(bytes, &header, vi, &layout, &mut sink)?,
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

fn read_ascii(
    bytes: &[u8],
    h: &Header,
    vi: usize,
    layout: &VertexLayout,
    sink: &mut Sink,
) -> Result<(), ParseError> {
    let mut lines = text::lines(&bytes[h.body..]);
    let mut values: Vec<f64> = Vec::new();
    let mut line_no = h.body_line - 1;
    for (ei, el) in h.elements.iter().enumerate() {
        sink.has_faces |=
            el.name == "face" && el.count > 0 && el.props.iter().any(|p| is_face_list(el, p));
        for index in 0..el.count {
            let line = loop {
                match lines.next() {
                    Some(item) => {
                        let (n, _, line) = item.map_err(|e| shift_line(e, h.body_line - 1))?;
                        line_no = h.body_line - 1 + n;
                        if !line.trim().is_empty() {
                            break line;
                        }
                    }
                    None => {
                        return fail(
                            Place::Line(line_no + 1),
                            format!(
                                "file ends at {} {index} of {} declared in the header",
                                el.name, el.count
                            ),
                        )
                    }
                }
            };
            let place = Place::Line(line_no);
            let mut tok = text::tokens(line);
            values.clear();
            for p in &el.props {
                let mut next = |what: &str| -> Result<f64, ParseError> {
                    let t = tok.next().ok_or_else(|| {
                        ParseError::new(place, format!("missing value for {what}"))
                    })?;
                    text::number(t, place)
                };
                match p.kind {
                    Kind::Scalar(_) => values.push(next(&p.name)?),
                    Kind::List { .. } => {
                        let n = next(&p.name)?;
                        if !(0.0..=1e6).contains(&n) || n.fract() != 0.0 {
                            return fail(place, format!("bad list length {n}"));
                        }
                        let items: Vec<f64> = (0..n as usize)
                            .map(|_| next(&p.name))
                            .collect::<Result<_, _>>()?;
                        if is_face_list(el, p) {
                            sink.polygon(&items, place)?;
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
    Ok(())
}

fn shift_line(mut e: ParseError, by: usize) -> ParseError {
    if let Place::Line(n) = e.place {
        e.place = Place::Line(n + by);
    }
    e
}

fn read_binary(
    bytes: &[u8],
    h: &Header,
    vi: usize,
    layout: &VertexLayout,
    sink: &mut Sink,
) -> Result<(), ParseError> {
    let big = h.encoding == Encoding::Big;
    let mut cur = Cursor::new(bytes, h.body);
    let mut values: Vec<f64> = Vec::new();
    for (ei, el) in h.elements.iter().enumerate() {
        sink.has_faces |=
            el.name == "face" && el.count > 0 && el.props.iter().any(|p| is_face_list(el, p));
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

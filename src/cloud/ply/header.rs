//! The PLY header (format, elements, properties and their scalar types), the vertex layout
//! it implies, and the sink both body readers (ascii in `mod.rs`, binary in `binary.rs`) fill.
use nalgebra::{Point3, Vector3};

use crate::cloud::columns;
use crate::cloud::error::{fail, ParseError, Place};
use crate::cloud::text;
use crate::cloud::types::PointCloud;

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Scalar {
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
    pub(super) fn parse(name: &str) -> Option<Scalar> {
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

    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The name used in headers (for messages).
    pub(super) fn name(self) -> &'static str {
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
    pub(super) fn holds(self, v: f64) -> bool {
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

    pub(super) fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes one value from exactly `self.size()` bytes.
    pub(super) fn decode(self, b: &[u8], big: bool) -> f64 {
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
pub(super) enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug, Clone)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: Kind,
}

#[derive(Debug, Clone)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: usize,
    pub(super) props: Vec<Property>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Encoding {
    Ascii,
    Little,
    Big,
}

pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    /// Byte offset where the body starts.
    pub(super) body: usize,
    /// Line number of the first body line (ascii).
    pub(super) body_line: usize,
}

pub(super) fn parse_header(bytes: &[u8]) -> Result<Header, ParseError> {
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

pub(super) fn scalar_type(name: &str, place: Place) -> Result<Scalar, ParseError> {
    Scalar::parse(name).ok_or_else(|| {
        ParseError::new(
            place,
            format!("unknown property type {:?}", text::shorten(name)),
        )
    })
}

/// Where the vertex element's properties go.
pub(super) struct VertexLayout {
    pub(super) xyz: [usize; 3],
    pub(super) normal: Option<[usize; 3]>,
    /// (property index, field name) of the other scalar properties.
    pub(super) fields: Vec<(usize, String)>,
}

pub(super) fn vertex_layout(el: &Element, line: usize) -> Result<VertexLayout, ParseError> {
    let find = |names: &[&str]| {
        el.props
            .iter()
            .position(|p| names.contains(&p.name.as_str()) && matches!(p.kind, Kind::Scalar(_)))
    };
    let Some((xyz, normal)) = columns::locate_xyz_normal(find) else {
        return fail(
            Place::Line(line),
            "vertex element lacks scalar x, y and z properties",
        );
    };
    let fields = el
        .props
        .iter()
        .enumerate()
        .filter(|(i, p)| !columns::is_located(xyz, normal, *i) && matches!(p.kind, Kind::Scalar(_)))
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
pub(super) struct Body<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) header: &'a Header,
    pub(super) vertex: usize,
    pub(super) layout: &'a VertexLayout,
}

/// Collects the parsed body.
pub(super) struct Sink {
    pub(super) cloud: PointCloud,
    pub(super) normals: Vec<Vector3<f64>>,
    pub(super) faces: Vec<[u32; 3]>,
    pub(super) has_faces: bool,
}

impl Sink {
    pub(super) fn vertex(&mut self, layout: &VertexLayout, values: &[f64]) {
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
    pub(super) fn polygon(&mut self, indices: &[f64], place: Place) -> Result<(), ParseError> {
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

pub(super) fn is_face_list(el: &Element, p: &Property) -> bool {
    el.name == "face"
        && matches!(p.kind, Kind::List { .. })
        && (p.name == "vertex_indices" || p.name == "vertex_index")
}

//! A parametric femoral component: a J-shaped sagittal profile of arcs swept medio-laterally,
//! two posterior condyles split by an intercondylar notch, a trochlear groove on the anterior
//! flange, rounded condyle edges, and five planar box-cut faces inside.
//!
//! Frame (mm): x medio-lateral, y anterior (+) to posterior (-), z proximal (+); centred on its
//! bounding box. Faces are wound counter-clockwise seen from outside.
use nalgebra::{Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::profile::{Piece, Polyline, Profile, Station};
use crate::cloud::{Aabb, Mesh};

/// Shape parameters of the parametric part (millimetres).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FemoralShape {
    /// Medio-lateral width (default 64).
    pub width: f64,
    /// Minimum wall thickness between the articular surface and the box cuts (default 7).
    pub thickness: f64,
    /// Half width of the intercondylar notch (default 9).
    pub notch_half_width: f64,
    /// Depth of the trochlear groove at its deepest (default 2.5).
    pub groove_depth: f64,
    /// Width (standard deviation) of the trochlear groove across x (default 7).
    pub groove_sigma: f64,
    /// How far the condyle edges drop over `edge_band` (default 2).
    pub edge_drop: f64,
    /// Band at each condyle edge over which the surface rounds off (default 6).
    pub edge_band: f64,
    /// Samples along the profile (default 260).
    pub profile_samples: usize,
    /// Grid spacing across x (default 0.5).
    pub x_step: f64,
}

impl Default for FemoralShape {
    fn default() -> Self {
        FemoralShape {
            width: 64.0,
            thickness: 7.0,
            notch_half_width: 9.0,
            groove_depth: 2.5,
            groove_sigma: 7.0,
            edge_drop: 2.0,
            edge_band: 6.0,
            profile_samples: 260,
            x_step: 0.5,
        }
    }
}

/// The built part: mesh and which faces are articular (polished) surface.
#[derive(Debug, Clone)]
pub struct FemoralPart {
    /// Closed triangle mesh.
    pub mesh: Mesh,
    /// Per face: true on the articular (outer) surface.
    pub articular: Vec<bool>,
}

fn sagittal_profile() -> Profile {
    Profile::new(
        Vector2::new(22.0, 45.0),
        Vector2::new(0.06, -1.0),
        vec![
            Piece::Line(34.0),
            Piece::Arc(40.0, 50.0),
            Piece::Arc(27.0, 75.0),
            Piece::Arc(21.0, 58.43),
            Piece::Line(12.0),
        ],
    )
}

fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Builds the parametric part.
pub fn build(shape: &FemoralShape) -> FemoralPart {
    let profile = sagittal_profile();
    let len = profile.length();
    let m = shape.profile_samples.max(40);
    let half = shape.width / 2.0;
    let nh = shape.notch_half_width;

    let (xs, j_nl, j_nr) = x_grid(shape);
    let nx = xs.len();

    let stations: Vec<_> = (0..=m)
        .map(|i| profile.at(len * i as f64 / m as f64))
        .collect();
    // The notch opens where the distal arc is half done and runs to the posterior end.
    let breaks = profile.breaks();
    let s_notch = 0.5 * (breaks[2] + breaks[3]);
    let i_notch = (s_notch / len * m as f64).round() as usize;
    // Groove along the anterior flange, fading out over the first distal arc.
    let groove_end = breaks[2];

    let drop = |i: usize, x: f64| -> f64 {
        let s = len * i as f64 / m as f64;
        let groove = shape.groove_depth
            * (-x * x / (2.0 * shape.groove_sigma.powi(2))).exp()
            * (1.0 - smoothstep(breaks[1], groove_end, s));
        let mut edge_dist = half - x.abs();
        if i >= i_notch {
            edge_dist = edge_dist.min(x.abs() - nh);
        }
        let e = ((shape.edge_band - edge_dist) / shape.edge_band).clamp(0.0, 1.0);
        groove + shape.edge_drop * e * e
    };

    // Inner box-cut polyline: corners on the inward offset of the profile.
    let corner_fractions = [0.0, 0.27, 0.40, 0.62, 0.76, 1.0];
    let inner = Polyline {
        vertices: corner_fractions
            .iter()
            .map(|f| {
                let st = profile.at(f * len);
                st.point - st.normal * shape.thickness
            })
            .collect(),
    }
    .resample_with_corners(m + 1);

    let mut vertices = Vec::with_capacity(2 * (m + 1) * nx);
    for st in &stations {
        let i = vertices.len() / nx;
        for &x in &xs {
            let yz = st.point - st.normal * drop(i, x);
            vertices.push(Point3::new(x, yz.x, yz.y));
        }
    }
    for yz in &inner {
        for &x in &xs {
            vertices.push(Point3::new(x, yz.x, yz.y));
        }
    }
    let mut builder = Builder {
        vertices: &vertices,
        faces: Vec::new(),
        articular: Vec::new(),
    };
    let topology = Topology {
        m,
        nx,
        i_notch,
        j_nl,
        j_nr,
    };
    add_faces(&mut builder, &topology, &stations);
    let Builder {
        faces, articular, ..
    } = builder;
    let mut mesh = Mesh { vertices, faces };
    let centre = Aabb::of(&mesh.vertices).expect("vertices").centre();
    mesh.vertices.iter_mut().for_each(|p| *p -= centre.coords);
    FemoralPart { mesh, articular }
}

/// The medio-lateral grid: `width / x_step` steps with the notch edges added exactly, and the
/// indices of the two notch edges.
fn x_grid(shape: &FemoralShape) -> (Vec<f64>, usize, usize) {
    let half = shape.width / 2.0;
    let nh = shape.notch_half_width;
    // x grid containing the side and notch edges exactly.
    let mut xs: Vec<f64> = Vec::new();
    let steps = (shape.width / shape.x_step).round() as usize;
    for j in 0..=steps {
        xs.push(-half + shape.width * j as f64 / steps as f64);
    }
    xs.extend([-nh, nh]);
    xs.sort_by(f64::total_cmp);
    xs.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let j_nl = xs
        .iter()
        .position(|&x| (x + nh).abs() < 1e-9)
        .expect("notch edge in grid");
    let j_nr = xs
        .iter()
        .position(|&x| (x - nh).abs() < 1e-9)
        .expect("notch edge in grid");

    (xs, j_nl, j_nr)
}

/// How the vertex grid is laid out: `m + 1` stations of `nx` outer vertices, then as many
/// inner ones; the notch spans columns `j_nl..j_nr` from station `i_notch` on.
#[derive(Clone, Copy)]
struct Topology {
    m: usize,
    nx: usize,
    i_notch: usize,
    j_nl: usize,
    j_nr: usize,
}

/// The faces of the part: outer (articular) and inner quads per station, side and notch walls,
/// end caps and the notch roof.
fn add_faces(builder: &mut Builder, t: &Topology, stations: &[Station]) {
    let Topology {
        m,
        nx,
        i_notch,
        j_nl,
        j_nr,
    } = *t;
    let outer_id = |i: usize, j: usize| (i * nx + j) as u32;
    let inner_id = |i: usize, j: usize| ((m + 1) * nx + i * nx + j) as u32;
    let to3 = |v: Vector2<f64>| Vector3::new(0.0, v.x, v.y);
    let in_notch = |i: usize, j: usize| i >= i_notch && j >= j_nl && j < j_nr;
    for i in 0..m {
        let n_out = to3(stations[i].normal + stations[i + 1].normal);
        for j in 0..nx - 1 {
            if in_notch(i, j) {
                continue;
            }
            builder.quad(
                [
                    outer_id(i, j),
                    outer_id(i + 1, j),
                    outer_id(i + 1, j + 1),
                    outer_id(i, j + 1),
                ],
                n_out,
                true,
            );
            builder.quad(
                [
                    inner_id(i, j),
                    inner_id(i + 1, j),
                    inner_id(i + 1, j + 1),
                    inner_id(i, j + 1),
                ],
                -n_out,
                false,
            );
        }
        // Side walls and, in the notch zone, notch walls.
        let mut walls = vec![(0, -Vector3::x()), (nx - 1, Vector3::x())];
        if i >= i_notch {
            walls.extend([(j_nl, Vector3::x()), (j_nr, -Vector3::x())]);
        }
        for (j, hint) in walls {
            builder.quad(
                [
                    outer_id(i, j),
                    outer_id(i + 1, j),
                    inner_id(i + 1, j),
                    inner_id(i, j),
                ],
                hint,
                false,
            );
        }
    }
    // End caps and the notch roof.
    for j in 0..nx - 1 {
        builder.quad(
            [
                outer_id(0, j),
                outer_id(0, j + 1),
                inner_id(0, j + 1),
                inner_id(0, j),
            ],
            -to3(stations[0].tangent),
            false,
        );
        if !in_notch(m, j) {
            builder.quad(
                [
                    outer_id(m, j),
                    outer_id(m, j + 1),
                    inner_id(m, j + 1),
                    inner_id(m, j),
                ],
                to3(stations[m].tangent),
                false,
            );
        }
        if (j_nl..j_nr).contains(&j) {
            let t = to3(stations[i_notch].tangent);
            builder.quad(
                [
                    outer_id(i_notch, j),
                    outer_id(i_notch, j + 1),
                    inner_id(i_notch, j + 1),
                    inner_id(i_notch, j),
                ],
                t,
                false,
            );
        }
    }
}

struct Builder<'a> {
    vertices: &'a [Point3<f64>],
    faces: Vec<[u32; 3]>,
    articular: Vec<bool>,
}

impl Builder<'_> {
    /// Adds quad a-b-c-d as two triangles wound so their normal agrees with `outward`.
    fn quad(&mut self, [a, b, c, d]: [u32; 4], outward: Vector3<f64>, articular: bool) {
        let p = |v: u32| self.vertices[v as usize];
        for tri in [[a, b, c], [a, c, d]] {
            let n = (p(tri[1]) - p(tri[0])).cross(&(p(tri[2]) - p(tri[0])));
            if n.norm() < 1e-12 {
                continue;
            }
            self.faces.push(if n.dot(&outward) >= 0.0 {
                tri
            } else {
                [tri[0], tri[2], tri[1]]
            });
            self.articular.push(articular);
        }
    }
}

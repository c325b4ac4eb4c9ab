//! Implant designs the shipped femoral cell was not designed on (issue 51, "the same on implant
//! designs you have not seen"): femoral_dm scaled (implant families run about 0.85-1.15 x),
//! mirrored (the left knee of the right one), and synth's parametric femoral part, each mounted
//! as the shipped cell's fixture holds femoral_dm: the part's centroid on the table axis at the
//! table centre (the fixture point), its anatomical directions as femoral_dm's. The variants'
//! meshes are written to a scratch folder (never the repository) and their cases are issue
//! 51's: defects uniform over the articular surface ([`super::femoral::uniform_config`]).
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Point3, UnitQuaternion, Vector3};
use polishbot::cloud::{Mesh, Units};
use polishbot::motion::setups::SetupCell;
use polishbot::motion::Inspection;
use polishbot::robot::{Turntable, Workcell};
use polishbot::synth::{build_femoral, FemoralShape, SynthConfig};

/// femoral_dm's medio-lateral axis (its file's frame is OpenSim's: x anterior, y proximal,
/// z to the right), the axis a left knee is mirrored along.
pub const MEDIO_LATERAL: usize = 2;

/// A variant of femoral_dm: scaled by `scale` about the fixture point, and mirrored along
/// [`MEDIO_LATERAL`] through it when `mirror`.
#[derive(Debug, Clone, Copy)]
pub struct Variant {
    /// Name in the printed table.
    pub name: &'static str,
    /// Scale about the fixture point.
    pub scale: f64,
    /// Mirrored (a left knee).
    pub mirror: bool,
}

/// The variants the planners check: the sizes at the ends of a family and the left knee.
pub const VARIANTS: [Variant; 4] = [
    Variant {
        name: "femoral_dm x0.85",
        scale: 0.85,
        mirror: false,
    },
    Variant {
        name: "femoral_dm x1.15",
        scale: 1.15,
        mirror: false,
    },
    Variant {
        name: "femoral_dm mirrored",
        scale: 1.0,
        mirror: true,
    },
    Variant {
        name: "femoral_dm mirrored x1.15",
        scale: 1.15,
        mirror: true,
    },
];

/// The reference point (mm) a cell's placement puts on its table's centre: the part's
/// centroid, where the design mounts it (`design::eval::placement`).
pub fn fixture_point_mm(wc: &Workcell, table: &Turntable) -> Point3<f64> {
    let m = wc.robot_from_reference;
    let r: Matrix3<f64> = m.fixed_slice::<3, 3>(0, 0).into();
    let t = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Point3::from(r.transpose() * (table.centre.coords - t) * 1e3)
}

/// The shipped femoral cell's fixture point (mm, femoral_dm's frame).
pub fn femoral_fixture_point() -> Point3<f64> {
    let (_, wc, table, _) = super::femoral::cell("femoral/");
    fixture_point_mm(&wc, &table.expect("the femoral cell has a table"))
}

/// `mesh` with every vertex mapped by `f`; faces re-wound when `f` mirrors.
fn mapped(mesh: &Mesh, f: impl Fn(&Point3<f64>) -> Point3<f64>, mirrors: bool) -> Mesh {
    Mesh {
        vertices: mesh.vertices.iter().map(f).collect(),
        faces: mesh
            .faces
            .iter()
            .map(|&[a, b, c]| if mirrors { [a, c, b] } else { [a, b, c] })
            .collect(),
    }
}

/// Writes `mesh` (mm) as a binary STL.
pub fn write_stl(path: &Path, mesh: &Mesh) {
    let mut out = vec![0u8; 80];
    out.extend((mesh.faces.len() as u32).to_le_bytes());
    for f in &mesh.faces {
        let [a, b, c] = f.map(|i| mesh.vertices[i as usize]);
        let n = (b - a)
            .cross(&(c - a))
            .try_normalize(0.0)
            .unwrap_or_default();
        for v in [n.x, n.y, n.z, a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z] {
            out.extend((v as f32).to_le_bytes());
        }
        out.extend([0u8; 2]);
    }
    std::fs::write(path, out).expect("write stl");
}

/// The uniform case's synth settings on the part `mesh` with articular surface `surface`
/// (mm), written to `dir` as `NAME.stl` and `NAME_contact.stl`.
fn written(dir: &Path, name: &str, mesh: &Mesh, surface: &Mesh, seed: u64) -> SynthConfig {
    let file = |suffix: &str| -> PathBuf { dir.join(format!("{name}{suffix}.stl")) };
    write_stl(&file(""), mesh);
    write_stl(&file("_contact"), surface);
    SynthConfig {
        mesh: Some(file("")),
        surface: Some(file("_contact")),
        units: Some(Units::Mm),
        ..super::femoral::uniform_config(seed)
    }
}

/// femoral_dm and its articular surface (mm) as variant `v`.
pub fn variant_meshes(v: &Variant) -> (Mesh, Mesh) {
    let load = |f: &str| {
        polishbot::design::load_mesh(&super::shared_data(f), Some(Units::M)).expect("mesh")
    };
    let p0 = femoral_fixture_point();
    let f = |p: &Point3<f64>| {
        let mut d = (p - p0) * v.scale;
        if v.mirror {
            d[MEDIO_LATERAL] = -d[MEDIO_LATERAL];
        }
        p0 + d
    };
    (
        mapped(&load("femoral_dm.stl"), f, v.mirror),
        mapped(&load("femoral_dm_contact.stl"), f, v.mirror),
    )
}

/// The synth settings of `v`'s uniform case, seed `seed`, its meshes written to `dir`.
pub fn variant_config(dir: &Path, v: &Variant, seed: u64) -> SynthConfig {
    let (mesh, surface) = variant_meshes(v);
    let name = v.name.replace([' ', '.'], "_");
    written(dir, &name, &mesh, &surface, seed)
}

/// Area-weighted centroid of a mesh's surface, mm.
fn surface_centroid(mesh: &Mesh) -> Point3<f64> {
    let (mut sum, mut area) = (Vector3::zeros(), 0.0);
    for i in 0..mesh.faces.len() {
        let a = mesh.face_normal_area(i).1;
        let c = mesh.faces[i].iter().fold(Vector3::zeros(), |s, &k| {
            s + mesh.vertices[k as usize].coords
        }) / 3.0;
        sum += c * a;
        area += a;
    }
    Point3::from(sum / area)
}

/// Synth's parametric femoral part (default shape) and its articular surface, turned into
/// femoral_dm's anatomical frame (its x medio-lateral, y anterior, z proximal onto
/// femoral_dm's z, x, y) with its centroid on the fixture point, mm.
pub fn parametric_meshes() -> (Mesh, Mesh) {
    let part = build_femoral(&FemoralShape::default());
    let surface = Mesh {
        vertices: part.mesh.vertices.clone(),
        faces: (part.mesh.faces.iter().zip(&part.articular))
            .filter(|(_, a)| **a)
            .map(|(f, _)| *f)
            .collect(),
    };
    let (c, p0) = (surface_centroid(&part.mesh), femoral_fixture_point());
    let f = |p: &Point3<f64>| {
        let d = p - c;
        p0 + Vector3::new(d.y, d.z, d.x)
    };
    (mapped(&part.mesh, f, false), mapped(&surface, f, false))
}

/// The synth settings of the uniform case on [`parametric_meshes`], written to `dir`.
pub fn parametric_config(dir: &Path, seed: u64) -> SynthConfig {
    let (mesh, surface) = parametric_meshes();
    written(dir, "parametric", &mesh, &surface, seed)
}

/// The uniform case of `config` (see [`super::femoral::of_case`]).
pub fn case(config: &SynthConfig) -> Inspection {
    super::femoral::of_case(config)
}

/// `mount` (a part direction, reference frame) mirrored along [`MEDIO_LATERAL`].
pub fn mirrored(mount: [f64; 3]) -> [f64; 3] {
    let mut m = mount;
    m[MEDIO_LATERAL] = -m[MEDIO_LATERAL];
    m
}

/// `cells` with a left knee's fixture: each setup's mounting mirrored along
/// [`MEDIO_LATERAL`] (the part's direction along the table axis mirrored, then turned onto the
/// axis the shortest way, as the design mounts a part), the part's centroid `p0` (mm) kept
/// on the table centre. Table and solids as the cell's.
pub fn mirrored_fixture(cells: &[SetupCell], p0: &Point3<f64>) -> Vec<SetupCell> {
    cells
        .iter()
        .map(|c| {
            let table = c.table.as_ref().expect("a table");
            let m = c.workcell.robot_from_reference;
            let r: Matrix3<f64> = m.fixed_slice::<3, 3>(0, 0).into();
            let first = r.transpose() * table.axis.into_inner();
            let mount = Vector3::from(mirrored(first.into()));
            let q = UnitQuaternion::rotation_between(&mount, &table.axis).expect("not opposite");
            let t = table.centre.coords - q * (p0.coords * 1e-3);
            let mut out = c.clone();
            out.workcell.robot_from_reference =
                nalgebra::Isometry3::from_parts(t.into(), q).to_homogeneous();
            out
        })
        .collect()
}

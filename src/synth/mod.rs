//! Synthetic cases with known answers: a reference cloud, a scan of the same part with planted
//! defects, noise and outliers moved by a random rigid transform, and the truth.
//!
//! Same config and seed, same files. Front: [`synth`]; files: [`SynthCase::write`].
mod config;
mod defects;
mod femoral;
mod limits;
mod placement;
mod profile;
mod random;
mod truth;
mod turntable;

use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub use config::{SiteFilter, SiteProbe, SynthConfig, MAX_DEFECTS};
pub use defects::{deviation_at, Defect, DefectKind};
pub use femoral::{build as build_femoral, FemoralPart, FemoralShape};
pub use limits::MAX_POINTS;
use random::gauss;
pub use truth::{OutlierTruth, Truth};
pub use turntable::{view_file, SetupTruth, TurntableConfig, TurntableTruth, ViewTruth};

use crate::cloud::{self, Geometry, Mesh, PlyPrecision, PointCloud};

/// A generated case.
#[derive(Debug, Clone)]
pub struct SynthCase {
    /// Dense reference samples with outward normals (reference frame).
    pub reference: PointCloud,
    /// The scan: defective, noisy surface points then outliers, in the scan frame.
    pub scan: PointCloud,
    /// The part's mesh (reference frame).
    pub mesh: Mesh,
    /// What was planted.
    pub truth: Truth,
    /// Turntable views (table frame) and their truth, when asked for.
    pub turntable: Option<(Vec<PointCloud>, TurntableTruth)>,
    /// The articular surface defects were planted on (reference frame), when known.
    pub articular: Option<Mesh>,
}

/// Points of articular.ply, written with turntable views (the area to inspect): about 0.1 mm
/// apart on a femoral component's 2,000 mm² articular surface, finer than any core spacing.
const ARTICULAR_POINTS: usize = 200_000;

impl SynthCase {
    /// Writes reference.ply, scan.ply and truth.json into `dir` (created if missing).
    /// Returns the bytes of reference.ply and scan.ply as written (F64: they read back exactly
    /// as `reference` and `scan`).
    pub fn write(&self, dir: &Path) -> Result<[Vec<u8>; 2]> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        let written =
            [("reference.ply", &self.reference), ("scan.ply", &self.scan)].map(|(name, c)| {
                (
                    dir.join(name),
                    cloud::write_ply_bytes(c, None, PlyPrecision::F64),
                )
            });
        for (path, bytes) in &written {
            std::fs::write(path, bytes)
                .with_context(|| format!("{}: cannot write", path.display()))?;
        }
        if let Some((views, truth)) = &self.turntable {
            for (view, t) in views.iter().zip(&truth.views) {
                cloud::write_ply(&dir.join(&t.file), view, None, PlyPrecision::F64)?;
            }
            truth.save(&dir.join("turntable.json"))?;
            if let Some(mesh) = &self.articular {
                let area = cloud::sample_mesh(mesh, ARTICULAR_POINTS, 1)?.cloud;
                cloud::write_ply(&dir.join("articular.ply"), &area, None, PlyPrecision::F64)?;
            }
        }
        self.truth.save(&dir.join("truth.json"))?;
        Ok(written.map(|(_, bytes)| bytes))
    }
}

/// The part geometry: mesh and the candidate surface for defects.
struct Part {
    mesh: Mesh,
    source: String,
    /// Surface on which defect centres may lie (None: the whole part).
    articular: Option<Mesh>,
}

fn load_part(cfg: &SynthConfig) -> Result<Part> {
    let Some(path) = &cfg.mesh else {
        let part = build_femoral(&cfg.shape);
        let faces = part
            .mesh
            .faces
            .iter()
            .zip(&part.articular)
            .filter(|(_, a)| **a)
            .map(|(f, _)| *f)
            .collect();
        let articular = Mesh {
            vertices: part.mesh.vertices.clone(),
            faces,
        };
        return Ok(Part {
            mesh: part.mesh,
            source: "parametric femoral component".into(),
            articular: Some(articular),
        });
    };
    let load_mesh = |p: &Path| -> Result<Mesh> {
        match cloud::load(p, None, cfg.units)?.geometry {
            Geometry::Mesh { mesh, .. } => Ok(mesh),
            Geometry::Cloud(_) => {
                anyhow::bail!("{}: has no faces; synth needs a mesh", p.display())
            }
        }
    };
    let mut mesh = load_mesh(path)?;
    mesh.orient_outward();
    let articular = cfg.surface.as_deref().map(load_mesh).transpose()?;
    Ok(Part {
        mesh,
        source: path.display().to_string(),
        articular,
    })
}

/// A uniformly random rotation and a translation of random direction and length up to `max`.
fn random_pose(rng: &mut ChaCha8Rng, max: f64) -> Isometry3<f64> {
    let q = nalgebra::Quaternion::new(gauss(rng), gauss(rng), gauss(rng), gauss(rng));
    let dir = Vector3::new(gauss(rng), gauss(rng), gauss(rng)).normalize();
    let t = dir * max * rng.gen::<f64>();
    Isometry3::from_parts(Translation3::from(t), UnitQuaternion::from_quaternion(q))
}

/// A fresh scan of a surface: synth's scanner model (Gaussian noise of `noise` mm on each
/// coordinate, outliers as a share of points by [`placement::add_outliers`]) and a new random
/// rigid pose with a translation up to `max_translation` mm, all from `seed`. `surface` needs
/// normals. Returns the scan (scan frame), its outliers and its `scan_to_reference`.
pub fn rescan(
    surface: &PointCloud,
    noise: f64,
    outliers: f64,
    max_translation: f64,
    seed: u64,
) -> Result<(PointCloud, OutlierTruth, Isometry3<f64>)> {
    anyhow::ensure!(
        surface.normals.is_some(),
        "rescan: the surface has no normals"
    );
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut points: Vec<Point3<f64>> = surface
        .points
        .iter()
        .map(|p| p + Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * noise)
        .collect();
    let truth = placement::add_outliers(&mut points, surface, outliers, &mut rng);
    let pose = random_pose(&mut rng, max_translation);
    let mut scan = PointCloud::from_points(points);
    scan.transform(&pose);
    Ok((scan, truth, pose.inverse()))
}

/// Makes a case.
pub fn synth(cfg: &SynthConfig) -> Result<SynthCase> {
    synth_at(cfg, &|_| true)
}

/// Makes a case whose defects sit only where `accept` allows.
pub fn synth_at(cfg: &SynthConfig, accept: &SiteFilter) -> Result<SynthCase> {
    cfg.check().map_err(anyhow::Error::msg)?;
    let part = load_part(cfg)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let defects =
        placement::place_defects(&part.mesh, part.articular.as_ref(), cfg, accept, &mut rng)?;

    let reference = cloud::sample_mesh(&part.mesh, cfg.reference_points, rng.gen())?.cloud;
    let sample = cloud::sample_mesh(&part.mesh, cfg.scan_points, rng.gen())?.cloud;
    let normals = sample.normals.as_ref().expect("sampled normals");
    let mut points: Vec<Point3<f64>> = sample
        .points
        .iter()
        .zip(normals)
        .map(|(p, n)| {
            let noise = Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * cfg.noise;
            p + n * deviation_at(&defects, p, n) + noise
        })
        .collect();
    let outliers = placement::add_outliers(&mut points, &sample, cfg.outliers, &mut rng);

    let turntable = match &cfg.turntable {
        Some(t) => Some(turntable::turntable_views(
            &part.mesh, &defects, t, cfg.noise, &mut rng,
        )?),
        None => None,
    };
    let move_scan = random_pose(&mut rng, cfg.max_translation);
    let mut scan = PointCloud::from_points(points);
    scan.transform(&move_scan);
    let mut truth = Truth {
        source: part.source,
        seed: cfg.seed,
        units: "mm".into(),
        scan_to_reference: [[0.0; 4]; 4],
        noise_mm: cfg.noise,
        reference_points: reference.len(),
        scan_points: scan.len(),
        outliers,
        defects,
    };
    truth.set_pose(&move_scan.inverse());
    Ok(SynthCase {
        reference,
        scan,
        mesh: part.mesh,
        truth,
        turntable,
        articular: part.articular,
    })
}

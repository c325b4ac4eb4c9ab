//! Synthetic cases with known answers: a reference cloud, a scan of the same part with planted
//! defects, noise and outliers moved by a random rigid transform, and the truth.
//!
//! Same config and seed, same files. Front: [`synth`]; files: [`SynthCase::write`].
mod defects;
mod femoral;
mod placement;
mod profile;
mod truth;
mod turntable;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub use defects::{deviation_at, Defect, DefectKind};
pub use femoral::{build as build_femoral, FemoralPart, FemoralShape};
pub use truth::{OutlierTruth, Truth};
pub use turntable::{TurntableConfig, TurntableTruth, ViewTruth};

use crate::cloud::{self, Geometry, Mesh, PlyPrecision, PointCloud, Units};

/// Settings of a synthetic case. Every field has a documented default.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SynthConfig {
    /// Seed of every random choice (default 1).
    pub seed: u64,
    /// A mesh to use instead of the parametric part (default none).
    pub mesh: Option<PathBuf>,
    /// The articular surface of `mesh` on which defects are planted (default: the whole mesh
    /// away from sharp edges).
    pub surface: Option<PathBuf>,
    /// Unit of `mesh` and `surface` (default: refuse files that look like metres).
    pub units: Option<Units>,
    /// Shape of the parametric part.
    pub shape: FemoralShape,
    /// Points in reference.ply (default 400,000).
    pub reference_points: usize,
    /// Surface points in scan.ply before outliers (default 300,000).
    pub scan_points: usize,
    /// Number of defects (default 6).
    pub defects: usize,
    /// Range of |height| of defects, mm (default 0.04..0.5).
    pub height_range: [f64; 2],
    /// Range of widths (FWHM) of defects, mm (default 0.4..3).
    pub width_range: [f64; 2],
    /// Share of pits among defects (default 0.25); the rest are bumps and ridges.
    pub pit_share: f64,
    /// Share of ridges among defects (default 0.25).
    pub ridge_share: f64,
    /// Standard deviation of Gaussian noise on each scan coordinate, mm (default 0.015).
    pub noise: f64,
    /// Outliers as a share of scan points, half scattered and half clustered (default 0.01).
    pub outliers: f64,
    /// Largest translation of the random scan pose, mm (default 60).
    pub max_translation: f64,
    /// Also make turntable range views of the defective part (default none).
    pub turntable: Option<TurntableConfig>,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            seed: 1,
            mesh: None,
            surface: None,
            units: None,
            shape: FemoralShape::default(),
            reference_points: 400_000,
            scan_points: 300_000,
            defects: 6,
            height_range: [0.04, 0.5],
            width_range: [0.4, 3.0],
            pit_share: 0.25,
            ridge_share: 0.25,
            noise: 0.015,
            outliers: 0.01,
            max_translation: 60.0,
            turntable: None,
        }
    }
}

/// Most points in reference.ply, scan.ply or a turntable view (about 500 MB of points and
/// normals at once: beyond it a setting is wrong, not the case large).
pub const MAX_POINTS: usize = 10_000_000;
/// Most defects planted (placement tries each against all others).
pub const MAX_DEFECTS: usize = 500;

/// `key = value unit` outside `lo..=hi` (or not finite) as a message naming the key.
fn outside(key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Option<String> {
    (!(v.is_finite() && (lo..=hi).contains(&v)))
        .then(|| format!("`{key}` = {v:?} {unit} is outside {lo}..={hi} {unit}"))
}

impl SynthConfig {
    /// Checks every setting against its range and unit before anything is made; the message
    /// names the key in backticks.
    pub fn check(&self) -> std::result::Result<(), String> {
        let n = |v: usize| v as f64;
        let [h0, h1] = self.height_range;
        let [w0, w1] = self.width_range;
        let (s, mm, share) = (&self.shape, "mm", "(share)");
        let shape = MAX_SHAPE_MM;
        let table = [
            (
                "reference_points",
                n(self.reference_points),
                1.0,
                n(MAX_POINTS),
                "points",
            ),
            (
                "scan_points",
                n(self.scan_points),
                1.0,
                n(MAX_POINTS),
                "points",
            ),
            ("defects", n(self.defects), 0.0, n(MAX_DEFECTS), "defects"),
            ("height_range", h0, 0.0, h1.min(MAX_DEFECT_HEIGHT_MM), mm),
            ("height_range", h1, h0.max(0.0), MAX_DEFECT_HEIGHT_MM, mm),
            ("width_range", w0, MIN_DEFECT_WIDTH_MM, w1, mm),
            (
                "width_range",
                w1,
                w0.max(MIN_DEFECT_WIDTH_MM),
                MAX_DEFECT_WIDTH_MM,
                mm,
            ),
            (
                "pit_share",
                self.pit_share,
                0.0,
                1.0 - self.ridge_share,
                share,
            ),
            ("ridge_share", self.ridge_share, 0.0, 1.0, share),
            ("noise", self.noise, 0.0, MAX_NOISE_MM, mm),
            ("outliers", self.outliers, 0.0, MAX_OUTLIER_SHARE, share),
            (
                "max_translation",
                self.max_translation,
                0.0,
                MAX_TRANSLATION_MM,
                mm,
            ),
            ("width", s.width, 1.0, shape, mm),
            ("thickness", s.thickness, 0.1, shape, mm),
            ("notch_half_width", s.notch_half_width, 0.0, shape, mm),
            ("groove_depth", s.groove_depth, 0.0, shape, mm),
            ("groove_sigma", s.groove_sigma, 0.1, shape, mm),
            ("edge_drop", s.edge_drop, 0.0, shape, mm),
            ("edge_band", s.edge_band, 0.1, shape, mm),
            (
                "profile_samples",
                n(s.profile_samples),
                10.0,
                1e5,
                "samples",
            ),
            ("x_step", s.x_step, 0.01, shape, mm),
        ];
        if let Some(m) = table
            .iter()
            .find_map(|&(key, v, lo, hi, unit)| outside(key, v, lo, hi, unit))
        {
            return Err(m);
        }
        match &self.turntable {
            Some(t) => t.check(),
            None => Ok(()),
        }
    }
}

/// Tallest planted defect, mm (a defect of a polished part, not a second part).
const MAX_DEFECT_HEIGHT_MM: f64 = 10.0;
/// Narrowest and widest planted defect (FWHM), mm.
const MIN_DEFECT_WIDTH_MM: f64 = 0.05;
/// Widest planted defect (FWHM), mm.
const MAX_DEFECT_WIDTH_MM: f64 = 100.0;
/// Largest scan noise, mm.
const MAX_NOISE_MM: f64 = 5.0;
/// Outlier share of the scan: below one half (the filter needs a majority of surface).
const MAX_OUTLIER_SHARE: f64 = 0.49;
/// Largest translation of the scan's pose, mm.
const MAX_TRANSLATION_MM: f64 = 10_000.0;
/// Largest dimension of the parametric part's shape settings, mm.
const MAX_SHAPE_MM: f64 = 1000.0;

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
}

impl SynthCase {
    /// Writes reference.ply, scan.ply and truth.json into `dir` (created if missing).
    pub fn write(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        cloud::write_ply(
            &dir.join("reference.ply"),
            &self.reference,
            None,
            PlyPrecision::F64,
        )?;
        cloud::write_ply(&dir.join("scan.ply"), &self.scan, None, PlyPrecision::F64)?;
        if let Some((views, truth)) = &self.turntable {
            for (view, t) in views.iter().zip(&truth.views) {
                cloud::write_ply(&dir.join(&t.file), view, None, PlyPrecision::F64)?;
            }
            truth.save(&dir.join("turntable.json"))?;
        }
        self.truth.save(&dir.join("truth.json"))
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

/// A standard normal sample (Box-Muller).
pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.gen::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
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

/// Decides whether a defect may sit at a surface point (reference frame, outward normal,
/// footprint radius in mm), e.g. only where the arm can reach.
pub type SiteFilter = dyn Fn(&Point3<f64>, &Vector3<f64>, f64) -> bool + Sync;

/// Makes a case.
pub fn synth(cfg: &SynthConfig) -> Result<SynthCase> {
    synth_at(cfg, &|_, _, _| true)
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
    })
}

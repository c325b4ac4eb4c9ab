//! Turntable range views of a synthetic part: the part turns about the table axis by each
//! view's true angle (nominal angle plus an unknown error), a fixed scanner sees the points
//! that face it and are not hidden behind others, with noise on each coordinate.
use std::collections::HashMap;

use anyhow::Result;
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::defects::{deviation_at, Defect};
use super::limits::{outside, MAX_POINTS};
use super::random::gauss;
use crate::cloud::{sample_mesh, transform::isometry_to_rows, Mesh, PointCloud};

/// Settings of the turntable views.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TurntableConfig {
    /// Number of views (default 12).
    pub views: usize,
    /// Nominal step between views in degrees (default 360 / views).
    pub step_deg: Option<f64>,
    /// Largest error of a true angle against its nominal angle, degrees (default 3).
    pub angle_error_deg: f64,
    /// Table axis direction in the table frame (default +z).
    pub axis: [f64; 3],
    /// A point on the table axis, table frame, mm (default 4, -3, 0: the part sits off-centre).
    pub centre: [f64; 3],
    /// Direction from the part towards the scanner (default 0, -1, 0.35).
    pub scanner_direction: [f64; 3],
    /// Points per view after visibility (default 100,000).
    pub points_per_view: usize,
    /// Image-plane cell of the visibility test, mm (default 0.3).
    pub occlusion_cell: f64,
    /// Noise along the line of sight only (one Gaussian of the case's `noise` per point,
    /// towards the scanner), as a triangulation or time-of-flight scanner has it, instead of
    /// the default's independent noise on each coordinate (default false).
    pub line_of_sight_noise: bool,
    /// One entry per setup: the part's tilt in degrees about the table frame's x axis through
    /// `centre` before the table turns (default [0]: one setup; 180 = the part turned over on
    /// the table, 90 = on a square fixture). Every setup after the first is also turned by a
    /// random angle about the table axis, as a part put back on the table by hand.
    pub setup_tilts_deg: Vec<f64>,
}

impl Default for TurntableConfig {
    fn default() -> Self {
        TurntableConfig {
            views: 12,
            step_deg: None,
            angle_error_deg: 3.0,
            axis: [0.0, 0.0, 1.0],
            centre: [4.0, -3.0, 0.0],
            scanner_direction: [0.0, -1.0, 0.35],
            points_per_view: 100_000,
            occlusion_cell: 0.3,
            line_of_sight_noise: false,
            setup_tilts_deg: vec![0.0],
        }
    }
}

/// Most turntable views (one per degree).
const MAX_VIEWS: usize = 360;
/// Largest error of a view's true angle, degrees.
const MAX_ANGLE_ERROR_DEG: f64 = 45.0;
/// Most setups (a workshop scans a part in two or three; beyond a few it is a typo).
const MAX_SETUPS: usize = 8;

impl TurntableConfig {
    /// Checks every setting against its range and unit; the message names the key.
    pub fn check(&self) -> std::result::Result<(), String> {
        let vectors = [
            ("axis", self.axis),
            ("centre", self.centre),
            ("scanner_direction", self.scanner_direction),
        ];
        for (key, v) in vectors {
            let norm = Vector3::from(v).norm();
            if !(norm.is_finite() && norm <= MAX_POINTS as f64) || (key != "centre" && norm == 0.0)
            {
                return Err(format!(
                    "`{key}` = {v:?} must be finite (and not zero for a direction)"
                ));
            }
        }
        let step = self.step_deg.unwrap_or(1.0);
        let setups = self.setup_tilts_deg.len() as f64;
        let tilt = self
            .setup_tilts_deg
            .iter()
            .copied()
            .find(|t| !t.is_finite() || t.abs() > 360.0);
        [
            outside("setup_tilts_deg", setups, 1.0, MAX_SETUPS as f64, "setups"),
            tilt.and_then(|t| outside("setup_tilts_deg", t, -360.0, 360.0, "deg")),
            outside("views", self.views as f64, 2.0, MAX_VIEWS as f64, "views"),
            outside("step_deg", step, 1e-3, 360.0, "deg"),
            outside(
                "angle_error_deg",
                self.angle_error_deg,
                0.0,
                MAX_ANGLE_ERROR_DEG,
                "deg",
            ),
            outside(
                "points_per_view",
                self.points_per_view as f64,
                1.0,
                MAX_POINTS as f64,
                "points",
            ),
            outside("occlusion_cell", self.occlusion_cell, 1e-3, 100.0, "mm"),
        ]
        .into_iter()
        .flatten()
        .next()
        .map_or(Ok(()), Err)
    }
}

/// The truth of one view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewTruth {
    /// File name of the view.
    pub file: String,
    /// The setup (index into [`TurntableTruth::setups`], 0 = the first; absent in files
    /// written before setups: 0).
    #[serde(default)]
    pub setup: usize,
    /// Nominal turntable angle, degrees.
    pub nominal_deg: f64,
    /// True turntable angle, degrees.
    pub true_deg: f64,
    /// Maps this view's points into the frame of its setup's first view (4x4 rows).
    pub view_to_first: [[f64; 4]; 4],
}

/// The truth of one setup (the part put on the table once).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetupTruth {
    /// Tilt of the part about the table frame's x axis through the centre, degrees.
    pub tilt_deg: f64,
    /// Extra turn about the table axis of the part put back by hand, degrees.
    pub turn_deg: f64,
    /// Maps reference-frame points into this setup's first view's frame (4x4 rows).
    pub first_from_reference: [[f64; 4]; 4],
}

/// The truth of a turntable set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TurntableTruth {
    /// Table axis (unit) in the table (= every view's) frame.
    pub axis: [f64; 3],
    /// A point on the axis, table frame.
    pub centre: [f64; 3],
    /// Maps reference-frame points into the first view's frame (4x4 rows).
    pub first_from_reference: [[f64; 4]; 4],
    /// Per view, setup after setup.
    pub views: Vec<ViewTruth>,
    /// Per setup (absent in files written before setups: the one setup is the fields above).
    #[serde(default)]
    pub setups: Vec<SetupTruth>,
}

/// Rotation by `deg` about the table axis.
fn table_rotation(axis: &Unit<Vector3<f64>>, centre: &Point3<f64>, deg: f64) -> Isometry3<f64> {
    let c = Translation3::from(centre.coords);
    c * Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_axis_angle(axis, deg.to_radians()),
    ) * c.inverse()
}

/// The file name of view `i` of setup `setup` (0-based): `view_000.ply` for the first setup
/// (as before setups), `setup2_view_000.ply` for the second, and so on.
pub fn view_file(setup: usize, i: usize) -> String {
    match setup {
        0 => format!("view_{i:03}.ply"),
        s => format!("setup{}_view_{i:03}.ply", s + 1),
    }
}

/// The scanner's fixed settings and the part's surface, shared by every view.
struct Scene<'a> {
    cfg: &'a TurntableConfig,
    axis: Unit<Vector3<f64>>,
    centre: Point3<f64>,
    towards_scanner: Vector3<f64>,
    surface: Vec<Point3<f64>>,
    normals: &'a [Vector3<f64>],
    noise: f64,
}

impl Scene<'_> {
    /// The points of one view: the part placed by `pose` (reference to table frame at the
    /// view's true angle), the visible points thinned to the view's count, with noise.
    fn view(&self, pose: &Isometry3<f64>, rng: &mut ChaCha8Rng) -> PointCloud {
        let cfg = self.cfg;
        let points: Vec<Point3<f64>> = self.surface.iter().map(|p| pose * p).collect();
        let facing: Vec<Vector3<f64>> = self.normals.iter().map(|n| pose.rotation * n).collect();
        let mut keep = visible_points(&points, &facing, &self.towards_scanner, cfg.occlusion_cell);
        // Thin to the requested count with a seeded shuffle prefix.
        if keep.len() > cfg.points_per_view {
            for k in 0..cfg.points_per_view {
                let j = rng.gen_range(k..keep.len());
                keep.swap(k, j);
            }
            keep.truncate(cfg.points_per_view);
            keep.sort_unstable();
        }
        let towards = self.towards_scanner;
        let view_points = keep
            .iter()
            .map(|&k| match cfg.line_of_sight_noise {
                true => points[k] + towards * (gauss(rng) * self.noise),
                false => points[k] + Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * self.noise,
            })
            .collect();
        PointCloud::from_points(view_points)
    }

    /// The part's placement on the table at angle 0 in setup `tilt_deg` turned by `turn_deg`.
    fn placement(&self, tilt_deg: f64, turn_deg: f64) -> Isometry3<f64> {
        let tilt = table_rotation(&Vector3::x_axis(), &self.centre, tilt_deg);
        table_rotation(&self.axis, &self.centre, turn_deg) * tilt
    }
}

/// Makes the views of `mesh` (reference frame = table frame at angle 0 in the first setup)
/// with `defects`: `cfg.views` views per setup, setup after setup.
pub fn turntable_views(
    mesh: &Mesh,
    defects: &[Defect],
    cfg: &TurntableConfig,
    noise: f64,
    rng: &mut ChaCha8Rng,
) -> Result<(Vec<PointCloud>, TurntableTruth)> {
    anyhow::ensure!(cfg.views >= 2, "a turntable set needs at least 2 views");
    anyhow::ensure!(
        !cfg.setup_tilts_deg.is_empty(),
        "a turntable set needs at least one setup"
    );
    let step = cfg.step_deg.unwrap_or(360.0 / cfg.views as f64);
    let dense = sample_mesh(mesh, cfg.points_per_view * 3, rng.gen())?.cloud;
    let normals = dense.normals.as_ref().expect("sampled normals");
    let scene = Scene {
        cfg,
        axis: Unit::new_normalize(Vector3::from(cfg.axis)),
        centre: Point3::from(cfg.centre),
        towards_scanner: Vector3::from(cfg.scanner_direction).normalize(),
        surface: dense
            .points
            .iter()
            .zip(normals)
            .map(|(p, n)| p + n * deviation_at(defects, p, n))
            .collect(),
        normals,
        noise,
    };
    let total = cfg.views * cfg.setup_tilts_deg.len();
    let mut views = Vec::with_capacity(total);
    let mut truth_views = Vec::with_capacity(total);
    let mut setups = Vec::with_capacity(cfg.setup_tilts_deg.len());
    for (s, &tilt_deg) in cfg.setup_tilts_deg.iter().enumerate() {
        let turn_deg = match s {
            0 => 0.0,
            _ => rng.gen_range(0.0..360.0),
        };
        let placement = scene.placement(tilt_deg, turn_deg);
        let mut first: Option<Isometry3<f64>> = None;
        for i in 0..cfg.views {
            let nominal = i as f64 * step;
            let true_deg = nominal + rng.gen_range(-1.0..=1.0) * cfg.angle_error_deg;
            let table = table_rotation(&scene.axis, &scene.centre, true_deg) * placement;
            views.push(scene.view(&table, rng));
            let first_table = *first.get_or_insert(table);
            truth_views.push(ViewTruth {
                file: view_file(s, i),
                setup: s,
                nominal_deg: nominal,
                true_deg,
                view_to_first: isometry_to_rows(&(first_table * table.inverse())),
            });
        }
        setups.push(SetupTruth {
            tilt_deg,
            turn_deg,
            first_from_reference: isometry_to_rows(&first.expect("at least two views")),
        });
    }
    let truth = TurntableTruth {
        axis: scene.axis.into_inner().into(),
        centre: cfg.centre,
        first_from_reference: setups[0].first_from_reference,
        views: truth_views,
        setups,
    };
    Ok((views, truth))
}

/// Indices of points that face the scanner (normal within 80 degrees of it) and are nearest
/// to it in their neighbourhood of the image plane (orthographic z-buffer, 3x3 cells).
fn visible_points(
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    towards: &Vector3<f64>,
    cell: f64,
) -> Vec<usize> {
    let u = towards
        .cross(&Vector3::z())
        .try_normalize(1e-9)
        .unwrap_or_else(|| towards.cross(&Vector3::x()).normalize());
    let v = towards.cross(&u);
    let key = |p: &Point3<f64>| {
        (
            (p.coords.dot(&u) / cell).floor() as i64,
            (p.coords.dot(&v) / cell).floor() as i64,
        )
    };
    // Height towards the scanner: larger is nearer.
    let mut nearest: HashMap<(i64, i64), f64> = HashMap::new();
    for p in points {
        let h = p.coords.dot(towards);
        let e = nearest.entry(key(p)).or_insert(f64::MIN);
        *e = e.max(h);
    }
    let min_cos = 10f64.to_radians().sin();
    (0..points.len())
        .filter(|&i| {
            let cos = normals[i].dot(towards);
            if cos < min_cos {
                return false;
            }
            // The surface itself rises across the 3x3 cells by up to this much.
            let tolerance = 2.2 * cell * (1.0 - cos * cos).sqrt() / cos + 0.1;
            let (a, b) = key(&points[i]);
            let h = points[i].coords.dot(towards);
            let front = (-1..=1)
                .flat_map(|da| (-1..=1).map(move |db| (a + da, b + db)))
                .filter_map(|k| nearest.get(&k))
                .fold(f64::MIN, |m, &x| m.max(x));
            h >= front - tolerance
        })
        .collect()
}

impl TurntableTruth {
    /// Writes turntable.json.
    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        std::fs::write(path, serde_json::to_string_pretty(self)?)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }

    /// Reads turntable.json.
    pub fn load(path: &std::path::Path) -> Result<TurntableTruth> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: line {}: {e}", path.display(), e.line()))
    }
}

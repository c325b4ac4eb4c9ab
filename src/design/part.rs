//! The part as the design sees it: its collision model and the articular surface's samples,
//! and the verdict on each sample.
use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::{Point3, Vector3};
use serde::Serialize;

use super::config::DesignConfig;
use crate::cloud::{self, Geometry, Mesh, Units};
use crate::repair::SurfacePoint;
use crate::spatial::Neighbours;

/// The part: its collision model and the articular surface's samples (reference frame, mm).
pub struct Part {
    /// Points of the whole part with outward normals.
    pub points: Vec<SurfacePoint>,
    /// Centroid of those points, mm: it sits on the table axis.
    pub centroid: Point3<f64>,
    /// Articular-surface samples with outward normals, in a random order (any prefix is a
    /// uniform sample).
    pub surface: Vec<(Point3<f64>, Vector3<f64>)>,
}

impl Part {
    /// Samples `reference` (the whole part, a closed mesh) and `surface` (its articular
    /// surface, same frame); the surface's normals are turned to agree with the nearest
    /// outward normal of the part.
    pub fn new(reference: &Mesh, surface: &Mesh, cfg: &DesignConfig) -> Result<Part> {
        let mut mesh = reference.clone();
        mesh.orient_outward();
        let whole = cloud::sample_mesh(&mesh, cfg.part_points, cfg.seed)?.cloud;
        let normals = whole.normals.clone().context("sampled normals")?;
        let points: Vec<SurfacePoint> = whole
            .points
            .iter()
            .zip(&normals)
            .map(|(p, n)| SurfacePoint {
                position: *p,
                normal: *n,
                distance: 0.0,
                uncertainty: 0.0,
                region: -1,
            })
            .collect();
        let n = points.len().max(1) as f64;
        let centroid = Point3::from(
            points
                .iter()
                .fold(Vector3::zeros(), |s, p| s + p.position.coords)
                / n,
        );
        let index = Neighbours::new(&whole.points);
        let art = cloud::sample_mesh(surface, cfg.final_samples, cfg.seed + 1)?.cloud;
        let art_normals = art.normals.clone().context("sampled normals")?;
        let surface = art
            .points
            .iter()
            .zip(&art_normals)
            .map(|(p, nrm)| {
                let outward = index.nearest(p).map_or(*nrm, |k| normals[k.index]);
                (*p, if nrm.dot(&outward) < 0.0 { -nrm } else { *nrm })
            })
            .collect();
        Ok(Part {
            points,
            centroid,
            surface,
        })
    }
}

/// Loads a mesh file (reference or surface) in `units`.
pub fn load_mesh(path: &Path, units: Option<Units>) -> Result<Mesh> {
    match cloud::load(path, None, units)?.geometry {
        Geometry::Mesh { mesh, .. } => Ok(mesh),
        Geometry::Cloud(_) => {
            anyhow::bail!("{}: has no faces; cell design needs a mesh", path.display())
        }
    }
}

/// The verdict on one articular-surface sample in the designed cell.
#[derive(Debug, Clone, Serialize)]
pub struct SampleVerdict {
    /// Position, reference frame, mm.
    pub position_mm: [f64; 3],
    /// Outward normal.
    pub normal: [f64; 3],
    /// The table angle that reaches it, degrees (none: not reached).
    pub angle_deg: Option<f64>,
    /// Not reached: the rule that refused it at the table angle that came nearest (a
    /// collision after a solved IK is nearer than joint limits, which are nearer than the
    /// wrist out of reach, which is nearer than the tool axis off the arm plane).
    pub refused_by: Option<String>,
    /// That nearest table angle, degrees.
    pub nearest_angle_deg: Option<f64>,
}

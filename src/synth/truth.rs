//! `truth.json`: what synth planted, so tests can score the pipeline against known answers.
use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::defects::{deviation_at, Defect};
use crate::cloud::transform::{isometry_from_rows, isometry_to_rows};

/// Indices (into scan.ply) of the planted outliers.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct OutlierTruth {
    /// Share of scan points that are outliers.
    pub fraction: f64,
    /// Points scattered off the surface, 2-15 mm away.
    pub scattered: Vec<usize>,
    /// Points in small dense "reflection" clusters 1-5 mm off the surface.
    pub clustered: Vec<usize>,
    /// Number of clusters.
    pub clusters: usize,
}

/// Everything synth knows about a case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Where the geometry came from ("parametric femoral component" or the mesh path).
    pub source: String,
    /// Seed the case was made with.
    pub seed: u64,
    /// Length unit of every number here: "mm".
    pub units: String,
    /// Rigid transform mapping scan points into the reference frame (4x4, row-major rows).
    pub scan_to_reference: [[f64; 4]; 4],
    /// Standard deviation of the Gaussian noise on each scan coordinate (mm).
    pub noise_mm: f64,
    /// Points in reference.ply.
    pub reference_points: usize,
    /// Points in scan.ply (surface points and outliers).
    pub scan_points: usize,
    /// The planted outliers.
    pub outliers: OutlierTruth,
    /// The planted defects, in the reference frame.
    pub defects: Vec<Defect>,
}

impl Truth {
    /// The true scan-to-reference pose.
    pub fn pose(&self) -> Result<Isometry3<f64>> {
        isometry_from_rows(&self.scan_to_reference)
    }

    /// Sets the pose.
    pub fn set_pose(&mut self, scan_to_reference: &Isometry3<f64>) {
        self.scan_to_reference = isometry_to_rows(scan_to_reference);
    }

    /// True signed deviation (mm, + = material in excess) at a reference-frame surface point.
    pub fn deviation_at(&self, p: &Point3<f64>, n: &Vector3<f64>) -> f64 {
        deviation_at(&self.defects, p, n)
    }

    /// Reads truth.json.
    pub fn load(path: &Path) -> Result<Truth> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        serde_json::from_str(&text)
            .map_err(|e| anyhow::anyhow!("{}: line {}: {}", path.display(), e.line(), e))
    }

    /// Writes truth.json.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self)?;
        std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
    }
}

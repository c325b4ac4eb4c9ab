//! Core points and their outward normals.
//!
//! A mesh reference is sampled area-uniformly with facet normals after orienting the winding
//! outward (so a core point next to a sharp edge carries its own facet's normal, not an
//! average across the edge). A cloud reference must carry normals (estimated ones must be
//! oriented outward consistently; a fixed orientation vector flips signs on a closed part).
use anyhow::{bail, Result};
use rand::seq::index::sample;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use nalgebra::Point3;

use crate::cloud::{sample_mesh, Mesh, Neighbours, PointCloud};

/// Which reference points become core points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CoreSelection {
    /// Every reference point.
    All,
    /// `count` reference points (default).
    #[default]
    Sample,
}

/// Settings of [`core_points`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct CoreConfig {
    /// All points or a sample (default sample).
    pub selection: CoreSelection,
    /// Size of the sample (default 100,000; all points when the reference has fewer).
    pub count: usize,
    /// Seed of the sample (default 1).
    pub seed: u64,
}

impl Default for CoreConfig {
    fn default() -> Self {
        CoreConfig {
            selection: CoreSelection::Sample,
            count: 100_000,
            seed: 1,
        }
    }
}

/// A dense reference cloud with outward facet normals sampled from `mesh` (its winding is
/// made outward first).
pub fn mesh_reference(mesh: &Mesh, points: usize, seed: u64) -> Result<PointCloud> {
    let mut mesh = mesh.clone();
    mesh.orient_outward();
    Ok(sample_mesh(&mesh, points, seed)?.cloud)
}

/// The core points of `reference` (which must carry outward unit normals).
// TODO(preprocess): take the curvature-aware sample (`preprocess::curvature_sample`) once it
// lands; until then the sample is uniform at random (seeded).
pub fn core_points(reference: &PointCloud, cfg: &CoreConfig) -> Result<PointCloud> {
    let Some(normals) = &reference.normals else {
        bail!("the reference has no normals: give a mesh, or a cloud with outward normals");
    };
    if let Some(i) = normals
        .iter()
        .position(|n| (n.norm() - 1.0).abs().is_nan() || (n.norm() - 1.0).abs() >= 1e-3)
    {
        bail!("reference normal {i} is not a unit vector");
    }
    if cfg.selection == CoreSelection::All || cfg.count >= reference.len() {
        return Ok(reference.clone());
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    let mut chosen = sample(&mut rng, reference.len(), cfg.count).into_vec();
    chosen.sort_unstable();
    Ok(reference.select(&chosen))
}

/// Area share of the core point `p` among the core points `index` holds: π r9² / 8, r9 the
/// distance to its 8th neighbour (the point itself is the first of the 9); None when the
/// index holds no point. Regions weigh points by it, and its median's square root is the
/// core-point spacing.
pub fn area_share(index: &Neighbours, p: &Point3<f64>) -> Option<f64> {
    index
        .knn(p, 9)
        .last()
        .map(|n| std::f64::consts::PI * n.dist2 / 8.0)
}

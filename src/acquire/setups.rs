//! Views of several setups (the part put on the table once per setup: turned over, or on a
//! tilted fixture) joined into one cloud: each setup's views merged about the table axis on
//! their own ([`merge_views`]), then every further setup registered onto the first
//! (FPFH -> MAC -> ICP, [`crate::register::register`]): directly onto the first setup's
//! merged cloud, or, given a reference, through it (setup k onto the reference, the first
//! setup onto the reference). The joined cloud is in the first setup's first view's frame.
use anyhow::{Context, Result};
use nalgebra::Isometry3;
use rayon::prelude::*;
use serde::Serialize;

use super::{merge_views, MergeConfig, Merged};
use crate::cloud::transform::isometry_to_rows;
use crate::cloud::PointCloud;
use crate::preprocess::{estimate_normals, voxel_downsample, NormalConfig, Orientation};
use crate::register::{register, RegisterConfig};

/// The views of one setup, in turntable order.
pub struct SetupViews {
    /// The views.
    pub views: Vec<PointCloud>,
    /// Their names (files).
    pub names: Vec<String>,
    /// Their nominal table angles, degrees.
    pub angles: Vec<f64>,
}

/// How a further setup was joined to the first.
#[derive(Debug, Clone, Serialize)]
pub struct SetupJoin {
    /// The setup (0 = the first).
    pub setup: usize,
    /// Maps this setup's merged cloud into the first setup's frame (4x4 rows).
    pub to_first: [[f64; 4]; 4],
    /// Registration fitness (share of points within the fitness distance) of the setup onto
    /// its target (the first setup's cloud, or the reference).
    pub fitness: f64,
    /// Inlier RMSE of that registration, mm.
    pub inlier_rmse: f64,
    /// Whether the join went through the reference.
    pub through_reference: bool,
    /// `to_first` as an isometry (not serialised).
    #[serde(skip)]
    pub pose: Isometry3<f64>,
}

/// The result of [`merge_setups`].
pub struct MergedSetups {
    /// Every setup's views in one cloud, first setup's first view's frame, thinned on the
    /// largest of the setups' voxels, with outward normals.
    pub cloud: PointCloud,
    /// Each setup's own merge (its cloud in its own first view's frame).
    pub setups: Vec<Merged>,
    /// The joins of the setups after the first.
    pub joins: Vec<SetupJoin>,
    /// Voxel of the final thinning, mm.
    pub voxel: f64,
}

/// Merges each setup of `setups` with `cfg`, registers the further setups onto the first
/// (through `reference` when given) with `reg`, and joins them.
pub fn merge_setups(
    setups: &[SetupViews],
    cfg: &MergeConfig,
    reference: Option<&PointCloud>,
    reg: &RegisterConfig,
) -> Result<MergedSetups> {
    anyhow::ensure!(!setups.is_empty(), "no setup to merge");
    let merged = setups
        .iter()
        .enumerate()
        .map(|(k, s)| {
            merge_views(&s.views, &s.names, &s.angles, cfg)
                .with_context(|| format!("setup {}", k + 1))
        })
        .collect::<Result<Vec<_>>>()?;
    // The first setup onto the reference, once, when joining through it.
    let first_to_reference = match reference {
        Some(r) => Some(
            register(&merged[0].cloud, r, reg)
                .map_err(|e| anyhow::anyhow!("setup 1 onto the reference: {e}"))?
                .pose,
        ),
        None => None,
    };
    let joins = (1..merged.len())
        .into_par_iter()
        .map(|k| join_one(k, &merged, reference, first_to_reference.as_ref(), reg))
        .collect::<Result<Vec<_>>>()?;
    let voxel = merged.iter().map(|m| m.voxel).fold(0.0, f64::max);
    let mut points: Vec<_> = merged[0].cloud.points.clone();
    for (j, m) in joins.iter().zip(&merged[1..]) {
        points.extend(m.cloud.points.iter().map(|p| j.pose * p));
    }
    let mut cloud = voxel_downsample(&PointCloud::from_points(points), voxel);
    cloud.fields.clear();
    if cfg.normals {
        let ncfg = NormalConfig {
            orientation: Orientation::Outward,
            ..NormalConfig::default()
        };
        let est = estimate_normals(&cloud, &ncfg).context("normals of the joined setups")?;
        cloud.normals = Some(est.normals);
    }
    Ok(MergedSetups {
        cloud,
        setups: merged,
        joins,
        voxel,
    })
}

/// Registers setup `k` of `merged` onto the first: onto the reference and back through the
/// first setup's pose `first_to_reference` when given, else onto the first setup's cloud.
fn join_one(
    k: usize,
    merged: &[Merged],
    reference: Option<&PointCloud>,
    first_to_reference: Option<&Isometry3<f64>>,
    reg: &RegisterConfig,
) -> Result<SetupJoin> {
    let target = reference.unwrap_or(&merged[0].cloud);
    let r = register(&merged[k].cloud, target, reg).map_err(|e| {
        let onto = if reference.is_some() {
            "the reference"
        } else {
            "setup 1"
        };
        anyhow::anyhow!("setup {} onto {onto}: {e}", k + 1)
    })?;
    let to_first = match first_to_reference {
        Some(f) => f.inverse() * r.pose,
        None => r.pose,
    };
    Ok(SetupJoin {
        setup: k,
        to_first: isometry_to_rows(&to_first),
        fitness: r.fitness,
        inlier_rmse: r.inlier_rmse,
        through_reference: reference.is_some(),
        pose: to_first,
    })
}

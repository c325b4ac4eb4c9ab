//! Core points and their outward normals.
//!
//! A mesh reference is sampled area-uniformly with facet normals after orienting the winding
//! outward (so a core point next to a sharp edge carries its own facet's normal, not an
//! average across the edge). A cloud reference keeps its normals, or gets PCA normals oriented
//! outward by propagation ([`cloud_reference`]; a fixed orientation vector would flip signs on
//! a closed part).
use anyhow::{bail, Result};
use rand::seq::index::sample;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use nalgebra::Point3;

use crate::cloud::{sample_mesh, Mesh, PointCloud};
use crate::preprocess::{
    curvature_sample, estimate_normals, CurvatureSampleConfig, NormalConfig, Orientation,
};
use crate::spatial::{Grid, Neighbours};

/// Which reference points become core points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CoreSelection {
    /// Every reference point.
    All,
    /// `count` reference points drawn uniformly at random (default: the defects' areas keep
    /// the full density; docs/ALGORITHMS.md has the comparison with `curvature`).
    #[default]
    Sample,
    /// `count` reference points from the curvature-aware down-sampling
    /// (`preprocess::curvature_sample`: half from the feature region, by default).
    Curvature,
}

/// Settings of [`core_points`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct CoreConfig {
    /// All points or a sample (default sample).
    pub selection: CoreSelection,
    /// Size of the sample (all points when the reference has fewer). Default (`None`):
    /// [`default_count`] of the scan's size.
    pub count: Option<usize>,
    /// Seed of the sample (default 1).
    pub seed: u64,
    /// Share of a `curvature` sample drawn from the non-feature (flat) region (J; default
    /// 0.5).
    pub uniform_ratio: f64,
}

impl Default for CoreConfig {
    fn default() -> Self {
        CoreConfig {
            selection: CoreSelection::Sample,
            count: None,
            seed: 1,
            uniform_ratio: 0.5,
        }
    }
}

/// Scan points per core point of the default sample ([`default_count`]).
const SCAN_POINTS_PER_CORE_POINT: usize = 6;

/// Bounds of the default sample size ([`default_count`]).
const DEFAULT_COUNT_RANGE: (usize, usize) = (50_000, 100_000);

/// The default number of core points for a scan of `scan_points` points: one per
/// [`SCAN_POINTS_PER_CORE_POINT`] scan points, within [`DEFAULT_COUNT_RANGE`]. Each core
/// point's result does not depend on the others, so the count sets the map's spacing and the
/// time, not the accuracy of a point: one per 6 scan points puts the core points about 1.25
/// smallest cylinder radii apart (about 2.45 scan spacings; M3C2's usual spacing is the
/// projection scale), and densification adds the reference points around every defect's top.
/// On femoral_dm at 300,000 scan points that is 50,000 core points, 0.57 mm apart
/// (docs/ALGORITHMS.md, Comparison, has the measurements against 100,000); the ceiling keeps
/// dense scans' time bounded, the floor keeps a sparse scan's map readable.
pub fn default_count(scan_points: usize) -> usize {
    let (lo, hi) = DEFAULT_COUNT_RANGE;
    (scan_points / SCAN_POINTS_PER_CORE_POINT).clamp(lo, hi)
}

/// A dense reference cloud with outward facet normals sampled from `mesh` (its winding is
/// made outward first).
pub fn mesh_reference(mesh: &Mesh, points: usize, seed: u64) -> Result<PointCloud> {
    let mut mesh = mesh.clone();
    mesh.orient_outward();
    Ok(sample_mesh(&mesh, points, seed)?.cloud)
}

/// A reference cloud ready for the comparison, and a sentence saying where its normals came
/// from. A cloud with normals keeps them (they must point outward). A cloud without gets PCA
/// normals of its 20 nearest points, oriented consistently and outward on a closed part
/// without a fixed orientation vector: [`Orientation::Propagate`] (a minimum spanning tree of
/// the 10-NN graph walked from the highest point, whose normal is turned up: outward on a
/// closed surface). Near a sharp edge a PCA normal averages the two faces (a mesh reference
/// keeps the facet normals there).
pub fn cloud_reference(mut cloud: PointCloud) -> Result<(PointCloud, String)> {
    if cloud.normals.is_some() {
        return Ok((cloud, "the reference cloud's own normals".into()));
    }
    let est = estimate_normals(
        &cloud,
        &NormalConfig {
            orientation: Orientation::Propagate,
            ..NormalConfig::default()
        },
    )?;
    cloud.normals = Some(est.normals);
    Ok((
        cloud,
        format!("PCA of 20 neighbours, {}", est.orientation_note),
    ))
}

/// The core points of `reference` (which must carry outward unit normals) for a scan of
/// `scan_points` points (it sets the default sample size, [`default_count`]).
pub fn core_points(
    reference: &PointCloud,
    scan_points: usize,
    cfg: &CoreConfig,
) -> Result<PointCloud> {
    let Some(normals) = &reference.normals else {
        bail!("the reference has no normals: give a mesh, or a cloud with outward normals");
    };
    if let Some(i) = normals.iter().position(|n| {
        let off = (n.norm() - 1.0).abs();
        off.is_nan() || off >= UNIT_TOLERANCE
    }) {
        bail!("reference normal {i} is not a unit vector");
    }
    let count = cfg.count.unwrap_or_else(|| default_count(scan_points));
    if cfg.selection == CoreSelection::All || count >= reference.len() {
        return Ok(reference.clone());
    }
    let chosen = match cfg.selection {
        CoreSelection::Curvature => {
            let sample = curvature_sample(
                reference,
                &CurvatureSampleConfig {
                    target: count,
                    uniform_ratio: cfg.uniform_ratio,
                    seed: cfg.seed,
                    ..CurvatureSampleConfig::default()
                },
            )?;
            sample.indices
        }
        CoreSelection::Sample | CoreSelection::All => {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
            let mut chosen = sample(&mut rng, reference.len(), count).into_vec();
            chosen.sort_unstable();
            chosen
        }
    };
    Ok(reference.select(&chosen))
}

/// A reference normal whose length is this far from 1 is not a unit vector (float rounding of
/// a normalised vector stays far below; a normal left unnormalised is far above).
const UNIT_TOLERANCE: f64 = 1e-3;

/// Area share of the core point `p` among the core points `index` holds: π r9² / 8, r9 the
/// distance to its 8th neighbour (the point itself is the first of the 9); None when the
/// index holds no point. Regions weigh points by it, and its median's square root is the
/// core-point spacing.
pub fn area_share(index: &Neighbours, p: &Point3<f64>) -> Option<f64> {
    index.knn(p, 9).last().map(|n| share_of(n.dist2))
}

/// [`area_share`] of every one of `points` among them (0 for an empty cloud's none), searched
/// as one batch on a grid: the same values, a fraction of the time for 100,000 points.
pub fn area_shares(points: &[Point3<f64>]) -> Vec<f64> {
    Grid::knn_among(points, 9, f64::INFINITY, |_, found| {
        found.last().map_or(0.0, |&(d2, _)| share_of(d2))
    })
}

/// π r² / 8 for r² the squared distance to the 8th neighbour.
fn share_of(dist2: f64) -> f64 {
    std::f64::consts::PI * dist2 / 8.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn default_count_follows_the_scan_within_its_range() {
        assert_eq!(default_count(0), 50_000);
        assert_eq!(default_count(303_000), 50_500);
        assert_eq!(default_count(450_000), 75_000);
        assert_eq!(default_count(1_212_000), 100_000);
    }

    #[test]
    fn batched_area_shares_equal_the_single_queries() {
        use rand::Rng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut points: Vec<Point3<f64>> = (0..3000)
            .map(|_| Point3::new(rng.gen_range(0.0..30.0), rng.gen_range(0.0..20.0), 0.0))
            .collect();
        points.push(points[7]); // a duplicate
        let index = Neighbours::new(&points);
        let single: Vec<f64> = points
            .iter()
            .map(|p| area_share(&index, p).unwrap())
            .collect();
        assert_eq!(area_shares(&points), single);
        assert!(area_shares(&[]).is_empty());
    }

    #[test]
    fn curvature_selection_keeps_reference_points_and_favours_the_fold() {
        // A 60 x 40 sheet (0.5 mm) folded 90 degrees at u = 15, with its normals.
        let (points, normals): (Vec<_>, Vec<_>) = (0..2400)
            .map(|i| {
                let (u, v) = ((i % 60) as f64 * 0.5, (i / 60) as f64 * 0.5);
                if u <= 15.0 {
                    (Point3::new(u, v, 0.0), Vector3::z())
                } else {
                    (Point3::new(15.0, v, u - 15.0), -Vector3::x())
                }
            })
            .unzip();
        let reference = PointCloud {
            points,
            normals: Some(normals),
            fields: Vec::new(),
        };
        let near_fold = |c: &PointCloud| {
            c.points
                .iter()
                .filter(|p| (p.x - 15.0).abs() < 1.1 && p.z < 1.1)
                .count()
        };
        let cfg = CoreConfig {
            count: Some(300),
            ..CoreConfig::default()
        };
        let uniform = core_points(&reference, 0, &cfg).unwrap();
        let curved = core_points(
            &reference,
            0,
            &CoreConfig {
                selection: CoreSelection::Curvature,
                ..cfg
            },
        )
        .unwrap();
        assert_eq!(curved.len(), 300);
        let normals = curved.normals.as_ref().unwrap();
        for (p, n) in curved.points.iter().zip(normals) {
            let i = reference.points.iter().position(|q| q == p).unwrap();
            assert_eq!(reference.normals.as_ref().unwrap()[i], *n);
        }
        assert!(near_fold(&curved) > 3 * near_fold(&uniform));
    }
}

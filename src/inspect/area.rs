//! The inspect area (`inspect --inspect-area FILE`): which core points lie in the area the user
//! asks to inspect.
use std::path::Path;

use anyhow::{Context, Result};
use nalgebra::Point3;

use super::config::FileInput;
use crate::cloud::{self, Geometry};
use crate::compare::{self, Deviations};
use crate::spatial::Neighbours;

/// Points sampled on an area given as a mesh: about 0.1 mm apart on 2,000 mm² (a femoral
/// component's articular surface), well under the default core-point spacing (about 0.5 mm),
/// so the reach below follows the core points.
const AREA_SAMPLES: usize = 200_000;

/// A core point lies in the area when a point of the area's file is within this many times
/// the larger of the two spacings (the core points' and the file's, each the square root of
/// the median area per point): on a sampled surface every point of it is within about half
/// a spacing of a sample, and a core point just off its rim is not counted in.
const AREA_REACH: f64 = 1.5;

/// Per core point of `dev`, whether it lies in the area of `path` (a mesh, sampled, or a
/// cloud, reference frame, the units of `input`).
pub fn core_points_in(path: &Path, input: FileInput, dev: &Deviations) -> Result<Vec<bool>> {
    let what = || format!("{}: inspect area", path.display());
    let points: Vec<Point3<f64>> = match cloud::load(path, input.format, input.units)?.geometry {
        Geometry::Mesh { mesh, .. } => {
            compare::mesh_reference(&mesh, AREA_SAMPLES, 1)
                .with_context(what)?
                .points
        }
        Geometry::Cloud(c) => c.points,
    };
    anyhow::ensure!(!points.is_empty(), "{}: has no points", what());
    let reach = AREA_REACH * spacing(&points).max(spacing(&dev.points));
    let index = Neighbours::new(&points);
    Ok(dev
        .points
        .iter()
        .map(|p| {
            index
                .knn(p, 1)
                .first()
                .is_some_and(|nb| nb.dist2 <= reach * reach)
        })
        .collect())
}

/// The square root of the median area share of `points` (0 for fewer than 9).
pub(crate) fn spacing(points: &[Point3<f64>]) -> f64 {
    let mut share: Vec<f64> = compare::area_shares(points)
        .into_iter()
        .filter(|a| *a > 0.0)
        .collect();
    if share.is_empty() {
        return 0.0;
    }
    let mid = share.len() / 2;
    share.select_nth_unstable_by(mid, f64::total_cmp).1.sqrt()
}

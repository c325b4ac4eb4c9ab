//! Several scans of one part (the setups of a workshop: the part turned over on the table, or
//! on a tilted fixture): each is filtered and registered to the reference on its own, then
//! their points are pooled in the reference frame and measured jointly; per core point, which
//! scans supported its measurement.
use std::path::Path;

use anyhow::{Context, Result};
use rayon::prelude::*;

use super::checks;
use super::config::{FileInput, InspectConfig, Source};
use super::pose::{register_scan, PoseSource};
use crate::cloud::PointCloud;
use crate::compare::Deviations;
use crate::preprocess;
use crate::spatial::Neighbours;

/// Most scans in one inspection: the support of a core point is a bitmask of them in a
/// `float` PLY property, exact up to 2^24.
pub const MAX_SCANS: usize = 24;

/// One scan filtered and moved into the reference frame.
pub struct Prepared {
    /// The filtered scan, reference frame.
    pub cloud: PointCloud,
    /// Its pose and where it came from.
    pub pose: PoseSource,
    /// The report's line on its outlier filter.
    pub filter_line: String,
}

/// Filters `scan` (read from `path`), checks its size against `reference` and moves it into
/// the reference frame: by the pose in `pose_file` when given, else by its own registration.
pub fn prepare(
    cfg: &InspectConfig,
    reference: (&Path, &PointCloud),
    path: &Path,
    scan: &PointCloud,
    pose_file: Option<&Path>,
) -> Result<Prepared> {
    let sor = preprocess::statistical_outlier_filter(scan, &cfg.filter)
        .with_context(|| format!("{}", path.display()))?;
    let mut cloud = sor.apply(scan);
    checks::check_sizes(reference, (path, &cloud))?;
    checks::check_scan_density(path, &cloud)?;
    let pose = match pose_file {
        Some(file) => PoseSource::Given {
            pose: checks::read_pose(file)?,
            source: file.to_path_buf(),
        },
        None => {
            PoseSource::Registered(Box::new(register_scan(&cloud, reference.1, &cfg.register)?))
        }
    };
    cloud.transform(&pose.pose());
    if let PoseSource::Given { source, .. } = &pose {
        checks::check_overlap(reference, (source, &cloud))?;
    }
    let filter_line = format!(
        "{} of {} scan points removed",
        sor.removed,
        sor.removed + sor.kept.len()
    );
    Ok(Prepared {
        cloud,
        pose,
        filter_line,
    })
}

/// Reads the further scans (in parallel).
pub fn load_more(paths: &[Source], files: FileInput) -> Result<Vec<PointCloud>> {
    anyhow::ensure!(
        paths.len() < MAX_SCANS,
        "{} scans: at most {MAX_SCANS} in one inspection",
        paths.len() + 1
    );
    paths.par_iter().map(|p| p.load_cloud(files)).collect()
}

/// The points of every scan in one cloud (points only: the comparison reads no more),
/// thinned on a voxel of the largest of the scans' mean spacings, as `merge` joins views:
/// where scans overlap their points would otherwise be twice as dense as elsewhere, and the
/// comparison's radii, set by the pooled cloud's density, too small where one scan alone saw
/// the surface (measured: two setups of synth's part pooled unthinned left 14 % of the
/// articular surface at a "scan border" that either setup alone measured).
pub fn pool(scans: &[&PointCloud]) -> PointCloud {
    let voxel = scans
        .par_iter()
        .map(|s| preprocess::mean_spacing(s))
        .reduce(|| 0.0, f64::max);
    let joined = PointCloud::from_points(
        scans
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .collect(),
    );
    preprocess::voxel_downsample(&joined, voxel)
}

/// Per core point of `dev`, the scans (bit k: scan k, in the order given) with a point in the
/// core point's cylinder (within its radius, or the smallest radius for a point pair, of the
/// core point and within the same of its tangent plane: the comparison's neighbourhood) when
/// the core point was measured; 0 when not.
pub fn support(dev: &Deviations, scans: &[&PointCloud]) -> Vec<u32> {
    let r0 = dev.radii.first().copied().unwrap_or(0.0);
    let indexes: Vec<Neighbours> = scans
        .par_iter()
        .map(|s| Neighbours::new(&s.points))
        .collect();
    (0..dev.points.len())
        .into_par_iter()
        .map(|i| {
            let v = &dev.values[i];
            if !v.distance.is_finite() {
                return 0;
            }
            let r = if v.radius > 0.0 { v.radius } else { r0 };
            let (p, n) = (&dev.points[i], &dev.normals[i]);
            let mut mask = 0u32;
            for (k, index) in indexes.iter().enumerate() {
                // A cylinder of radius r and half-length r fits in the sphere of r * sqrt 2.
                let hit = index
                    .within_unsorted(p, r * std::f64::consts::SQRT_2)
                    .iter()
                    .any(|nb| {
                        let d = index.point(nb.index) - p;
                        let along = d.dot(n);
                        along.abs() <= r && (d.norm_squared() - along * along) <= r * r
                    });
                mask |= u32::from(hit) << k;
            }
            mask
        })
        .collect()
}

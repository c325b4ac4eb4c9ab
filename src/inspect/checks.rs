//! The checks inspection makes on its inputs before it measures: a given pose must come from a
//! registration that succeeded, scan and reference must be of one size once units are applied,
//! and normals must be unit vectors pointing outward.
use std::path::Path;

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Point3};
use serde::Deserialize;

use crate::cloud::{transform, PointCloud};

pub use super::orientation::orient_outward;

/// Accepted ratio of the scan's to the reference's robust bounding-box diagonal: a scan of
/// the part (a partial view included) spans about the part; a unit slip (mm read as m) is a
/// factor of 1000.
pub const SIZE_RATIO: (f64, f64) = (0.5, 2.0);
/// Share of the points farthest from the centre left out of the robust extent (stray
/// outliers left by the filter do not widen it).
const EXTENT_TRIM: f64 = 0.01;
/// Largest accepted deviation of a normal's length from 1 (as the comparison's own check).
const UNIT_TOLERANCE: f64 = 1e-3;

/// Reads `scan_to_reference` from a registration.json or a synth truth.json, refusing a
/// registration whose status is not "ok" or "given".
pub fn read_pose(path: &Path) -> Result<Isometry3<f64>> {
    #[derive(Deserialize)]
    struct Pose {
        scan_to_reference: Option<[[f64; 4]; 4]>,
        status: Option<String>,
        reason: Option<String>,
    }
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: --pose: cannot read", path.display()))?;
    let pose: Pose = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: --pose: line {}: {e}", path.display(), e.line()))?;
    if let Some(status) = pose
        .status
        .as_deref()
        .filter(|s| !["ok", "given"].contains(s))
    {
        bail!(
            "{}: --pose: the registration's status is {status:?} ({}): not a pose to measure with",
            path.display(),
            pose.reason.as_deref().unwrap_or("no reason given")
        );
    }
    let Some(rows) = pose.scan_to_reference else {
        bail!("{}: --pose: no `scan_to_reference`", path.display());
    };
    transform::isometry_from_rows(&rows)
        .with_context(|| format!("{}: --pose: scan_to_reference", path.display()))
}

/// Refuses a cloud without normals or with a normal that is not a unit vector, naming the
/// file, what it is (`what`: "reference", "--core file") and the point index.
pub fn check_unit_normals(path: &Path, what: &str, cloud: &PointCloud) -> Result<()> {
    let Some(normals) = &cloud.normals else {
        bail!(
            "{}: the {what} has no normals: give a cloud with outward unit normals",
            path.display()
        );
    };
    let bad = normals
        .iter()
        .position(|n| n.norm().is_nan() || (n.norm() - 1.0).abs() >= UNIT_TOLERANCE);
    if let Some(i) = bad {
        let n = normals[i];
        bail!(
            "{}: {what} point {i}: normal ({}, {}, {}) is not a unit vector (length {})",
            path.display(),
            n.x,
            n.y,
            n.z,
            n.norm()
        );
    }
    Ok(())
}

/// Refuses a scan whose robust extent ([`robust_extent`]) is not within [`SIZE_RATIO`] of the
/// reference's (both in millimetres after `--units`). The scan is still in its own frame, so
/// the measure is one that turns with the part, not an axis-aligned box.
pub fn check_sizes(reference: (&Path, &PointCloud), scan: (&Path, &PointCloud)) -> Result<()> {
    let r = robust_extent(&reference.1.points);
    let s = robust_extent(&scan.1.points);
    let ratio = s / r;
    if !(SIZE_RATIO.0..=SIZE_RATIO.1).contains(&ratio) {
        bail!(
            "{}: the scan spans {s:.3} mm but the reference {} spans {r:.3} mm (ratio {ratio:.3}, \
             outside {}..{}): are the files in the same unit? check --units",
            scan.0.display(),
            reference.0.display(),
            SIZE_RATIO.0,
            SIZE_RATIO.1
        );
    }
    Ok(())
}

/// Largest accepted median spacing of the (filtered) scan's points, mm: twice the width of
/// the smallest defect the verdict must see ([`crate::regions::SMALLEST_DEFECT_MM`]). A scan
/// that sparse resolves no core point (its cylinders would be about 2 x the spacing wide, over
/// [`crate::regions::MAX_RESOLVING_RADIUS_MM`]), and its comparison grows cylinders of tens of
/// millimetres: a 100-point scan of the synth part took 56 s (issue 52).
pub const MAX_SCAN_SPACING_MM: f64 = 2.0 * crate::regions::SMALLEST_DEFECT_MM;

/// Refuses a scan whose median point spacing (the square root of the median area per point)
/// exceeds [`MAX_SCAN_SPACING_MM`].
pub fn check_scan_density(path: &Path, scan: &PointCloud) -> Result<()> {
    let s = super::area::spacing(&scan.points);
    if s.is_nan() || s > MAX_SCAN_SPACING_MM {
        bail!(
            "{}: the scan's points are {s:.4} mm apart (median, {} points after the outlier \
             filter): too sparse to see a {} mm defect anywhere (at most {MAX_SCAN_SPACING_MM} mm)",
            path.display(),
            scan.len(),
            crate::regions::SMALLEST_DEFECT_MM
        );
    }
    Ok(())
}

/// Refuses a pose that does not put the scan onto the reference: the moved scan's median
/// point must lie within the reference's robust extent ([`robust_extent`]) of the
/// reference's (a pose of another scan, or a translation of 1e300 that made the comparison
/// search without end).
pub fn check_overlap(reference: (&Path, &PointCloud), scan: (&Path, &PointCloud)) -> Result<()> {
    let extent = robust_extent(&reference.1.points);
    let off = (median_point(&scan.1.points) - median_point(&reference.1.points)).norm();
    if !(off.is_finite() && off <= extent) {
        bail!(
            "{}: --pose puts the scan {off:.4e} mm from the reference {} (which spans {extent:.4} \
             mm): not a pose of this scan onto this reference",
            scan.0.display(),
            reference.0.display()
        );
    }
    Ok(())
}

/// The per-axis median of `points` (the origin for none).
fn median_point(points: &[Point3<f64>]) -> Point3<f64> {
    let mut centre = Point3::origin();
    if points.is_empty() {
        return centre;
    }
    for axis in 0..3 {
        let mut v: Vec<f64> = points.iter().map(|p| p[axis]).collect();
        centre[axis] = *v.select_nth_unstable_by(points.len() / 2, f64::total_cmp).1;
    }
    centre
}

/// Twice the distance from the per-axis median point within which all but [`EXTENT_TRIM`] of
/// the points lie: about the part's diameter, unmoved by a few stray points.
fn robust_extent(points: &[Point3<f64>]) -> f64 {
    if points.is_empty() {
        return f64::NAN;
    }
    let n = points.len();
    let centre = median_point(points);
    let mut d: Vec<f64> = points.iter().map(|p| (p - centre).norm()).collect();
    let k = (((n - 1) as f64) * (1.0 - EXTENT_TRIM)) as usize;
    2.0 * *d.select_nth_unstable_by(k, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_extent_is_the_diameter_and_ignores_a_stray_point() {
        // 2,000 points on a circle of radius 10 in a tilted plane: extent 20.
        let mut pts: Vec<Point3<f64>> = (0..2000)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 2000.0;
                Point3::new(10.0 * a.cos(), 7.0 * a.sin(), 7.0 * a.sin() + 5.0)
            })
            .collect();
        let d = robust_extent(&pts);
        assert!((d - 20.0).abs() < 0.05, "{d}");
        pts.push(Point3::new(1e6, 0.0, 0.0));
        assert!((robust_extent(&pts) - d).abs() < 0.05);
    }
}

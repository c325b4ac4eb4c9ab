//! The checks inspection makes on its inputs before it measures: a given pose must come from a
//! registration that succeeded, scan and reference must be of one size once units are applied,
//! and normals must be unit vectors pointing outward.
use std::path::Path;

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Point3};
use serde::Deserialize;

use crate::cloud::{transform, PointCloud};
use crate::preprocess::{estimate_normals, orient_sheets, NormalConfig, Orientation};

/// Accepted ratio of the scan's to the reference's robust bounding-box diagonal: a scan of
/// the part (a partial view included) spans about the part; a unit slip (mm read as m) is a
/// factor of 1000.
pub const SIZE_RATIO: (f64, f64) = (0.5, 2.0);
/// Share of the points farthest from the centre left out of the robust extent (stray
/// outliers left by the filter do not widen it).
const EXTENT_TRIM: f64 = 0.01;
/// Points of the reference whose normals are compared with a propagated orientation (a
/// sample along the file's order; the sign test needs no more).
const ORIENTATION_SAMPLE: usize = 20_000;
/// Fewest sampled points for the orientation test (PCA takes 20 neighbours; with fewer the
/// propagated orientation says nothing).
const ORIENTATION_MIN_POINTS: usize = 200;
/// Share of sampled normals that must agree in sign with the propagated orientation for the
/// normals to be taken as they are (or disagree, for them to be turned round): PCA normals
/// near sharp edges and on thin walls may disagree with correct normals now and then.
const ORIENTATION_AGREEMENT: f64 = 0.9;
/// Points of the quick first orientation test: a tenth of [`ORIENTATION_SAMPLE`] (its PCA
/// and propagation cost about a tenth).
const ORIENTATION_QUICK_SAMPLE: usize = 2_000;
/// Share of the quick sample's normals that must agree for the normals to be kept without
/// the full test.
const ORIENTATION_QUICK_AGREEMENT: f64 = 0.97;
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

/// Compares a reference cloud's own normals with a propagated orientation sheet by sheet (PCA
/// normals of a sample oriented by [`orient_sheets`], which never carries a sign across a
/// wall): kept when at least [`ORIENTATION_AGREEMENT`] of the sampled normals agree with
/// their sheet's orientation taken with the sign most of that sheet's normals have, and the
/// largest sheet's normals agree with its propagated outward orientation; turned round (with
/// a note) when that largest sheet's normals oppose it; refused when they are not consistent.
/// Each sheet takes its own sign because a thin-walled part's inner faces (box cuts) form
/// sheets of their own whose outward sign the seed of the propagation cannot tell (issue 52:
/// a femoral part with a 3 mm wall, its correct normals refused). Returns the note of a turn.
pub fn orient_outward(path: &Path, cloud: &mut PointCloud) -> Result<Option<String>> {
    if cloud.normals.is_none() {
        return Ok(None);
    }
    // A small sample that agrees clearly settles it; anything else gets the full check.
    if let Some(a) = agreement(path, cloud, ORIENTATION_QUICK_SAMPLE)? {
        if a.consistent >= ORIENTATION_QUICK_AGREEMENT && a.largest_outward {
            return Ok(None);
        }
    }
    let Some(a) = agreement(path, cloud, ORIENTATION_SAMPLE)? else {
        return Ok(None);
    };
    if a.consistent < ORIENTATION_AGREEMENT {
        bail!(
            "{}: reference normals are not consistently oriented: {:.0} % of {} sampled normals \
             agree with a propagated orientation of their own smooth sheet (need {:.0} %)",
            path.display(),
            100.0 * a.consistent,
            a.picked,
            100.0 * ORIENTATION_AGREEMENT
        );
    }
    if a.largest_outward {
        return Ok(None);
    }
    let normals = cloud.normals.as_mut().expect("normals");
    normals.iter_mut().for_each(|n| *n = -*n);
    Ok(Some(format!(
        "{}: the reference normals point inward (those of its largest smooth sheet, {} of {} \
         sampled points, oppose a propagated outward orientation): turned round",
        path.display(),
        a.largest,
        a.picked
    )))
}

/// Largest lean of an edge of the orientation check's propagation graph
/// ([`orient_sheets`]'s `max_lean`, the cosine of the angle between the edge and a normal):
/// 0.3 leaves out edges more than 17 degrees off either point's tangent plane. Neighbours on
/// one smooth sheet lean by about their distance / (2 x radius of curvature): under 0.25 for
/// 2 mm apart on a 4 mm rounding; an edge across a wall or a sharp edge leans 0.7 to 1.
const ORIENTATION_MAX_LEAN: f64 = 0.3;

/// What [`agreement`] found on a sample.
struct Agreement {
    /// Share of the sampled normals that agree with their sheet's propagated orientation
    /// taken with the sign most of the sheet's normals have.
    consistent: f64,
    /// Whether most of the largest sheet's normals agree with its propagated outward
    /// orientation (seeded up at its highest point).
    largest_outward: bool,
    /// Points of the largest sheet.
    largest: usize,
    /// Sampled points.
    picked: usize,
}

/// Compares the normals of about `size` points of `cloud` (evenly along the file's order)
/// with PCA normals of that sample oriented sheet by sheet ([`orient_sheets`]); None when the
/// sample has fewer than [`ORIENTATION_MIN_POINTS`] points or the cloud no normals.
fn agreement(path: &Path, cloud: &PointCloud, size: usize) -> Result<Option<Agreement>> {
    let step = cloud.len().div_ceil(size).max(1);
    let picked: Vec<usize> = (0..cloud.len()).step_by(step).collect();
    let Some(normals) = cloud.normals.as_ref() else {
        return Ok(None);
    };
    if picked.len() < ORIENTATION_MIN_POINTS {
        return Ok(None);
    }
    let sample = PointCloud::from_points(picked.iter().map(|&i| cloud.points[i]).collect());
    let cfg = NormalConfig {
        orientation: Orientation::Unoriented,
        ..NormalConfig::default()
    };
    let mut est = estimate_normals(&sample, &cfg)
        .with_context(|| format!("{}: reference normals: orientation check", path.display()))?;
    let sheets = orient_sheets(
        &sample.points,
        &mut est.normals,
        cfg.propagate_k,
        ORIENTATION_MAX_LEAN,
    );
    // Per sheet: (points, of which agree).
    let count = sheets.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    let mut tally = vec![(0usize, 0usize); count];
    for ((&i, e), &s) in picked.iter().zip(&est.normals).zip(&sheets) {
        let t = &mut tally[s as usize];
        t.0 += 1;
        t.1 += usize::from(normals[i].dot(e) > 0.0);
    }
    let consistent = tally.iter().map(|&(n, a)| a.max(n - a)).sum::<usize>();
    let &(largest, agree) = tally.iter().max_by_key(|t| t.0).expect("a sample point");
    Ok(Some(Agreement {
        consistent: consistent as f64 / picked.len() as f64,
        largest_outward: 2 * agree >= largest,
        largest,
        picked: picked.len(),
    }))
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

//! Whether a reference cloud's own normals point out of the material, judged sheet by sheet
//! (issue 52): a thin-walled part (a femoral component's articular surface and its box cuts
//! 3-6 mm behind it) has sheets a propagation must not carry a sign across, and an inner sheet
//! whose outward side no seed tells.
//!
//! Two questions, asked of a sample of the cloud:
//! 1. Is each smooth sheet consistent? PCA normals oriented sheet by sheet
//!    ([`orient_sheets`], no edge across a wall) must agree with the file's normals on one sign
//!    per sheet for [`AGREEMENT`] of the points. A sample too sparse to keep the walls apart
//!    fails this, so a failed sample is asked again at full density ([`SAMPLES`]) before a
//!    refusal.
//! 2. Does each sheet point out? A ray from a point along its normal crosses the surface an
//!    even number of times when the normal points out of a closed part (ray parity); each
//!    sheet of at least [`MIN_SHEET_SHARE`] of the sample casts up to [`RAYS_PER_SHEET`] rays
//!    and votes. The vote depends on no sheet's size or seed: an inner sheet is judged as the
//!    outer one is. All sheets in: turned round, with a note; some in and some out: refused.
use std::path::Path;

use anyhow::{bail, Context, Result};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use crate::cloud::PointCloud;
use crate::preprocess::{estimate_normals, orient_sheets, NormalConfig, Orientation};
use crate::spatial::Neighbours;

/// Sizes of the samples asked in turn: 20,000 points settle an ordinary reference quickly; a
/// sample that fails question 1 is asked again with up to 200,000 points (about the densest
/// reference inspect reads), whose neighbours no longer reach across a 3 mm wall.
const SAMPLES: [usize; 2] = [20_000, 200_000];
/// Fewest sampled points for the test (PCA takes 20 neighbours; with fewer the propagated
/// orientation says nothing).
const MIN_POINTS: usize = 200;
/// Share of sampled normals that must agree in sign with their sheet's propagated orientation:
/// PCA normals near sharp edges may disagree with correct normals now and then.
const AGREEMENT: f64 = 0.9;
/// Largest lean of an edge of the propagation graph ([`orient_sheets`]'s `max_lean`, the
/// cosine of the angle between the edge and a normal): 0.3 leaves out edges more than 17
/// degrees off either point's tangent plane. Neighbours on one smooth sheet lean by about
/// their distance / (2 x radius of curvature): under 0.25 for 2 mm apart on a 4 mm rounding;
/// an edge across a wall or a sharp edge leans 0.7 to 1.
const MAX_LEAN: f64 = 0.3;
/// Smallest sheet that votes on its outward side, as a share of the sample: slivers along
/// sharp edges are a few points each and too small to cast a fair vote.
const MIN_SHEET_SHARE: f64 = 0.01;
/// Rays cast per voting sheet (evenly through its points): enough that a few rays grazing an
/// edge do not swing the vote.
const RAYS_PER_SHEET: usize = 64;
/// Radius of a ray, in median point spacings of the sample: wide enough that a crossed
/// surface has a point within it, narrow enough to keep the sides of a 3 mm wall apart.
const RAY_RADIUS_SPACINGS: f64 = 1.5;
/// A point the ray passes whose normal is within this cosine of perpendicular to the ray
/// grazes it and is not counted (the ray may or may not cross there).
const GRAZE: f64 = 0.2;
/// Share of a sheet's rays that must say "out" (even parity) for the sheet to count as
/// pointing out, or say "in" for it to count as pointing in; a sheet between these is left
/// as it is (never turned or refused on a split vote).
const VOTE: f64 = 0.7;

/// Checks a reference cloud's own normals (questions 1 and 2 of the module): kept when every
/// sheet is consistent and points out (or its vote is split), turned round (with a note)
/// when every voting sheet points in, refused naming the file otherwise. Returns the note of
/// a turn.
pub fn orient_outward(path: &Path, cloud: &mut PointCloud) -> Result<Option<String>> {
    if cloud.normals.is_none() || cloud.len() < MIN_POINTS {
        return Ok(None);
    }
    let mut found = None;
    for size in SAMPLES {
        let s = sheets(path, cloud, size)?;
        let enough = s.consistent >= AGREEMENT;
        found = Some(s);
        if enough || size >= cloud.len() {
            break;
        }
    }
    let s = found.expect("one sample");
    if s.consistent < AGREEMENT {
        bail!(
            "{}: reference normals are not consistently oriented: {:.0} % of {} sampled normals \
             agree with a propagated orientation of their own smooth sheet (need {:.0} %)",
            path.display(),
            100.0 * s.consistent,
            s.picked.len(),
            100.0 * AGREEMENT
        );
    }
    let votes = votes(cloud, &s);
    let inward: Vec<&Vote> = votes.iter().filter(|v| v.out <= 1.0 - VOTE).collect();
    let outward = votes.iter().filter(|v| v.out >= VOTE).count();
    match (inward.first(), outward) {
        (None, _) => Ok(None),
        (Some(v), 0) => {
            let normals = cloud.normals.as_mut().expect("normals");
            normals.iter_mut().for_each(|n| *n = -*n);
            Ok(Some(format!(
                "{}: the reference normals point inward ({} of {} sampled points on sheets whose \
                 normals point into the material, e.g. {:.0} % of the rays of a sheet of {}): \
                 turned round",
                path.display(),
                inward.iter().map(|v| v.points).sum::<usize>(),
                s.picked.len(),
                100.0 * (1.0 - v.out),
                v.points
            )))
        }
        (Some(v), _) => bail!(
            "{}: reference normals point into the material on one sheet and out of it on \
             others: the sheet of {} sampled points around point {} ({:.4}, {:.4}, {:.4}) mm \
             points in ({:.0} % of its rays cross the surface an odd number of times)",
            path.display(),
            v.points,
            v.at,
            cloud.points[v.at].x,
            cloud.points[v.at].y,
            cloud.points[v.at].z,
            100.0 * (1.0 - v.out)
        ),
    }
}

/// What [`sheets`] found on a sample.
struct Sheets {
    /// The sampled point indices (into the cloud).
    picked: Vec<usize>,
    /// Per sampled point its sheet.
    sheet: Vec<u32>,
    /// Share of the sampled normals that agree with their sheet's propagated orientation
    /// taken with the sign most of the sheet's normals have.
    consistent: f64,
}

/// Orients PCA normals of about `size` points of `cloud` (evenly along the file's order)
/// sheet by sheet ([`orient_sheets`]) and compares the cloud's normals with them.
fn sheets(path: &Path, cloud: &PointCloud, size: usize) -> Result<Sheets> {
    let normals = cloud.normals.as_ref().expect("normals");
    let step = cloud.len().div_ceil(size).max(1);
    let picked: Vec<usize> = (0..cloud.len()).step_by(step).collect();
    let sample = PointCloud::from_points(picked.iter().map(|&i| cloud.points[i]).collect());
    let cfg = NormalConfig {
        orientation: Orientation::Unoriented,
        ..NormalConfig::default()
    };
    let mut est = estimate_normals(&sample, &cfg)
        .with_context(|| format!("{}: reference normals: orientation check", path.display()))?;
    let sheet = orient_sheets(&sample.points, &mut est.normals, cfg.propagate_k, MAX_LEAN);
    // Per sheet: (points, of which agree).
    let count = sheet.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
    let mut tally = vec![(0usize, 0usize); count];
    for ((&i, e), &s) in picked.iter().zip(&est.normals).zip(&sheet) {
        let t = &mut tally[s as usize];
        t.0 += 1;
        t.1 += usize::from(normals[i].dot(e) > 0.0);
    }
    let consistent = tally.iter().map(|&(n, a)| a.max(n - a)).sum::<usize>();
    Ok(Sheets {
        consistent: consistent as f64 / picked.len() as f64,
        picked,
        sheet,
    })
}

/// One sheet's vote on its outward side.
struct Vote {
    /// Sampled points of the sheet.
    points: usize,
    /// A point of the sheet (cloud index), for the message.
    at: usize,
    /// Share of its rays with even parity (the file's normals point out).
    out: f64,
}

/// The votes of the sheets of at least [`MIN_SHEET_SHARE`] of the sample (module doc,
/// question 2).
fn votes(cloud: &PointCloud, s: &Sheets) -> Vec<Vote> {
    let normals = cloud.normals.as_ref().expect("normals");
    let points: Vec<Point3<f64>> = s.picked.iter().map(|&i| cloud.points[i]).collect();
    let dirs: Vec<Vector3<f64>> = s.picked.iter().map(|&i| normals[i]).collect();
    let index = Neighbours::new(&points);
    let radius = RAY_RADIUS_SPACINGS * super::area::spacing(&points);
    let reach = diagonal(&points);
    let count = s.sheet.iter().map(|&k| k as usize + 1).max().unwrap_or(0);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (j, &k) in s.sheet.iter().enumerate() {
        members[k as usize].push(j);
    }
    let least = ((MIN_SHEET_SHARE * points.len() as f64).ceil() as usize).max(RAYS_PER_SHEET);
    members
        .par_iter()
        .filter(|m| m.len() >= least)
        .map(|m| {
            let step = m.len().div_ceil(RAYS_PER_SHEET);
            let rays: Vec<usize> = m.iter().step_by(step).copied().collect();
            let even = rays
                .iter()
                .filter(|&&j| crossings(&index, &points, &dirs, j, radius, reach).is_multiple_of(2))
                .count();
            Vote {
                points: m.len(),
                at: s.picked[m[0]],
                out: even as f64 / rays.len() as f64,
            }
        })
        .collect()
}

/// The times a ray from sampled point `from` along its normal crosses the sampled surface
/// within `reach`: the points within `radius` of the ray (past `radius` from its start, not
/// grazing it, [`GRAZE`]) in order along it, a new crossing wherever the side their normals
/// face turns or a gap of over 2 x `radius` opens.
fn crossings(
    index: &Neighbours,
    points: &[Point3<f64>],
    dirs: &[Vector3<f64>],
    from: usize,
    radius: f64,
    reach: f64,
) -> usize {
    let (p, d) = (points[from], dirs[from]);
    let mut hits: Vec<(f64, bool, usize)> = Vec::new();
    let mut t = radius;
    while t <= reach + radius {
        for nb in index.within_unsorted(&(p + d * t), radius * std::f64::consts::SQRT_2) {
            let v = points[nb.index] - p;
            let along = v.dot(&d);
            let facing = dirs[nb.index].dot(&d);
            if along > radius && (v - d * along).norm() <= radius && facing.abs() > GRAZE {
                hits.push((along, facing > 0.0, nb.index));
            }
        }
        t += 2.0 * radius;
    }
    hits.sort_unstable_by_key(|h| h.2);
    hits.dedup_by_key(|h| h.2);
    hits.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut runs = 0;
    let mut last: Option<(f64, bool)> = None;
    for &(along, side, _) in &hits {
        if last.is_none_or(|(t0, s0)| s0 != side || along - t0 > 2.0 * radius) {
            runs += 1;
        }
        last = Some((along, side));
    }
    runs
}

/// The diagonal of the points' bounding box (0 for none).
fn diagonal(points: &[Point3<f64>]) -> f64 {
    let Some(first) = points.first() else {
        return 0.0;
    };
    let (lo, hi) = points
        .iter()
        .fold((first.coords, first.coords), |(lo, hi), p| {
            (lo.inf(&p.coords), hi.sup(&p.coords))
        });
    (hi - lo).norm()
}

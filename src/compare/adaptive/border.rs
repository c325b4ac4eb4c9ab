//! Step 8, border: a cylinder's value beside unmeasured surface must stand on its disc's
//! scan points. Where a core point without a distance for want of scan (a hole, the scan's
//! border, the shadow of a defect) lies within the largest radius of a core point measured by
//! a cylinder (same surface by the normal filter), that core point's fit is made again and
//! checked (`cover.rs`, step 3: at least `BORDER_FIT_MIN` scan points kept and `BORDER_FILL`
//! of those its disc's reference points predict); a fit that fails gives no distance
//! ([`Reason::ScanBorder`]). The core points it withdraws make their neighbours' fits checked
//! in turn, until none is withdrawn (each fit is checked once). Values a peak model gave or
//! fitted are kept. A scan without core points lacking scan is untouched.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::context::Context;
use super::fit::at_supported;
use super::radius::Scratch;
use crate::compare::config::CompareConfig;
use crate::compare::deviation::{Deviation, Reason};
use crate::spatial::Neighbours;

/// Nearest unmeasured core points looked at per measured one (those of another surface, by
/// the normal filter, do not count; a few suffice to find one of its own within reach).
const NEAREST_UNMEASURED: usize = 8;

/// Withdraws the distance of every core point of `points` (outward unit `normals`, results
/// `values`) measured by a cylinder whose fit its disc's scan points do not support, when a
/// core point of its surface lacking scan lies within the largest radius (module doc).
pub(super) fn withdraw_unsupported(
    prep: &Context,
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &mut [Deviation],
    cfg: &CompareConfig,
) {
    let unscanned = |v: &Deviation| matches!(v.reason, Reason::FewScan | Reason::ScanBorder);
    let mut holes: Vec<usize> = (0..values.len())
        .filter(|&i| unscanned(&values[i]))
        .collect();
    // A fit checked once gives the same answer again.
    let mut checked = vec![false; values.len()];
    while !holes.is_empty() {
        let index = Neighbours::new(&holes.iter().map(|&i| points[i]).collect::<Vec<_>>());
        let beside = |i: usize| {
            index
                .knn_within(&points[i], NEAREST_UNMEASURED, prep.largest_radius())
                .iter()
                .any(|nb| normals[holes[nb.index]].dot(&normals[i]) >= prep.cos_limit)
        };
        let candidates: Vec<usize> = (0..values.len())
            .into_par_iter()
            .filter(|&i| {
                let v = &values[i];
                !checked[i] && v.reason == Reason::Ok && !v.peak_fitted && beside(i)
            })
            .collect();
        candidates.iter().for_each(|&i| checked[i] = true);
        let withdrawn = unsupported(prep, points, normals, values, cfg, &candidates);
        holes = withdrawn.iter().map(|&(i, _)| i).collect();
        for (i, v) in withdrawn {
            values[i] = v;
        }
    }
}

/// Of the core points `candidates`, those whose fit (made again) its disc's scan points do
/// not support, each with its missing result; a value another step replaced (a different
/// distance) is left alone.
fn unsupported(
    prep: &Context,
    points: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &[Deviation],
    cfg: &CompareConfig,
    candidates: &[usize],
) -> Vec<(usize, Deviation)> {
    candidates
        .par_iter()
        .map_init(Scratch::default, |scratch, &i| {
            (i, at_supported(prep, &points[i], &normals[i], cfg, scratch))
        })
        .filter(|(i, (v, support))| {
            !support.enough(prep.scan_per_reference)
                && v.distance.to_bits() == values[*i].distance.to_bits()
        })
        .map(|(i, (v, _))| {
            let missing = Deviation::missing(Reason::ScanBorder, v.radius, v.n_ref, v.n_scan);
            (i, missing)
        })
        .collect()
}

//! Densification (adaptive variant): extra core points where a defect may lie between the
//! given ones. A defect narrower than about twice the core-point spacing holds one or two core
//! points, often off its top, and a region needs `min_points` error points; so at every summit
//! of the significant core points beyond `densify_above` whose LoD is at most twice that (the
//! tolerance, in `inspect`) and whose cylinder is mostly covered by the reference surface
//! ([`MIN_COVERAGE`]; the largest |distance| of its sign among them within the refine radius),
//! each reference point within the refine radius (normal within
//! `max_normal_angle`, not itself a core point) becomes a core point of its own, evaluated
//! like the others. docs/ALGORITHMS.md has the numbers.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::adaptive::{at, summits, Prepared, Scratch};
use super::{CompareConfig, Deviation};

/// A summit's cylinder must hold at least this share of the reference points a full disc of
/// its radius holds: fits through the few points of a narrow face or a strip beside an edge
/// (a third or less) give chance error points that densification would turn into regions.
const MIN_COVERAGE: f64 = 0.6;

/// Core points added by [`densify`].
#[derive(Default)]
pub(super) struct Densified {
    /// The reference points made core points.
    pub points: Vec<Point3<f64>>,
    /// Their outward unit normals (the reference's).
    pub normals: Vec<Vector3<f64>>,
}

/// The extra core points around the summits among `values` (one per core point of `prep`,
/// whose outward unit normals are `normals`), and their results.
pub(super) fn densify(
    prep: &Prepared,
    normals: &[Vector3<f64>],
    values: &[Deviation],
    cfg: &CompareConfig,
) -> (Densified, Vec<Deviation>) {
    let above = cfg.adaptive.densify_above;
    // Reference points per mm² (median): a full disc of radius r holds about π r² of them.
    let density = super::surface_density(&prep.clouds.ref_grid);
    let candidates: Vec<usize> = (0..values.len())
        .filter(|&i| {
            let v = &values[i];
            let disc = std::f64::consts::PI * v.radius * v.radius * density;
            v.significant
                && v.distance.abs() > above
                && v.uncertainty <= 2.0 * above
                && v.n_ref as f64 >= MIN_COVERAGE * disc
        })
        .collect();
    if candidates.is_empty() {
        return (Densified::default(), Vec::new());
    }
    let distances: Vec<f64> = values.iter().map(|v| v.distance).collect();
    let tops = summits(prep, prep.core, &candidates, &distances);
    let c = prep.clouds;
    let mut extra: Vec<usize> = tops
        .par_iter()
        .map_init(Vec::new, |near, &i| {
            let (p, n) = (&prep.core[i], &normals[i]);
            near.clear();
            c.ref_grid
                .cylinder(p, n, prep.refine_radius, cfg.max_distance, near);
            near.iter()
                .map(|m| m.index)
                .filter(|&j| {
                    let x = &c.reference.points[j];
                    prep.ref_normals[j].dot(n) >= prep.cos_limit
                        && prep.nearest_core(x).is_some_and(|c| c != x)
                })
                .collect::<Vec<usize>>()
        })
        .flatten()
        .collect();
    extra.sort_unstable();
    extra.dedup();
    let values = extra
        .par_iter()
        .map_init(Scratch::default, |scratch, &j| {
            let (x, n) = (&c.reference.points[j], &prep.ref_normals[j]);
            at(prep, x, n, cfg, scratch)
        })
        .collect();
    let added = Densified {
        points: extra.iter().map(|&j| c.reference.points[j]).collect(),
        normals: extra.iter().map(|&j| prep.ref_normals[j]).collect(),
    };
    (added, values)
}

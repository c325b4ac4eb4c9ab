//! Step 4, refine: the distance at every given core point ([`super::fit::at`]), and for the
//! significant ones beyond `refine_above` (the tolerance) the peak around it. A defect
//! narrower than the core spacing has its top between core points: the reference points of
//! the core point's cell (nearest to it among the core points; normal within
//! `max_normal_angle`) are evaluated like core points, and the largest distance of the same
//! sign whose fit describes the surface becomes the core point's `peak`, with where it lies
//! (its top, where the peak fit looks).
use nalgebra::{Point3, Vector3};

use super::context::Context;
use super::fit::at;
use super::radius::Scratch;
use crate::cloud::PointCloud;
use crate::compare::config::CompareConfig;
use crate::compare::deviation::{Deviation, PEAK_LOD_RATIO};

/// The given core points measured: one result each, and where its peak lies.
pub(super) struct Measured {
    /// One result per given core point.
    pub(super) values: Vec<Deviation>,
    /// Where each one's peak was found (the core point unless a reference point of its cell
    /// gave it).
    pub(super) tops: Vec<Point3<f64>>,
}

/// Every core point of `core` (outward unit `normals`) measured and refined, in parallel.
pub(super) fn measure(
    prep: &Context,
    core: &PointCloud,
    normals: &[Vector3<f64>],
    cfg: &CompareConfig,
) -> Measured {
    let grid = &prep.clouds.ref_grid;
    let refined = crate::compare::clouds::run(grid, core, normals, |s: &mut Scratch, p, n| {
        let dev = at(prep, p, n, cfg, s);
        refine(prep, dev, p, n, cfg, s)
    });
    let (values, tops) = refined.into_iter().unzip();
    Measured { values, tops }
}

/// Sets `dev.peak` of a significant core point beyond `refine_above` to the distance of
/// largest magnitude, of the same sign, at it and at the reference points of its cell (nearest
/// to it among the core points; normal within `max_normal_angle`) whose fit describes the
/// surface (residual SD at most `max_misfit` × noise): a defect narrower than the core spacing
/// has its top between core points. Also returns where that peak was found (`p` unless a
/// reference point of the cell gave it).
fn refine(
    prep: &Context,
    mut dev: Deviation,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    cfg: &CompareConfig,
    scratch: &mut Scratch,
) -> (Deviation, Point3<f64>) {
    let mut top = *p;
    if !prep.refined(&dev) {
        return (dev, top);
    }
    // The candidate list is taken out of the scratch while `at` uses the rest of it.
    let mut near = std::mem::take(&mut scratch.near);
    near.clear();
    let c = prep.clouds;
    prep.reference_near(p, n, prep.refine_radius, cfg.max_distance, &mut near);
    for &m in &near {
        let (x, nx) = (&c.reference.points[m], &prep.ref_normals[m]);
        let own_cell = prep.nearest_core(x) == Some(p);
        if nx.dot(n) < prep.cos_limit || !own_cell {
            continue;
        }
        let d = at(prep, x, nx, cfg, scratch);
        if d.significant
            && d.spread[1] <= cfg.adaptive.max_misfit * prep.noise
            && d.uncertainty <= PEAK_LOD_RATIO * dev.uncertainty
            && d.distance * dev.peak > 0.0
            && d.distance.abs() > dev.peak.abs()
        {
            dev.peak = d.distance;
            top = *x;
        }
    }
    scratch.near = near;
    (dev, top)
}

//! Adaptive M3C2: per core point, the cylinder radius follows the RWME similarity of the
//! reference part X and the scan part Y inside it, and the distance is the offset between the
//! two surfaces' crossings of the normal line, from local quadric fits of the point pairs.
//! Around the defects, peak models of the scan points measure what the cylinders smooth.
//!
//! [`run`] reads top to bottom, one file per step:
//! 1. [`prepare`]: per cloud, once: the point pairs ([`point_pair`]: each scan point's height
//!    above its paired reference point's tangent plane), δ and the RWME terms per reference
//!    point, the noise, the refine radius, the thresholds from the tolerance ([`context`]).
//! 2. [`radius`]: per core point, the RWME similarity per candidate radius and the radius.
//! 3. [`fit`]: the quadric fit at that radius ([`quadric`]), grown while the confidence
//!    intervals intersect; the distance and its LoD.
//! 4. [`refine`]: the peak of each error point from the reference points of its cell.
//! 5. [`densify`]: core points added around the summits of defects, and narrow defects
//!    measured by peak models. It runs before the peak fit, which also fits the summits it
//!    added.
//! 6. [`peaks`]: the peak model ([`peak_model`], [`peak_shape`], in its window: [`model`]) at
//!    each summit gives its peak.
//! 7. [`fill`]: inside a defect a model describes, its height at the core points.
//! 8. [`border`]: beside core points without scan, cylinder values their disc's scan points
//!    do not support are withdrawn.
//!
//! Settings: [`crate::compare::AdaptiveConfig`]; docs/ALGORITHMS.md has the method.
mod border;
mod context;
mod densify;
mod fill;
mod fit;
mod model;
mod peak_model;
mod peak_shape;
mod peaks;
mod point_pair;
mod prepare;
mod quadric;
mod radius;
mod refine;

use anyhow::Result;
use nalgebra::{Point3, Vector3};

pub(super) use self::radius::radii;
use crate::cloud::PointCloud;
use crate::compare::clouds::Clouds;
use crate::compare::config::CompareConfig;
use crate::compare::deviation::Deviation;

/// Runs the adaptive variant at every core point of `core` (outward unit `normals`) with the
/// candidate `radii`, adding core points around the summits of defects.
pub(super) fn run(
    clouds: &Clouds,
    core: &PointCloud,
    normals: &[Vector3<f64>],
    radii: &[f64],
    cfg: &CompareConfig,
) -> Result<Evaluated> {
    let a = &cfg.adaptive;
    let ctx = prepare::prepare(clouds, core, radii, cfg)?;
    // Steps 2-4 at every given core point.
    let measured = refine::measure(&ctx, core, normals, cfg);
    let added = densify::densify(&ctx, normals, &measured.values, cfg);
    // The added core points follow the given ones; each is its own top.
    let mut values = measured.values;
    values.extend(added.values);
    let tops = [measured.tops, added.points.clone()].concat();
    let points = [&core.points[..], &added.points].concat();
    let normals = [normals, &added.normals].concat();
    let mut models = added.models;
    if a.peak_fit {
        models.extend(peaks::fit_peaks(
            &ctx,
            &points,
            &tops,
            &normals,
            &mut values,
            cfg,
        ));
    }
    if a.model_fill {
        fill::fill(&ctx, &points, &normals, &mut values, models, cfg);
    }
    border::withdraw_unsupported(&ctx, &points, &normals, &mut values, cfg);
    Ok(Evaluated {
        values,
        noise: ctx.noise,
        points,
        normals,
    })
}

/// What [`run`] returns: every core point (the given ones, then those densification added)
/// with its outward unit normal and result, and the noise used.
pub(super) struct Evaluated {
    /// One result per core point.
    pub values: Vec<Deviation>,
    /// Scan noise used, mm.
    pub noise: f64,
    /// The core points.
    pub points: Vec<Point3<f64>>,
    /// Their outward unit normals.
    pub normals: Vec<Vector3<f64>>,
}

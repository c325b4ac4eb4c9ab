//! Step 6, peaks (`peak_fit`): the height of each defect's top from a model of its shape
//! ([`super::peak_model`]) fitted to the scan points around it, in place of the largest of
//! the cylinders' smoothed values.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::context::Context;
use super::model::{fit_window, gather_window, Model, ModelScratch};
use crate::compare::config::CompareConfig;
use crate::compare::deviation::{Deviation, Reason};

/// The peak fit (`peak_fit`): at every summit — a refined core point whose |peak| is the
/// largest among the refined core points of the same sign within the refine radius (one per
/// bump, a few along a ridge) — the peak model is fitted to the scan points within the
/// window radius (largest candidate radius + refine radius: the cell's reach plus the widest
/// flank a quadric estimate sees) of the refined top, in the tangent frame of the core point's
/// normal, heights = the point-pair distances. An accepted fit replaces that core point's peak;
/// the accepted models are returned.
pub(super) fn fit_peaks(
    prep: &Context,
    points: &[Point3<f64>],
    tops: &[Point3<f64>],
    normals: &[Vector3<f64>],
    values: &mut [Deviation],
    cfg: &CompareConfig,
) -> Vec<Model> {
    // Points a peak model measured (densification) have their peak from it already.
    let refined_ids: Vec<usize> = (0..values.len())
        .filter(|&i| prep.refined(&values[i]) && values[i].reason != Reason::PeakModel)
        .collect();
    if refined_ids.is_empty() {
        return Vec::new();
    }
    let peaks: Vec<f64> = values.iter().map(|v| v.peak).collect();
    let summits = prep.summits(points, &refined_ids, &peaks);
    let fitted: Vec<(usize, Model)> = summits
        .par_iter()
        .map_init(ModelScratch::default, |scratch, &i| {
            gather_window(prep, &tops[i], &normals[i], prep.peak_window(), scratch);
            let (fit, w) = fit_window(prep, values[i].peak, cfg, scratch)?;
            fit.accepted(&w)
                .then(|| (i, Model::new(tops[i], normals[i], fit)))
        })
        .flatten()
        .collect();
    fitted
        .into_iter()
        .map(|(i, model)| {
            values[i].peak = model.fit.peak;
            values[i].peak_fitted = true;
            model
        })
        .collect()
}

//! Pairwise alignment of one view onto a target surface (another view, or the union of the
//! views placed so far) with the register stage's ICP.
use anyhow::Result;
use nalgebra::{Isometry3, Point3, Vector3};

use super::config::MergeConfig;
use crate::cloud::PointCloud;
use crate::preprocess::{estimate_normals, mean_spacing_in, NormalConfig, Orientation};
use crate::register::icp::{fitness, icp, IcpParams};
use crate::register::{register, RegisterConfig};
use crate::spatial::Grid;

/// A view prepared as an ICP target and as a source.
pub(super) struct Prepared {
    /// Target points: the view thinned to at most `icp_target_points` (evenly strided).
    pub target: Vec<Point3<f64>>,
    /// Grid of `target`.
    pub index: Grid,
    /// Unoriented PCA normals of `target`.
    pub normals: Vec<Vector3<f64>>,
    /// Source points (evenly strided, at most `icp_max_points`).
    pub sample: Vec<Point3<f64>>,
    /// Mean spacing of the target points.
    pub spacing: f64,
    /// Every [`COARSE_EVERY`]-th target point with its normal and their grid: the target of
    /// the pull's two wide stages (None for a union, which is only refined onto).
    pub coarse: Option<Coarse>,
}

/// A thinned copy of a view's target for the wide ICP stages.
pub(super) struct Coarse {
    target: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    index: Grid,
}

/// Every how many target points the two wide stages of [`pair_icp`] (30 and 16.5 mr) match
/// against. They only pull the pose in (the final stage matches every target point) and a
/// nearest-point search within 30 mr costs with the number of points in reach: on the
/// 36-view turn they took half of the pulls' time on a quarter and a half of the sample.
/// The normals stay those of the full target (the planes are as exact), the matches are up
/// to about two spacings coarser, well inside the stages' distances.
const COARSE_EVERY: usize = 4;

impl Coarse {
    fn of(target: &[Point3<f64>], normals: &[Vector3<f64>]) -> Coarse {
        let target: Vec<Point3<f64>> = target.iter().step_by(COARSE_EVERY).copied().collect();
        Coarse {
            index: Grid::for_points(&target),
            normals: normals.iter().step_by(COARSE_EVERY).copied().collect(),
            target,
        }
    }
}

/// Every `len / max_points`-th point (rounded up): at most `max_points` of them.
pub(super) fn strided<T: Copy>(points: &[T], max_points: usize) -> Vec<T> {
    let stride = points.len().div_ceil(max_points.max(1)).max(1);
    points.iter().step_by(stride).copied().collect()
}

/// Prepares one view as ICP target and source.
pub(super) fn prepare(view: &PointCloud, cfg: &MergeConfig) -> Result<Prepared> {
    let ncfg = NormalConfig {
        orientation: Orientation::Unoriented,
        ..NormalConfig::default()
    };
    let target = strided(&view.points, cfg.icp_target_points);
    let target_cloud = PointCloud::from_points(target.clone());
    let normals = estimate_normals(&target_cloud, &ncfg)?.normals;
    let index = Grid::for_points(&target);
    Ok(Prepared {
        coarse: Some(Coarse::of(&target, &normals)),
        // The grid mean_spacing would build over the same points.
        spacing: mean_spacing_in(&index, &target),
        index,
        target,
        normals,
        sample: strided(&view.points, cfg.icp_max_points),
    })
}

/// The union of the targets of `members` (prepared view, its view-to-first pose) in the first
/// view's frame, each member thinned evenly so that the union holds at most `max_points`: the
/// growing model a new view is aligned against. No sample (it is only a target).
pub(super) fn union(members: &[(&Prepared, Isometry3<f64>)], max_points: usize) -> Prepared {
    let total: usize = members.iter().map(|(p, _)| p.target.len()).sum();
    let stride = total.div_ceil(max_points.max(1)).max(1);
    let (mut target, mut normals) = (Vec::new(), Vec::new());
    for (p, pose) in members {
        for (q, n) in p.target.iter().zip(&p.normals).step_by(stride) {
            target.push(pose * q);
            normals.push(pose.rotation * n);
        }
    }
    Prepared {
        index: Grid::for_points(&target),
        target,
        normals,
        sample: Vec::new(),
        coarse: None,
        spacing: members.iter().map(|(p, _)| p.spacing).fold(0.0, f64::max),
    }
}

/// Correspondence distance of a stage between `src` and `dst`, in mm, from one in mr.
fn distance(src: &Prepared, dst: &Prepared, in_mr: f64) -> f64 {
    in_mr * src.spacing.max(dst.spacing)
}

/// Share of `src`'s sample points (every `every`-th) within `in_mr` mean spacings of `dst`
/// under `pose`.
pub(super) fn overlap(
    src: &Prepared,
    dst: &Prepared,
    pose: &Isometry3<f64>,
    in_mr: f64,
    every: usize,
) -> f64 {
    let sample: Vec<Point3<f64>> = src.sample.iter().step_by(every.max(1)).copied().collect();
    fitness(&sample, &dst.index, pose, distance(src, dst, in_mr)).0
}

/// Aligns `src` onto `dst` from `init`: ICP at the start distance, a middle distance and the
/// final distance; the first two stages use every 4th and every 2nd sample point and the
/// coarse target ([`COARSE_EVERY`]; they only pull the pose in). With `short`, only the final
/// stage runs (a short-range refinement that cannot wander far from `init`). Returns the pose and
/// its fitness at the final distance.
pub(super) fn pair_icp(
    src: &Prepared,
    dst: &Prepared,
    init: &Isometry3<f64>,
    cfg: &MergeConfig,
    short: bool,
) -> (Isometry3<f64>, f64) {
    let mr = src.spacing.max(dst.spacing);
    let mut pose = *init;
    let coarse: Vec<Point3<f64>> = src.sample.iter().step_by(4).copied().collect();
    let middle: Vec<Point3<f64>> = src.sample.iter().step_by(2).copied().collect();
    // (distance in mr, source points, tolerance, on the coarse target)
    let stages = [
        (cfg.start_distance, &coarse, 1e-6, true),
        (
            0.5 * (cfg.start_distance + cfg.final_distance),
            &middle,
            1e-6,
            true,
        ),
        (cfg.final_distance, &src.sample, 1e-9, false),
    ];
    let first = if short { 2 } else { 0 };
    let mut fit = 0.0;
    for (d, sample, tolerance, wide) in &stages[first..] {
        let p = IcpParams {
            max_distance: d * mr,
            max_iterations: cfg.icp_max_iterations,
            relative_tolerance: *tolerance,
            kernel_scale: None,
            min_kernel_scale: 1e-3 * mr,
        };
        let r = match dst.coarse.as_ref().filter(|_| *wide) {
            Some(c) => icp(sample, &c.target, &c.normals, &c.index, &pose, &p),
            None => icp(sample, &dst.target, &dst.normals, &dst.index, &pose, &p),
        };
        pose = r.pose;
        fit = r.fitness;
    }
    // The final stage's fitness: the share of the whole sample it matched within the final
    // distance at its last matching, which is at the pose it returns (or within a step of
    // norm 1e-13 of it, when such a step ended it); matching the sample once more there
    // cost one more ICP iteration.
    (pose, fit)
}

/// Coarse registration (`register()`: FPFH + MAC + ICP) of view `s` onto view `d`, refined by
/// the merge ICP; None when it does not fit.
pub(super) fn coarse_pair(
    views: &[PointCloud],
    prepared: &[Prepared],
    (s, d): (usize, usize),
    cfg: &MergeConfig,
) -> Option<(Isometry3<f64>, f64)> {
    let reg = register(&views[s], &views[d], &RegisterConfig::default()).ok()?;
    let (pose, f) = pair_icp(&prepared[s], &prepared[d], &reg.pose, cfg, false);
    (f >= cfg.min_fitness).then_some((pose, f))
}

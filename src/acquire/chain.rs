//! Pairwise alignment along the chain of views and loop closure.
use anyhow::{bail, Result};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::MergeConfig;
use crate::cloud::PointCloud;
use crate::preprocess::{estimate_normals, mean_spacing, NormalConfig, Orientation};
use crate::register::icp::{fitness, icp, IcpParams};
use crate::register::{register, RegisterConfig};
use crate::spatial::Grid;

/// A view the chain could align.
pub(super) struct ChainPose {
    /// Index into the input views.
    pub index: usize,
    /// View-to-first pose.
    pub pose: Isometry3<f64>,
    /// Fitness onto the previous aligned view.
    pub fitness: f64,
    /// Coarse alignment was needed.
    pub coarse: bool,
}

/// Result of [`align_chain`].
pub(super) struct Chain {
    /// Aligned views in order.
    pub poses: Vec<ChainPose>,
    /// Names of skipped views.
    pub skipped: Vec<String>,
    /// Closure error before distribution (deg, mm).
    pub loop_closure: Option<[f64; 2]>,
}

/// A view prepared as an ICP target and as a source.
pub(super) struct Prepared {
    /// Target points: the view thinned to at most `icp_target_points` (evenly strided).
    target: Vec<Point3<f64>>,
    index: Grid,
    /// Unoriented PCA normals of `target`.
    normals: Vec<Vector3<f64>>,
    /// Source points (evenly strided, at most `icp_max_points`).
    sample: Vec<Point3<f64>>,
    /// Mean spacing of the target points.
    spacing: f64,
}

fn strided(points: &[Point3<f64>], max_points: usize) -> Vec<Point3<f64>> {
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
    Ok(Prepared {
        index: Grid::for_points(&target),
        target,
        normals,
        sample: strided(&view.points, cfg.icp_max_points),
        spacing: mean_spacing(&target_cloud),
    })
}

/// Aligns `src` onto `dst` from `init`: ICP at the start distance, a middle distance and the
/// final distance; the first two stages use every 4th and every 2nd sample point (they only
/// pull the pose in). Returns the pose and its fitness at the final distance.
fn pair_icp(
    src: &Prepared,
    dst: &Prepared,
    init: &Isometry3<f64>,
    cfg: &MergeConfig,
) -> (Isometry3<f64>, f64) {
    let mr = src.spacing.max(dst.spacing);
    let mut pose = *init;
    let coarse: Vec<Point3<f64>> = src.sample.iter().step_by(4).copied().collect();
    let middle: Vec<Point3<f64>> = src.sample.iter().step_by(2).copied().collect();
    for (d, sample, tolerance) in [
        (cfg.start_distance, &coarse, 1e-6),
        (
            0.5 * (cfg.start_distance + cfg.final_distance),
            &middle,
            1e-6,
        ),
        (cfg.final_distance, &src.sample, 1e-9),
    ] {
        let p = IcpParams {
            max_distance: d * mr,
            max_iterations: cfg.icp_max_iterations,
            relative_tolerance: tolerance,
            kernel_scale: None,
            min_kernel_scale: 1e-3 * mr,
        };
        pose = icp(sample, &dst.target, &dst.normals, &dst.index, &pose, &p).pose;
    }
    let (f, _) = fitness(&src.sample, &dst.index, &pose, cfg.final_distance * mr);
    (pose, f)
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
    let (pose, f) = pair_icp(&prepared[s], &prepared[d], &reg.pose, cfg);
    (f >= cfg.min_fitness).then_some((pose, f))
}

/// Pairwise alignment: ICP from `init`, coarse registration when that does not fit.
fn align_pair(
    views: &[PointCloud],
    prepared: &[Prepared],
    (s, d): (usize, usize),
    init: &Isometry3<f64>,
    cfg: &MergeConfig,
) -> Option<(Isometry3<f64>, f64, bool)> {
    let (pose, f) = pair_icp(&prepared[s], &prepared[d], init, cfg);
    if f >= cfg.min_fitness {
        return Some((pose, f, false));
    }
    coarse_pair(views, prepared, (s, d), cfg).map(|(pose, f)| (pose, f, true))
}

/// True when the views make a full turn: the next step after the last view reaches 360.
fn full_turn(angles: &[f64]) -> bool {
    let n = angles.len();
    if n < 3 {
        return false;
    }
    let step = (angles[n - 1] - angles[0]) / (n - 1) as f64;
    let next = angles[n - 1] + step - angles[0];
    (next.abs() - 360.0).abs() < 0.5 * step.abs()
}

/// Spreads the closure error `e` (direct last-to-first pose times the inverse chained one)
/// over the m edges of the loop: view k's pose is corrected by the fraction k / m of `e`.
fn distribute(poses: &mut [ChainPose], e: &Isometry3<f64>) {
    let m = poses.len() as f64;
    let (axis_angle, t) = (e.rotation.scaled_axis(), e.translation.vector);
    for (k, p) in poses.iter_mut().enumerate() {
        let f = k as f64 / m;
        let corr = Isometry3::from_parts(
            Translation3::from(f * t),
            UnitQuaternion::from_scaled_axis(f * axis_angle),
        );
        p.pose = corr * p.pose;
    }
}

/// Chains pairwise alignments from the nominal poses and closes the loop on a full turn.
pub(super) fn align_chain(
    views: &[PointCloud],
    prepared: &[Prepared],
    names: &[String],
    angles: &[f64],
    nominal: &[Isometry3<f64>],
    cfg: &MergeConfig,
) -> Result<Chain> {
    let mut poses = vec![ChainPose {
        index: 0,
        pose: Isometry3::identity(),
        fitness: 1.0,
        coarse: false,
    }];
    let mut skipped = Vec::new();
    for i in 1..views.len() {
        let prev = poses.last().expect("first view");
        let j = prev.index;
        let init = nominal[j].inverse() * nominal[i];
        match align_pair(views, prepared, (i, j), &init, cfg) {
            Some((rel, f, coarse)) => {
                let pose = prev.pose * rel;
                poses.push(ChainPose {
                    index: i,
                    pose,
                    fitness: f,
                    coarse,
                });
            }
            None if cfg.skip_bad => skipped.push(names[i].clone()),
            None => bail!(
                "{}: cannot be aligned to {} (ICP from the nominal angle {} deg and coarse \
                 alignment both fit below {}); use --skip-bad to leave it out",
                names[i],
                names[j],
                angles[i],
                cfg.min_fitness
            ),
        }
    }
    let mut loop_closure = None;
    let last_pose = poses.last().expect("first view");
    let (l, last) = (last_pose.index, last_pose.pose);
    // Only a loop whose last view was kept closes; a closure error of half a step or more is
    // a wrong match, not drift.
    let half_step =
        0.5 * (angles[angles.len() - 1] - angles[0]).abs() / (angles.len().max(2) - 1) as f64;
    if full_turn(angles) && poses.len() >= 3 && l == views.len() - 1 {
        // The chained pose is a closer start than the nominal one.
        if let Some((rel, _, _)) = align_pair(views, prepared, (l, 0), &last, cfg) {
            // last -> first measured directly versus through the chain.
            let e = rel * last.inverse();
            if e.rotation.angle().to_degrees() < half_step {
                loop_closure = Some([e.rotation.angle().to_degrees(), e.translation.vector.norm()]);
                distribute(&mut poses, &e);
            }
        }
    }
    Ok(Chain {
        poses,
        skipped,
        loop_closure,
    })
}

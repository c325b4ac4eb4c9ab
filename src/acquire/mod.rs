//! Acquisition: merges turntable range views into one complete cloud.
//!
//! ```text
//! no axis given: axis from the first neighbouring pair register() aligns
//! nominal start poses (rotation by -angle about the table axis through the centre)
//!   ─ each view placed by robust point-to-plane ICP onto the union of the placed views that
//!     overlap it (the growing model), from the pose its nearest placed view predicts, then
//!     from the nominal pose, then from register()'s FPFH+MAC; a match whose rotation against
//!     the nominal pose exceeds the angle tolerance is rejected; none within it: the view is
//!     held at its predicted pose refined by a short-range ICP (reported)
//!   ─ full turn: ICP last -> first measures the loop closure (reported)
//!   ─ global step: joint point-to-plane ICP over every overlapping pair (multi-view ICP)
//!   ─ axis and centre estimated from the refined poses
//!   ─ views into the first view's frame, voxel thinning, optional SOR, normals
//! ```
mod axis;
mod config;
mod global;
mod pair;
mod place;
mod setups;

use std::time::Instant;

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::cloud::transform::{isometry_to_rows, pose_difference};
use crate::cloud::PointCloud;
use crate::preprocess::{
    check_voxel, estimate_normals, mean_spacing, statistical_outlier_filter, voxel_downsample,
    NormalConfig, Orientation, SorConfig,
};
pub use axis::{estimate_axis, AxisEstimate};
pub use config::{MergeConfig, DEFAULT_ANGLE_TOLERANCE};
pub use global::GlobalRefinement;
pub use place::{Placement, Rejected};
pub use setups::{merge_setups, MergedSetups, SetupJoin, SetupViews};

/// One view's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct ViewPose {
    /// The view's name (file).
    pub name: String,
    /// Nominal angle, degrees.
    pub nominal_deg: f64,
    /// Estimated table angle (about the estimated axis), degrees.
    pub angle_deg: f64,
    /// Refined view-to-first pose, 4x4 rows.
    pub view_to_first: [[f64; 4]; 4],
    /// Correction against the nominal start pose: rotation (deg) and translation (mm).
    pub correction_deg: f64,
    /// Translation part of the correction, mm.
    pub correction_mm: f64,
    /// Fitness of its placement onto the model (1 for the first view).
    pub fitness: f64,
    /// True when coarse registration gave the accepted start.
    pub coarse: bool,
    /// How the pose was found.
    pub placement: Placement,
    /// The views it was placed against (the overlapping part of the growing model).
    pub model: Vec<String>,
    /// Matches rejected because their correction exceeds the angle tolerance.
    pub rejected: Vec<Rejected>,
    /// RMS point-to-plane residual onto its partners after the global step, mm (None: no
    /// global step or no partner).
    pub residual_mm: Option<f64>,
    /// Its matched points in the global step.
    pub residual_points: usize,
    /// The views it was paired with in the global step.
    pub partners: Vec<String>,
    /// The refined pose (not serialised).
    #[serde(skip)]
    pub pose: Isometry3<f64>,
}

/// The result of [`merge_views`].
#[derive(Debug, Clone, Serialize)]
pub struct Merged {
    /// The joined cloud in the first view's frame (not serialised).
    #[serde(skip)]
    pub cloud: PointCloud,
    /// Aligned views, in input order.
    pub views: Vec<ViewPose>,
    /// Views skipped because they could not be aligned (`skip_bad`).
    pub skipped: Vec<String>,
    /// Loop-closure error before the global step (rotation deg, translation mm); None when
    /// the views do not make a full turn, the last view was skipped, or the direct match does
    /// not fit or is half a step or more off (a wrong match, not drift).
    pub loop_closure: Option<[f64; 2]>,
    /// The global step (None when it did not run: `global` off or no overlapping pair).
    pub global: Option<GlobalRefinement>,
    /// The angle tolerance used, degrees.
    pub angle_tolerance: f64,
    /// Estimated table axis and centre (first view's frame); None with fewer than 2 views.
    pub axis: Option<AxisEstimate>,
    /// The start axis when none was given: estimated from one neighbouring pair.
    pub axis_seed: Option<AxisSeed>,
    /// Voxel of the joining, mm.
    pub voxel: f64,
    /// Points before thinning.
    pub joined_points: usize,
    /// Wall time of each step.
    pub times: MergeTimes,
}

/// Wall time of each step of [`merge_views`], seconds.
#[derive(Debug, Clone, Default, Serialize)]
pub struct MergeTimes {
    /// Preparing every view as an ICP target and source (thinning, normals, grid).
    pub prepare: f64,
    /// Seeding the table axis when none is given (0 otherwise).
    pub axis: f64,
    /// Placing the views one by one, with the pulls from the nominal poses computed ahead
    /// side by side (the loop closure's first pull among them).
    pub place: f64,
    /// Measuring the loop closure.
    pub loop_closure: f64,
    /// The global step's search for overlapping pairs.
    pub global_pairs: f64,
    /// The global step's joint solve.
    pub global_solve: f64,
    /// Joining, thinning, outlier filter and normals of the joined cloud.
    pub join: f64,
    /// All of [`merge_views`].
    pub total: f64,
}

/// Rotation by `deg` about the axis `axis` through `centre`.
pub fn table_rotation(axis: &Unit<Vector3<f64>>, centre: &Point3<f64>, deg: f64) -> Isometry3<f64> {
    let c = Translation3::from(centre.coords);
    c * Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_axis_angle(axis, deg.to_radians()),
    ) * c.inverse()
}

/// The table axis estimated from one neighbouring pair when none is given.
#[derive(Debug, Clone, Serialize)]
pub struct AxisSeed {
    /// The pair (moving view, fixed view) it came from.
    pub pair: [String; 2],
    /// Unit axis, signed so that the table turns by +angle about it.
    pub axis: [f64; 3],
    /// Its point at the height of the first view's centroid, mm.
    pub centre: [f64; 3],
    /// Measured turn of the pair, degrees (nominal step for comparison in `nominal_deg`).
    pub turn_deg: f64,
    /// Nominal step of the pair, degrees.
    pub nominal_deg: f64,
}

/// Estimates the table axis when none is given: the first neighbouring pair (view i onto view
/// i-1) that `register()` (FPFH + MAC + ICP) aligns gives a relative rotation; its rotation
/// axis, signed by the nominal step, is the axis, and its fixed line through the height of
/// the first view's centroid gives the centre.
fn seed_axis(
    views: &[PointCloud],
    prepared: &[pair::Prepared],
    names: &[String],
    angles: &[f64],
    centroid: &Point3<f64>,
    cfg: &MergeConfig,
) -> Result<AxisSeed> {
    for i in 1..views.len() {
        let step = angles[i] - angles[i - 1];
        let Some((rel, _)) = pair::coarse_pair(views, prepared, (i, i - 1), cfg) else {
            continue;
        };
        let turn = rel.rotation.angle();
        if step == 0.0 || turn < 1f64.to_radians() {
            continue;
        }
        // rel is the rotation by -step about the axis.
        let axis = Unit::new_normalize(-rel.rotation.scaled_axis() * step.signum());
        let Some(est) = estimate_axis(&[rel], &axis, centroid) else {
            continue;
        };
        return Ok(AxisSeed {
            pair: [names[i].clone(), names[i - 1].clone()],
            axis: axis.into_inner().into(),
            centre: est.centre,
            turn_deg: turn.to_degrees() * step.signum(),
            nominal_deg: step,
        });
    }
    bail!(
        "cannot estimate the table axis: no neighbouring pair of views registers with a turn \
         of more than 1 degree; give --axis or --calibration"
    )
}

/// The global step over the placed views that were not held (a held view keeps its pose and
/// is no one's partner): the refined poses of all placed views, the step's summary and each
/// view's residuals (None for held views, or all when the step did not run). Times its pair
/// search and its solve into `times`.
fn refine_globally(
    placed: &[place::Placed],
    prepared: &[pair::Prepared],
    cfg: &MergeConfig,
    times: &mut MergeTimes,
) -> (
    Vec<Isometry3<f64>>,
    Option<GlobalRefinement>,
    Vec<Option<global::ViewResidual>>,
) {
    let mut poses: Vec<Isometry3<f64>> = placed.iter().map(|p| p.pose).collect();
    let mut residuals = vec![None; placed.len()];
    let free: Vec<usize> = (0..placed.len())
        .filter(|&k| placed[k].placement != Placement::Held)
        .collect();
    if !cfg.global || free.len() < 2 {
        return (poses, None, residuals);
    }
    let views: Vec<&pair::Prepared> = free.iter().map(|&k| &prepared[placed[k].index]).collect();
    let mut free_poses: Vec<Isometry3<f64>> = free.iter().map(|&k| poses[k]).collect();
    let t = Instant::now();
    let edges = global::pairs(&views, &free_poses, cfg);
    times.global_pairs = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let refined = global::refine(&views, &mut free_poses, &edges, cfg);
    times.global_solve = t.elapsed().as_secs_f64();
    let Some((summary, per_view)) = refined else {
        return (poses, None, residuals);
    };
    for ((&k, pose), mut res) in free.iter().zip(free_poses).zip(per_view) {
        poses[k] = pose;
        // Partners as positions among all placed views.
        res.partners = res.partners.iter().map(|&f| free[f]).collect();
        residuals[k] = Some(res);
    }
    (poses, Some(summary), residuals)
}

/// Fewest points of a view: a match is judged by the share of the view's points within the
/// final distance of its partner, and a few points fit that well almost anywhere (issue 52: a
/// 10-point view matched at fitness 1.0 at a wrong pose and pulled the global RMS from 0.21
/// to 10.7 mm). 500 points of a part are a strip of its surface whose shape pins a pose; a
/// turntable range view has tens of thousands.
pub const MIN_VIEW_POINTS: usize = 500;

/// Refuses view lists whose lengths differ, an empty list and views of under
/// [`MIN_VIEW_POINTS`] points.
fn check_views(views: &[PointCloud], names: &[String], angles: &[f64]) -> Result<()> {
    if views.len() != angles.len() || views.len() != names.len() {
        bail!("{} views but {} angles", views.len(), angles.len());
    }
    if views.is_empty() {
        bail!("no views to merge");
    }
    for (v, n) in views.iter().zip(names) {
        if v.len() < MIN_VIEW_POINTS {
            bail!(
                "{n}: {} points: too few to match at a pose one can trust (a view needs at \
                 least {MIN_VIEW_POINTS})",
                v.len()
            );
        }
    }
    Ok(())
}

/// Merges `views` (with `names` for messages and nominal `angles` in degrees).
pub fn merge_views(
    views: &[PointCloud],
    names: &[String],
    angles: &[f64],
    cfg: &MergeConfig,
) -> Result<Merged> {
    check_views(views, names, angles)?;
    let start = Instant::now();
    let mut times = MergeTimes::default();
    // Views prepared side by side (each one's normals and grid leave cores idle); the first
    // failing view in input order is named.
    let prepared: Vec<Result<pair::Prepared>> = views
        .par_iter()
        .zip(names)
        .map(|(v, n)| pair::prepare(v, cfg).map_err(|e| anyhow::anyhow!("{n}: {e}")))
        .collect();
    let prepared: Vec<pair::Prepared> = prepared.into_iter().collect::<Result<_>>()?;
    times.prepare = start.elapsed().as_secs_f64();
    let t = Instant::now();
    let centroid = {
        let v = &views[0];
        Point3::from(v.points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / v.len() as f64)
    };
    let (axis, centre, axis_seed) = match cfg.axis {
        Some(a) => {
            let axis_v = Vector3::from(a);
            if axis_v.norm().is_nan() || axis_v.norm() <= 1e-12 {
                bail!("table axis {a:?} has no direction");
            }
            let centre = cfg.centre.map_or(centroid, Point3::from);
            (Unit::new_normalize(axis_v), centre, None)
        }
        None if views.len() < 2 => (Vector3::z_axis(), centroid, None),
        None => {
            let seed = seed_axis(views, &prepared, names, angles, &centroid, cfg)?;
            let centre = cfg.centre.map_or(Point3::from(seed.centre), Point3::from);
            (
                Unit::new_normalize(Vector3::from(seed.axis)),
                centre,
                Some(seed),
            )
        }
    };
    times.axis = t.elapsed().as_secs_f64();
    let nominal: Vec<Isometry3<f64>> = angles
        .iter()
        .map(|a| table_rotation(&axis, &centre, -(a - angles[0])))
        .collect();
    let mut inputs = place::Inputs {
        views,
        prepared: &prepared,
        names,
        angles,
        nominal: &nominal,
        axis: &axis,
        pulls: Vec::new(),
    };
    let t = Instant::now();
    inputs.pulls = place::nominal_pulls(&inputs, cfg);
    let placed = place::place_views(&inputs, cfg)?;
    times.place = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let loop_closure = place::loop_closure(&inputs, &placed.placed, cfg);
    times.loop_closure = t.elapsed().as_secs_f64();
    let (poses, global, residuals) = refine_globally(&placed.placed, &prepared, cfg, &mut times);
    let kept: Vec<usize> = placed.placed.iter().map(|p| p.index).collect();
    let axis_est = estimate_axis(&poses, &axis, &centre);
    let mut out_views = Vec::new();
    for ((p, pose), res) in placed.placed.iter().zip(&poses).zip(&residuals) {
        let i = p.index;
        let (dr, dt) = pose_difference(&nominal[i], pose);
        let angle = axis_est.as_ref().map_or(angles[i] - angles[0], |a| {
            a.angle_of(pose, angles[i] - angles[0])
        }) + angles[0];
        let name_of = |v: &[usize]| v.iter().map(|&k| names[k].clone()).collect::<Vec<_>>();
        out_views.push(ViewPose {
            name: names[i].clone(),
            nominal_deg: angles[i],
            angle_deg: angle,
            view_to_first: isometry_to_rows(pose),
            correction_deg: dr,
            correction_mm: dt,
            fitness: p.fitness,
            coarse: p.coarse,
            placement: p.placement,
            model: name_of(&p.model),
            rejected: p.rejected.clone(),
            residual_mm: res.as_ref().map(|r| r.rms_mm).filter(|r| r.is_finite()),
            residual_points: res.as_ref().map_or(0, |r| r.points),
            partners: res.as_ref().map_or(Vec::new(), |r| {
                name_of(&r.partners.iter().map(|&k| kept[k]).collect::<Vec<_>>())
            }),
            pose: *pose,
        });
    }
    let t = Instant::now();
    let (cloud, voxel, joined_points) = join(views, &kept, &poses, cfg)?;
    times.join = t.elapsed().as_secs_f64();
    times.total = start.elapsed().as_secs_f64();
    Ok(Merged {
        cloud,
        views: out_views,
        skipped: placed.skipped,
        loop_closure,
        global,
        angle_tolerance: cfg.angle_tolerance,
        axis: axis_est,
        axis_seed,
        voxel,
        joined_points,
        times,
    })
}

/// The views at `kept` (input indices) at their `poses` joined into one cloud, thinned on the
/// voxel (`cfg.voxel`, else the first view's mean spacing), optionally filtered, with normals:
/// the cloud, the voxel and the points before thinning.
fn join(
    views: &[PointCloud],
    kept: &[usize],
    poses: &[Isometry3<f64>],
    cfg: &MergeConfig,
) -> Result<(PointCloud, f64, usize)> {
    let voxel = cfg.voxel.unwrap_or_else(|| mean_spacing(&views[0]));
    let mut joined = Vec::new();
    for (i, pose) in kept.iter().zip(poses) {
        joined.extend(views[*i].points.iter().map(|p| pose * p));
    }
    let joined_points = joined.len();
    let joined = PointCloud::from_points(joined);
    if cfg.voxel.is_some() {
        check_voxel(&joined, voxel, "merge voxel (--voxel / voxel)")?;
    }
    let mut cloud = voxel_downsample(&joined, voxel);
    cloud.normals = None;
    cloud.fields.clear();
    if cfg.sor {
        let r = statistical_outlier_filter(&cloud, &SorConfig::default())
            .context("outlier filter of the joined cloud")?;
        cloud = cloud.select(&r.kept);
    }
    if cfg.normals {
        let ncfg = NormalConfig {
            orientation: Orientation::Outward,
            ..NormalConfig::default()
        };
        let est = estimate_normals(&cloud, &ncfg).context("normals of the joined cloud")?;
        cloud.normals = Some(est.normals);
    }
    Ok((cloud, voxel, joined_points))
}

//! Acquisition: merges turntable range views into one complete cloud.
//!
//! ```text
//! no axis given: axis from the first neighbouring pair register() aligns
//! nominal start poses (rotation by -angle about the table axis through the centre)
//!   ─ pairwise robust point-to-plane ICP view i -> view i-1 from the nominal relative pose
//!     (coarse-to-fine distances; register()'s FPFH+MAC when ICP does not fit)
//!   ─ full turn: ICP last -> first closes the loop; the closure error is spread along the chain
//!   ─ axis and centre estimated from the refined poses
//!   ─ views into the first view's frame, voxel thinning, optional SOR, normals
//! ```
mod axis;
mod chain;

use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::cloud::transform::{isometry_to_rows, pose_difference};
use crate::cloud::PointCloud;
use crate::preprocess::{
    check_voxel, estimate_normals, mean_spacing, statistical_outlier_filter, voxel_downsample,
    NormalConfig, Orientation, SorConfig,
};
pub use axis::{estimate_axis, AxisEstimate};

/// Settings of the merge stage (lengths in mm, angles in degrees).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MergeConfig {
    /// Table axis direction in the views' frame. The table turns the part by +angle about
    /// it, so view i's start pose is the rotation by -(angle_i - angle_0). Default none: the
    /// axis is estimated from the first neighbouring pair that registers.
    pub axis: Option<[f64; 3]>,
    /// A point on the table axis (default: the estimated axis' point at the height of the
    /// first view's centroid, or that centroid when the axis is given).
    pub centre: Option<[f64; 3]>,
    /// Most points of a moving view used by the pairwise ICP (evenly strided; default 10,000).
    pub icp_max_points: usize,
    /// Most points of a view used as the ICP target, with PCA normals (evenly strided;
    /// default 30,000).
    pub icp_target_points: usize,
    /// First ICP correspondence distance in multiples of the mean spacing mr (default 30).
    pub start_distance: f64,
    /// Final ICP correspondence distance and fitness distance, in mr (default 3).
    pub final_distance: f64,
    /// Iteration cap of each ICP stage (default 30).
    pub icp_max_iterations: usize,
    /// Least share of a view's points within the final distance of its neighbour for an
    /// alignment to count (default 0.3).
    pub min_fitness: f64,
    /// Skip a view that cannot be aligned instead of failing (default false).
    pub skip_bad: bool,
    /// Voxel of the joined cloud (default: the first view's mean spacing).
    pub voxel: Option<f64>,
    /// Statistical outlier filter on the joined cloud (default false).
    pub sor: bool,
    /// Estimate normals of the joined cloud (default true).
    pub normals: bool,
}

impl Default for MergeConfig {
    fn default() -> Self {
        MergeConfig {
            axis: None,
            centre: None,
            icp_max_points: 10_000,
            icp_target_points: 30_000,
            start_distance: 30.0,
            final_distance: 3.0,
            icp_max_iterations: 30,
            min_fitness: 0.3,
            skip_bad: false,
            voxel: None,
            sor: false,
            normals: true,
        }
    }
}

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
    /// Fitness of the pairwise alignment onto the previous view (1 for the first view).
    pub fitness: f64,
    /// True when ICP from the nominal pose did not fit and coarse alignment was used.
    pub coarse: bool,
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
    /// Loop-closure error before distribution (rotation deg, translation mm); None when the
    /// views do not make a full turn, the last view was skipped, or the direct match is half a
    /// step or more off the chain (a wrong match, not drift).
    pub loop_closure: Option<[f64; 2]>,
    /// Estimated table axis and centre (first view's frame); None with fewer than 2 views.
    pub axis: Option<AxisEstimate>,
    /// The start axis when none was given: estimated from one neighbouring pair.
    pub axis_seed: Option<AxisSeed>,
    /// Voxel of the joining, mm.
    pub voxel: f64,
    /// Points before thinning.
    pub joined_points: usize,
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
    prepared: &[chain::Prepared],
    names: &[String],
    angles: &[f64],
    centroid: &Point3<f64>,
    cfg: &MergeConfig,
) -> Result<AxisSeed> {
    for i in 1..views.len() {
        let step = angles[i] - angles[i - 1];
        let Some((rel, _)) = chain::coarse_pair(views, prepared, (i, i - 1), cfg) else {
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

/// Merges `views` (with `names` for messages and nominal `angles` in degrees).
pub fn merge_views(
    views: &[PointCloud],
    names: &[String],
    angles: &[f64],
    cfg: &MergeConfig,
) -> Result<Merged> {
    if views.len() != angles.len() || views.len() != names.len() {
        bail!("{} views but {} angles", views.len(), angles.len());
    }
    if views.is_empty() {
        bail!("no views to merge");
    }
    for (v, n) in views.iter().zip(names) {
        if v.len() < 10 {
            bail!("{n}: {} points; at least 10 are needed", v.len());
        }
    }
    let prepared: Vec<chain::Prepared> = views
        .iter()
        .zip(names)
        .map(|(v, n)| chain::prepare(v, cfg).map_err(|e| anyhow::anyhow!("{n}: {e}")))
        .collect::<Result<_>>()?;
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
    let nominal: Vec<Isometry3<f64>> = angles
        .iter()
        .map(|a| table_rotation(&axis, &centre, -(a - angles[0])))
        .collect();
    let chained = chain::align_chain(views, &prepared, names, angles, &nominal, cfg)?;
    let mut out_views = Vec::new();
    let kept: Vec<usize> = chained.poses.iter().map(|p| p.index).collect();
    let poses: Vec<Isometry3<f64>> = chained.poses.iter().map(|p| p.pose).collect();
    let axis_est = estimate_axis(&poses, &axis, &centre);
    for p in &chained.poses {
        let i = p.index;
        let (dr, dt) = pose_difference(&nominal[i], &p.pose);
        let angle = axis_est.as_ref().map_or(angles[i] - angles[0], |a| {
            a.angle_of(&p.pose, angles[i] - angles[0])
        }) + angles[0];
        out_views.push(ViewPose {
            name: names[i].clone(),
            nominal_deg: angles[i],
            angle_deg: angle,
            view_to_first: isometry_to_rows(&p.pose),
            correction_deg: dr,
            correction_mm: dt,
            fitness: p.fitness,
            coarse: p.coarse,
            pose: p.pose,
        });
    }
    let voxel = cfg.voxel.unwrap_or_else(|| mean_spacing(&views[0]));
    let mut joined = Vec::new();
    for (i, pose) in kept.iter().zip(&poses) {
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
    Ok(Merged {
        cloud,
        views: out_views,
        skipped: chained.skipped,
        loop_closure: chained.loop_closure,
        axis: axis_est,
        axis_seed,
        voxel,
        joined_points,
    })
}

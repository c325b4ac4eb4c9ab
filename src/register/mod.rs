//! Registration: brings a scan into the reference (CAD) frame.
//!
//! ```text
//! scan, reference ─ mean spacing mr ─ voxel grid (15 mr) ─ normals (radius 2 voxel)
//!   ─ FPFH (radius 5 voxel) ─ feature matches (mutual, capped)
//!   ─ MAC: compatibility graph, W ⊙ (W × W), maximal cliques, node-guided selection,
//!          weighted SVD per clique, MAE score, re-weighted refinement
//!   ─ best few hypotheses ranked by a short ICP (near-symmetric parts)
//!   ─ robust point-to-plane ICP on the full clouds           => scan_to_reference
//! ```
pub mod correspondences;
pub mod feature_search;
pub mod fpfh;
pub mod icp;
pub mod mac;

use crate::cloud::transform::isometry_to_rows;
use std::time::{Duration, Instant};

use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::cloud::PointCloud;
use crate::preprocess::{
    estimate_normals, mean_spacing_in, voxel_downsample, NormalConfig, Orientation,
};
use crate::spatial::Grid;
use icp::{IcpParams, IcpResult};
use mac::{MacParams, MacStats};

/// Default coarse voxel in units of the cloud resolution mr. 15 mr leaves about 6k / 7.6k
/// points of a 400k / 300k femoral case. Against 10 mr (the fine ICP on 40,000 points both
/// times), on the 20 synth cases of tests/register.rs: the final poses are as close to the
/// truth (worst 0.0014 deg / 0.0009 mm), the coarse ones stay well inside the fine ICP's
/// reach (worst 0.64 deg / 0.36 mm against 0.23 deg / 0.18 mm), and registration of the
/// 400k / 300k bench case takes 0.57-0.59 s instead of 0.70-0.71 s (FPFH 0.10 s instead of
/// 0.18 s). 5 mr took 1.6-2.2 s on an older machine where 10 mr took 1.0-1.4 s.
pub const VOXEL_SPACINGS: f64 = 15.0;

/// Settings of the registration stage. Lengths in mm; `None` lengths derive from the cloud
/// resolution `mr` (mean nearest-neighbour spacing, the larger of the two clouds').
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegisterConfig {
    /// Voxel size of the coarse stage (default [`VOXEL_SPACINGS`] mr).
    pub voxel: Option<f64>,
    /// Normal estimation radius on the voxel clouds (default 2 voxel), at most 30 neighbours.
    pub normal_radius: Option<f64>,
    /// FPFH radius (default 5 voxel), at most `feature_max_nn` neighbours.
    pub feature_radius: Option<f64>,
    /// Neighbour cap of the FPFH search (Open3D tutorial: 100).
    pub feature_max_nn: usize,
    /// Most scan points that get a descriptor (evenly strided over the voxel cloud; the
    /// reference is described everywhere; default 8,000).
    pub max_keypoints: usize,
    /// Keep only mutual nearest feature matches (default true).
    pub mutual: bool,
    /// Cap on correspondences, smallest feature distance first (default 3000).
    pub max_correspondences: usize,
    /// Compatibility scale d_cs (default 1 voxel).
    pub compat_sigma: Option<f64>,
    /// First-order graph cut on exp(-d²/(2 d_cs²)) (default 0.6, i.e. d ≤ 1.01 d_cs).
    pub compat_min_score: f64,
    /// Inlier threshold tau of the hypothesis score (default 1.5 voxel).
    pub inlier_threshold: Option<f64>,
    /// Smallest clique (default 3).
    pub min_clique: usize,
    /// Cap on maximal cliques enumerated (default 30,000; each start vertex gets at least
    /// an equal share, and no more than max(share, 64)). Against 100,000: the clique search
    /// of the bench case 0.10 s instead of 0.14 s; on tests/register.rs the same final poses,
    /// the worst coarse one 0.67 deg / 0.38 mm instead of 0.64 deg / 0.36 mm.
    pub max_cliques: usize,
    /// Time budget of the clique search in seconds (default 2).
    pub clique_time_budget: f64,
    /// Cliques kept after node-guided selection (default 200).
    pub top_k: usize,
    /// Distinct hypotheses ranked by a short ICP (default 5).
    pub rank_candidates: usize,
    /// Most scan points used by the fine ICP (evenly strided; default 40,000). Against
    /// 100,000, on the 20 synth cases of tests/register.rs: worst final error 0.0014 deg /
    /// 0.0009 mm instead of 0.0010 deg / 0.0008 mm, in half the time (bench case: 0.11 s
    /// instead of 0.21 s); `pose_std`, and so the registration error, grows as 1/√n (0.0005
    /// → 0.0007 mm there), still covering the actual error on every case.
    pub icp_max_points: usize,
    /// Fine ICP correspondence distance (default 2 voxel).
    pub icp_max_distance: Option<f64>,
    /// Fine ICP iteration cap (default 100).
    pub icp_max_iterations: usize,
    /// Fine ICP relative tolerance on fitness and inlier RMSE (default 1e-7).
    pub icp_relative_tolerance: f64,
    /// Fixed Geman–McClure scale of the fine ICP; default adaptive (3 × robust sigma).
    pub icp_kernel_scale: Option<f64>,
    /// Distance within which a scan point counts as fitting the reference in the reported
    /// fitness and inlier RMSE (default 3 x the reference's mean spacing).
    pub fitness_distance: Option<f64>,
    /// Below this final fitness the registration fails (default 0.2).
    pub min_fitness: f64,
    /// Below this many inlying correspondences the coarse stage fails (default 8).
    pub min_inliers: usize,
}

impl Default for RegisterConfig {
    fn default() -> Self {
        RegisterConfig {
            voxel: None,
            normal_radius: None,
            feature_radius: None,
            feature_max_nn: 100,
            max_keypoints: 8_000,
            mutual: true,
            max_correspondences: 3000,
            compat_sigma: None,
            compat_min_score: 0.6,
            inlier_threshold: None,
            min_clique: 3,
            max_cliques: 30_000,
            clique_time_budget: 2.0,
            top_k: 200,
            rank_candidates: 5,
            icp_max_points: 40_000,
            icp_max_distance: None,
            icp_max_iterations: 100,
            icp_relative_tolerance: 1e-7,
            icp_kernel_scale: None,
            fitness_distance: None,
            min_fitness: 0.2,
            min_inliers: 8,
        }
    }
}

/// A hypothesis ranked by the short ICP.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// MAE score of the MAC pose.
    pub score: f64,
    /// Inlying correspondences of the MAC pose.
    pub inliers: usize,
    /// Fitness after the short ICP on the voxel clouds (pairs within 1 voxel).
    pub icp_fitness: f64,
    /// Point-to-plane RMS after the short ICP (mm).
    pub icp_plane_rmse: f64,
}

/// Diagnostics of the coarse (feature + MAC) stage.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Coarse {
    /// Scan-to-reference pose of the chosen MAC hypothesis (before any ICP), 4x4 row-major.
    pub scan_to_reference: [[f64; 4]; 4],
    /// Cloud resolution mr (mm).
    pub resolution: f64,
    /// Voxel size (mm).
    pub voxel: f64,
    /// Normal radius (mm).
    pub normal_radius: f64,
    /// FPFH radius (mm).
    pub feature_radius: f64,
    /// Compatibility scale d_cs (mm).
    pub compat_sigma: f64,
    /// Inlier threshold tau (mm).
    pub inlier_threshold: f64,
    /// Down-sampled scan points.
    pub scan_points: usize,
    /// Scan points described by FPFH (keypoints).
    pub scan_keypoints: usize,
    /// Down-sampled reference points.
    pub reference_points: usize,
    /// Putative correspondences.
    pub correspondences: usize,
    /// Fraction of correspondences within tau under the chosen pose.
    pub inlier_ratio: f64,
    /// MAC counters and times.
    pub mac: MacStats,
    /// Ranked hypotheses, in MAC score order.
    pub candidates: Vec<Candidate>,
    /// Index of the chosen candidate.
    pub chosen: usize,
    /// MAE score of the chosen hypothesis.
    pub chosen_score: f64,
}

/// Seconds spent per step.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Times {
    /// Resolution, voxel grid and normals.
    pub prepare: f64,
    /// FPFH on both clouds.
    pub fpfh: f64,
    /// Feature matching.
    pub correspondences: f64,
    /// MAC (graphs, cliques, hypotheses).
    pub mac: f64,
    /// Short ICP ranking of hypotheses.
    pub ranking: f64,
    /// Fine ICP (including target normals).
    pub icp: f64,
    /// Everything.
    pub total: f64,
}

/// How many of the fine ICP's statistical `pose_std` make the registration error: the
/// covariance sees only the scatter of the residuals, not systematic error (the reference's
/// sampling, defects the robust kernel only partly ignores). On the 20 synth cases of
/// tests/register.rs the largest actual displacement along the normal was 0.7-3.0 (median
/// 2.0) × `pose_std`.
pub const POSE_STD_FACTOR: f64 = 2.0;

/// The result of [`register`]: what `registration.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct Registration {
    /// Maps scan points into the reference frame: 4x4 row-major.
    pub scan_to_reference: [[f64; 4]; 4],
    /// Final fitness: fraction of the scan points used by the fine ICP that have a reference
    /// point within `fitness_distance`.
    pub fitness: f64,
    /// RMS point-to-point distance of those pairs (mm).
    pub inlier_rmse: f64,
    /// Distance of the fitness test (mm).
    pub fitness_distance: f64,
    /// Registration error for the comparison's level of detection (mm, 1 σ):
    /// [`POSE_STD_FACTOR`] × the fine ICP's `pose_std`; when that is undetermined the
    /// point-to-plane RMSE (conservative: it holds the scan noise too); NaN when registration
    /// failed before the fine stage.
    pub registration_error: f64,
    /// Coarse stage diagnostics.
    pub coarse: Coarse,
    /// Fine ICP diagnostics.
    pub fine: Option<IcpResult>,
    /// Fine ICP correspondence distance (mm).
    pub fine_max_distance: f64,
    /// Scan points used by the fine ICP.
    pub fine_points: usize,
    /// Times per step.
    pub times: Times,
    /// The pose as an isometry (not serialised: `scan_to_reference` carries it).
    #[serde(skip)]
    pub pose: Isometry3<f64>,
}

/// Why registration did not produce a pose.
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// An input cannot be registered (too few points, no normals possible...).
    #[error("registration input: {0}")]
    Input(String),
    /// No pose scored above the thresholds; the diagnostics say how far it got.
    #[error("registration failed: {reason}")]
    Failed {
        /// What fell short.
        reason: String,
        /// Everything computed up to the failure.
        diagnostics: Box<Registration>,
    },
}

/// Registers `scan` onto `reference`: see the module documentation.
pub fn register(
    scan: &PointCloud,
    reference: &PointCloud,
    cfg: &RegisterConfig,
) -> Result<Registration, RegisterError> {
    register_with_progress(scan, reference, cfg, &|_| {})
}

/// Number of steps reported through the progress callback.
pub const PROGRESS_STEPS: u64 = 6;

/// [`register`], calling `progress(step name)` as each of [`PROGRESS_STEPS`] steps starts.
pub fn register_with_progress(
    scan: &PointCloud,
    reference: &PointCloud,
    cfg: &RegisterConfig,
    progress: &dyn Fn(&str),
) -> Result<Registration, RegisterError> {
    let start = Instant::now();
    for (name, c) in [("scan", scan), ("reference", reference)] {
        if c.len() < 10 {
            return Err(RegisterError::Input(format!(
                "{name} has {} points; at least 10 are needed",
                c.len()
            )));
        }
    }
    let mut times = Times::default();
    let mut coarse = Coarse::default();

    progress("down-sampling and normals");
    let t = Instant::now();
    // The reference's grid serves its resolution here and the fine ICP's searches.
    let (ref_index, scan_index) = rayon::join(
        || Grid::for_points(&reference.points),
        || Grid::for_points(&scan.points),
    );
    let mr_ref = mean_spacing_in(&ref_index, &reference.points);
    let mr = mean_spacing_in(&scan_index, &scan.points).max(mr_ref);
    drop(scan_index);
    let voxel = cfg.voxel.unwrap_or(VOXEL_SPACINGS * mr);
    if voxel.is_nan() || voxel <= 0.0 {
        return Err(RegisterError::Input(
            "cloud resolution is zero (all points coincide)".into(),
        ));
    }
    let normal_radius = cfg.normal_radius.unwrap_or(2.0 * voxel);
    let feature_radius = cfg.feature_radius.unwrap_or(5.0 * voxel);
    let use_input_normals = scan.normals.is_some() && reference.normals.is_some();
    let down = |c: &PointCloud| -> Result<PointCloud, RegisterError> {
        let d = voxel_downsample(c, voxel);
        let normals = match d.normals {
            Some(n) if use_input_normals => n,
            _ => {
                let ncfg = NormalConfig {
                    k: 30,
                    radius: Some(normal_radius),
                    orientation: Orientation::Outward,
                    ..NormalConfig::default()
                };
                estimate_normals(&PointCloud::from_points(d.points.clone()), &ncfg)
                    .map_err(|e| RegisterError::Input(e.to_string()))?
                    .normals
            }
        };
        Ok(PointCloud {
            normals: Some(normals),
            ..d
        })
    };
    let (s_down, r_down) = rayon::join(|| down(scan), || down(reference));
    let (s_down, r_down) = (s_down?, r_down?);
    let (s_pts, r_pts) = (s_down.points, r_down.points);
    let s_nrm = s_down.normals.unwrap_or_default();
    let r_nrm = r_down.normals.unwrap_or_default();
    let r_index = Grid::for_points(&r_pts);
    coarse.resolution = mr;
    coarse.voxel = voxel;
    coarse.normal_radius = normal_radius;
    coarse.feature_radius = feature_radius;
    coarse.scan_points = s_pts.len();
    coarse.reference_points = r_pts.len();
    times.prepare = t.elapsed().as_secs_f64();

    progress("FPFH features");
    let t = Instant::now();
    let stride = s_pts.len().div_ceil(cfg.max_keypoints.max(1));
    let keypoints: Vec<usize> = (0..s_pts.len()).step_by(stride).collect();
    coarse.scan_keypoints = keypoints.len();
    let (s_f, r_f) = rayon::join(
        || {
            fpfh::compute_fpfh_at(
                &s_pts,
                &s_nrm,
                feature_radius,
                cfg.feature_max_nn,
                &keypoints,
            )
        },
        || fpfh::compute_fpfh(&r_pts, &r_nrm, feature_radius, cfg.feature_max_nn),
    );
    times.fpfh = t.elapsed().as_secs_f64();

    progress("feature matching");
    let t = Instant::now();
    let corr = correspondences::match_features(&s_f, &r_f, cfg.mutual, cfg.max_correspondences);
    coarse.correspondences = corr.len();
    let src: Vec<Point3<f64>> = corr.iter().map(|c| s_pts[keypoints[c.scan]]).collect();
    let dst: Vec<Point3<f64>> = corr.iter().map(|c| r_pts[c.reference]).collect();
    times.correspondences = t.elapsed().as_secs_f64();

    progress("MAC coarse alignment");
    let t = Instant::now();
    let params = MacParams {
        compat_sigma: cfg.compat_sigma.unwrap_or(voxel),
        compat_min_score: cfg.compat_min_score,
        inlier_threshold: cfg.inlier_threshold.unwrap_or(1.5 * voxel),
        min_clique: cfg.min_clique,
        max_cliques: cfg.max_cliques,
        time_budget: Duration::from_secs_f64(cfg.clique_time_budget),
        top_k: cfg.top_k,
        max_graph_work: 30_000_000,
        hypotheses_out: cfg.rank_candidates.max(1),
    };
    coarse.compat_sigma = params.compat_sigma;
    coarse.inlier_threshold = params.inlier_threshold;
    let (hyps, stats) = mac::mac(&src, &dst, &params);
    coarse.mac = stats;
    times.mac = t.elapsed().as_secs_f64();

    progress("ranking hypotheses");
    let t = Instant::now();
    let short = IcpParams {
        max_distance: voxel,
        max_iterations: 30,
        relative_tolerance: 1e-6,
        kernel_scale: Some(0.5 * voxel),
        min_kernel_scale: 0.0,
    };
    let ranked: Vec<IcpResult> = hyps
        .iter()
        .map(|h| icp::icp(&s_pts, &r_pts, &r_nrm, &r_index, &h.pose, &short))
        .collect();
    coarse.candidates = hyps
        .iter()
        .zip(&ranked)
        .map(|(h, r)| Candidate {
            score: h.score,
            inliers: h.inliers,
            icp_fitness: r.fitness,
            icp_plane_rmse: r.plane_rmse,
        })
        .collect();
    let chosen = (0..ranked.len()).max_by(|&a, &b| {
        let (ra, rb) = (&ranked[a], &ranked[b]);
        let close = (ra.fitness - rb.fitness).abs() < 0.01 * ra.fitness.max(rb.fitness);
        if close {
            rb.plane_rmse.total_cmp(&ra.plane_rmse)
        } else {
            ra.fitness.total_cmp(&rb.fitness)
        }
    });
    times.ranking = t.elapsed().as_secs_f64();

    let fine_max_distance = cfg.icp_max_distance.unwrap_or(2.0 * voxel);
    let mut out = Registration {
        scan_to_reference: isometry_to_rows(&Isometry3::identity()),
        fitness: 0.0,
        inlier_rmse: 0.0,
        registration_error: f64::NAN,
        fitness_distance: cfg.fitness_distance.unwrap_or(3.0 * mr_ref),
        coarse,
        fine: None,
        fine_max_distance,
        fine_points: 0,
        times,
        pose: Isometry3::identity(),
    };
    let fail = |mut out: Registration, reason: String| {
        out.times.total = start.elapsed().as_secs_f64();
        Err(RegisterError::Failed {
            reason,
            diagnostics: Box::new(out),
        })
    };
    let Some(chosen) = chosen else {
        return fail(
            out,
            "no pose hypothesis (no consistent correspondences)".into(),
        );
    };
    let h = hyps[chosen];
    out.coarse.chosen = chosen;
    out.coarse.chosen_score = h.score;
    out.coarse.inlier_ratio = h.inliers as f64 / corr.len().max(1) as f64;
    out.coarse.scan_to_reference = isometry_to_rows(&h.pose);
    if h.inliers < cfg.min_inliers {
        return fail(
            out,
            format!(
                "best hypothesis has {} inlying correspondences (at least {} needed)",
                h.inliers, cfg.min_inliers
            ),
        );
    }

    progress("fine ICP");
    let t = Instant::now();
    let stride = scan.len().div_ceil(cfg.icp_max_points.max(1));
    let src_fine: Vec<Point3<f64>> = scan.points.iter().step_by(stride).copied().collect();
    let ref_normals: Vec<Vector3<f64>> = match &reference.normals {
        Some(n) => n.clone(),
        None => {
            let ncfg = NormalConfig {
                orientation: Orientation::Unoriented,
                ..NormalConfig::default()
            };
            estimate_normals(&PointCloud::from_points(reference.points.clone()), &ncfg)
                .map_err(|e| RegisterError::Input(e.to_string()))?
                .normals
        }
    };
    let fine = icp::icp(
        &src_fine,
        &reference.points,
        &ref_normals,
        &ref_index,
        &ranked[chosen].pose,
        &IcpParams {
            max_distance: fine_max_distance,
            max_iterations: cfg.icp_max_iterations,
            relative_tolerance: cfg.icp_relative_tolerance,
            kernel_scale: cfg.icp_kernel_scale,
            min_kernel_scale: 1e-3 * mr,
        },
    );
    out.times.icp = t.elapsed().as_secs_f64();
    out.fine_points = src_fine.len();
    out.fine = Some(fine);
    (out.fitness, out.inlier_rmse) =
        icp::fitness(&src_fine, &ref_index, &fine.pose, out.fitness_distance);
    out.registration_error = if fine.pose_std.is_finite() {
        POSE_STD_FACTOR * fine.pose_std
    } else {
        fine.plane_rmse
    };
    out.pose = fine.pose;
    out.scan_to_reference = isometry_to_rows(&fine.pose);
    out.times.total = start.elapsed().as_secs_f64();
    if out.fitness < cfg.min_fitness {
        let reason = format!(
            "final fitness {:.3} (scan points within {:.3} mm of the reference) is below {:.3}",
            out.fitness, out.fitness_distance, cfg.min_fitness
        );
        return fail(out, reason);
    }
    Ok(out)
}

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

mod config;
pub use config::{RegisterConfig, VOXEL_SPACINGS};

use crate::cloud::transform::isometry_to_rows;
use std::time::{Duration, Instant};

use nalgebra::{Isometry3, Point3, Vector3};
use serde::Serialize;

use crate::cloud::PointCloud;
use crate::preprocess::{
    estimate_normals, mean_spacing_in, voxel_downsample, NormalConfig, Orientation,
};
use crate::spatial::Grid;
use icp::{IcpParams, IcpResult};
use mac::{MacParams, MacStats};

/// A hypothesis ranked by the short ICP.
#[derive(Debug, Clone, Serialize)]
pub struct PoseCandidate {
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
    pub candidates: Vec<PoseCandidate>,
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

/// [`register`], calling `progress(step name)` as each of [`PROGRESS_STEPS`] steps starts:
/// down-sampling and normals -> FPFH -> correspondences -> MAC -> ranking -> fine ICP.
pub fn register_with_progress(
    scan: &PointCloud,
    reference: &PointCloud,
    cfg: &RegisterConfig,
    progress: &dyn Fn(&str),
) -> Result<Registration, RegisterError> {
    let start = Instant::now();
    cfg.check()
        .map_err(|m| RegisterError::Input(format!("[register] {m}")))?;
    check_sizes(scan, reference)?;
    let mut times = Times::default();
    progress("down-sampling and normals");
    let t = Instant::now();
    let prep = prepare(scan, reference, cfg)?;
    times.prepare = t.elapsed().as_secs_f64();

    progress("FPFH features");
    let t = Instant::now();
    let features = describe(&prep, cfg);
    times.fpfh = t.elapsed().as_secs_f64();

    progress("feature matching");
    let t = Instant::now();
    let pairs = match_pairs(&prep, &features, cfg);
    times.correspondences = t.elapsed().as_secs_f64();

    progress("MAC coarse alignment");
    let t = Instant::now();
    let (hyps, mut coarse) = coarse_hypotheses(&prep, &pairs, cfg);
    coarse.scan_keypoints = features.keypoints.len();
    times.mac = t.elapsed().as_secs_f64();

    progress("ranking hypotheses");
    let t = Instant::now();
    let ranked = rank_hypotheses(&prep, &hyps, &mut coarse);
    times.ranking = t.elapsed().as_secs_f64();

    let mut out = Registration {
        scan_to_reference: isometry_to_rows(&Isometry3::identity()),
        fitness: 0.0,
        inlier_rmse: 0.0,
        registration_error: f64::NAN,
        fitness_distance: cfg.fitness_distance.unwrap_or(3.0 * prep.mr_ref),
        coarse,
        fine: None,
        fine_max_distance: cfg.icp_max_distance.unwrap_or(2.0 * prep.voxel),
        fine_points: 0,
        times,
        pose: Isometry3::identity(),
    };
    let start_pose = match choose(&ranked, &hyps, pairs.count, cfg, &mut out) {
        Ok(pose) => pose,
        Err(reason) => return fail(out, reason, start),
    };

    progress("fine ICP");
    let t = Instant::now();
    fine_icp(scan, reference, &prep, &start_pose, cfg, &mut out)?;
    out.times.icp = t.elapsed().as_secs_f64();
    out.times.total = start.elapsed().as_secs_f64();
    if out.fitness < cfg.min_fitness {
        let reason = format!(
            "final fitness {:.3} (scan points within {:.3} mm of the reference) is below {:.3}",
            out.fitness, out.fitness_distance, cfg.min_fitness
        );
        return fail(out, reason, start);
    }
    Ok(out)
}

/// Fewest points of either cloud that registration takes.
const MIN_POINTS: usize = 10;

/// Refuses a cloud with fewer than [`MIN_POINTS`] points.
fn check_sizes(scan: &PointCloud, reference: &PointCloud) -> Result<(), RegisterError> {
    for (name, c) in [("scan", scan), ("reference", reference)] {
        if c.len() < MIN_POINTS {
            return Err(RegisterError::Input(format!(
                "{name} has {} points; at least {MIN_POINTS} are needed",
                c.len()
            )));
        }
    }
    Ok(())
}

/// The failure `reason`, with everything computed so far as its diagnostics.
fn fail(
    mut out: Registration,
    reason: String,
    start: Instant,
) -> Result<Registration, RegisterError> {
    out.times.total = start.elapsed().as_secs_f64();
    Err(RegisterError::Failed {
        reason,
        diagnostics: Box::new(out),
    })
}

/// Points of a voxel cloud and their normals.
type VoxelCloud = (Vec<Point3<f64>>, Vec<Vector3<f64>>);

/// Both clouds down-sampled on the coarse voxel grid with normals, and the lengths derived
/// from the cloud resolution.
struct Prepared {
    /// Cloud resolution mr: the larger mean spacing of the two clouds (mm).
    mr: f64,
    /// The reference's own mean spacing (mm).
    mr_ref: f64,
    /// Coarse voxel edge (mm).
    voxel: f64,
    /// Normal estimation radius on the voxel clouds (mm).
    normal_radius: f64,
    /// FPFH radius (mm).
    feature_radius: f64,
    /// Voxel scan points and normals.
    scan: VoxelCloud,
    /// Voxel reference points and normals.
    reference: VoxelCloud,
    /// Index of the voxel reference (the ranking ICP's searches).
    reference_voxel_index: Grid,
    /// Index of the full reference (its resolution here, the fine ICP's searches).
    reference_index: Grid,
}

/// Cloud resolution, voxel grid and normals (the step "down-sampling and normals").
fn prepare(
    scan: &PointCloud,
    reference: &PointCloud,
    cfg: &RegisterConfig,
) -> Result<Prepared, RegisterError> {
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
    let down = |c: &PointCloud| voxel_with_normals(c, voxel, normal_radius, use_input_normals);
    let (s_down, r_down) = rayon::join(|| down(scan), || down(reference));
    let (s_down, r_down) = (s_down?, r_down?);
    Ok(Prepared {
        mr,
        mr_ref,
        voxel,
        normal_radius,
        feature_radius,
        reference_voxel_index: Grid::for_points(&r_down.0),
        scan: s_down,
        reference: r_down,
        reference_index: ref_index,
    })
}

/// Neighbours of the normal estimate on the voxel clouds (within the normal radius).
const VOXEL_NORMAL_K: usize = 30;

/// `c` down-sampled on voxels of edge `voxel`, with its own normals (when `keep_normals`) or
/// normals estimated within `radius`, oriented outward.
fn voxel_with_normals(
    c: &PointCloud,
    voxel: f64,
    radius: f64,
    keep_normals: bool,
) -> Result<VoxelCloud, RegisterError> {
    let d = voxel_downsample(c, voxel);
    let normals = match d.normals {
        Some(n) if keep_normals => n,
        _ => {
            let ncfg = NormalConfig {
                k: VOXEL_NORMAL_K,
                radius: Some(radius),
                orientation: Orientation::Outward,
                ..NormalConfig::default()
            };
            estimate_normals(&PointCloud::from_points(d.points.clone()), &ncfg)
                .map_err(|e| RegisterError::Input(e.to_string()))?
                .normals
        }
    };
    Ok((d.points, normals))
}

/// FPFH descriptors: of evenly strided scan keypoints and of every voxel reference point.
struct Features {
    /// Indices of the described voxel scan points.
    keypoints: Vec<usize>,
    /// Their descriptors.
    scan: Vec<fpfh::Fpfh>,
    /// The voxel reference's descriptors.
    reference: Vec<fpfh::Fpfh>,
}

/// FPFH on both voxel clouds (the step "FPFH features").
fn describe(prep: &Prepared, cfg: &RegisterConfig) -> Features {
    let ((s_pts, s_nrm), (r_pts, r_nrm)) = (&prep.scan, &prep.reference);
    let stride = s_pts.len().div_ceil(cfg.max_keypoints.max(1));
    let keypoints: Vec<usize> = (0..s_pts.len()).step_by(stride).collect();
    let (radius, max_nn) = (prep.feature_radius, cfg.feature_max_nn);
    let (scan, reference) = rayon::join(
        || fpfh::compute_fpfh_at(s_pts, s_nrm, radius, max_nn, &keypoints),
        || fpfh::compute_fpfh(r_pts, r_nrm, radius, max_nn),
    );
    Features {
        keypoints,
        scan,
        reference,
    }
}

/// Putative point pairs of the feature matches.
struct Pairs {
    /// Matches found.
    count: usize,
    /// Their scan points.
    src: Vec<Point3<f64>>,
    /// Their reference points.
    dst: Vec<Point3<f64>>,
}

/// Feature matching (the step "feature matching").
fn match_pairs(prep: &Prepared, f: &Features, cfg: &RegisterConfig) -> Pairs {
    let corr =
        correspondences::match_features(&f.scan, &f.reference, cfg.mutual, cfg.max_correspondences);
    Pairs {
        count: corr.len(),
        src: corr
            .iter()
            .map(|c| prep.scan.0[f.keypoints[c.scan]])
            .collect(),
        dst: corr.iter().map(|c| prep.reference.0[c.reference]).collect(),
    }
}

/// Cap on the compatibility graph's work (pair evaluations) in MAC.
const MAX_GRAPH_WORK: u64 = 30_000_000;

/// MAC hypotheses from the pairs, and the coarse diagnostics so far (the step "MAC coarse
/// alignment").
fn coarse_hypotheses(
    prep: &Prepared,
    pairs: &Pairs,
    cfg: &RegisterConfig,
) -> (Vec<mac::Hypothesis>, Coarse) {
    let params = MacParams {
        compat_sigma: cfg.compat_sigma.unwrap_or(prep.voxel),
        compat_min_score: cfg.compat_min_score,
        inlier_threshold: cfg.inlier_threshold.unwrap_or(1.5 * prep.voxel),
        min_clique: cfg.min_clique,
        max_cliques: cfg.max_cliques,
        time_budget: Duration::from_secs_f64(cfg.clique_time_budget),
        top_k: cfg.top_k,
        max_graph_work: MAX_GRAPH_WORK,
        hypotheses_out: cfg.rank_candidates.max(1),
    };
    let (hyps, stats) = mac::mac(&pairs.src, &pairs.dst, &params);
    let coarse = Coarse {
        resolution: prep.mr,
        voxel: prep.voxel,
        normal_radius: prep.normal_radius,
        feature_radius: prep.feature_radius,
        compat_sigma: params.compat_sigma,
        inlier_threshold: params.inlier_threshold,
        scan_points: prep.scan.0.len(),
        reference_points: prep.reference.0.len(),
        correspondences: pairs.count,
        mac: stats,
        ..Coarse::default()
    };
    (hyps, coarse)
}

/// Each hypothesis refined by a short ICP on the voxel clouds, recorded in `coarse.candidates`
/// (the step "ranking hypotheses").
fn rank_hypotheses(
    prep: &Prepared,
    hyps: &[mac::Hypothesis],
    coarse: &mut Coarse,
) -> Vec<IcpResult> {
    let short = IcpParams {
        max_distance: prep.voxel,
        max_iterations: 30,
        relative_tolerance: 1e-6,
        kernel_scale: Some(0.5 * prep.voxel),
        min_kernel_scale: 0.0,
    };
    let (s_pts, (r_pts, r_nrm)) = (&prep.scan.0, &prep.reference);
    let ranked: Vec<IcpResult> = hyps
        .iter()
        .map(|h| {
            icp::icp(
                s_pts,
                r_pts,
                r_nrm,
                &prep.reference_voxel_index,
                &h.pose,
                &short,
            )
        })
        .collect();
    coarse.candidates = hyps
        .iter()
        .zip(&ranked)
        .map(|(h, r)| PoseCandidate {
            score: h.score,
            inliers: h.inliers,
            icp_fitness: r.fitness,
            icp_plane_rmse: r.plane_rmse,
        })
        .collect();
    ranked
}

/// The best ranked hypothesis (highest short-ICP fitness; within 1 % of it, the lowest
/// point-to-plane RMS) recorded in `out.coarse`; its short-ICP pose starts the fine ICP. The
/// reason when there is none, or it has too few inliers.
fn choose(
    ranked: &[IcpResult],
    hyps: &[mac::Hypothesis],
    correspondences: usize,
    cfg: &RegisterConfig,
    out: &mut Registration,
) -> Result<Isometry3<f64>, String> {
    let chosen = (0..ranked.len()).max_by(|&a, &b| {
        let (ra, rb) = (&ranked[a], &ranked[b]);
        let close = (ra.fitness - rb.fitness).abs() < 0.01 * ra.fitness.max(rb.fitness);
        if close {
            rb.plane_rmse.total_cmp(&ra.plane_rmse)
        } else {
            ra.fitness.total_cmp(&rb.fitness)
        }
    });
    let Some(chosen) = chosen else {
        return Err("no pose hypothesis (no consistent correspondences)".into());
    };
    let h = hyps[chosen];
    out.coarse.chosen = chosen;
    out.coarse.chosen_score = h.score;
    out.coarse.inlier_ratio = h.inliers as f64 / correspondences.max(1) as f64;
    out.coarse.scan_to_reference = isometry_to_rows(&h.pose);
    if h.inliers < cfg.min_inliers {
        return Err(format!(
            "best hypothesis has {} inlying correspondences (at least {} needed)",
            h.inliers, cfg.min_inliers
        ));
    }
    Ok(ranked[chosen].pose)
}

/// Robust point-to-plane ICP of a strided sample of the full scan onto the full reference
/// from `start`, with the fitness, the registration error and the pose written into `out`
/// (the step "fine ICP").
fn fine_icp(
    scan: &PointCloud,
    reference: &PointCloud,
    prep: &Prepared,
    start: &Isometry3<f64>,
    cfg: &RegisterConfig,
    out: &mut Registration,
) -> Result<(), RegisterError> {
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
        &prep.reference_index,
        start,
        &IcpParams {
            max_distance: out.fine_max_distance,
            max_iterations: cfg.icp_max_iterations,
            relative_tolerance: cfg.icp_relative_tolerance,
            kernel_scale: cfg.icp_kernel_scale,
            min_kernel_scale: 1e-3 * prep.mr,
        },
    );
    out.fine_points = src_fine.len();
    out.fine = Some(fine);
    (out.fitness, out.inlier_rmse) = icp::fitness(
        &src_fine,
        &prep.reference_index,
        &fine.pose,
        out.fitness_distance,
    );
    out.registration_error = if fine.pose_std.is_finite() {
        POSE_STD_FACTOR * fine.pose_std
    } else {
        fine.plane_rmse
    };
    out.pose = fine.pose;
    out.scan_to_reference = isometry_to_rows(&fine.pose);
    Ok(())
}

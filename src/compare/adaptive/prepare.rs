//! Step 1, prepare: what every core point reads, computed once per cloud. Each scan point is
//! paired with a reference point ([`super::point_pair`]); each reference point gets δ, its
//! one-sided distance to the scan along its normal, and its RWME terms; the noise is
//! estimated from the δ; the core points get their spacing (the refine radius).
use anyhow::Result;
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::context::{Context, RefSlot, Thresholds};
use super::point_pair::{each_nearest, Pairing};
use super::quadric::MAD_TO_SD;
use crate::cloud::PointCloud;
use crate::compare::clouds::{surface_density, Clouds};
use crate::compare::config::CompareConfig;
use crate::compare::core::area_share;
use crate::compare::cover::cover_radius2;
use crate::spatial::Neighbours;

/// δ_i looks among this many nearest scan points of a reference point. 3 instead of 4 (until
/// 2026-12-01): every IoU, peak and false-region count of seeds 11-82 at 300k and 11-58 at
/// 1.2M identical, RMS within 0.0001 mm but one (0.0030 → 0.0025 mm), and the adaptive
/// comparison at 20k core points 0.397 → 0.361 s; 8 gave the same accuracy-test results at
/// a third more search time.
const DELTA_NEIGHBOURS: usize = 3;

/// Cylinders' reach is padded by this relative margin so that rounding never drops a scan
/// point on its boundary.
const REACH_MARGIN: f64 = 1e-9;

/// The refine radius is this many core-point spacings: it holds a core point's Voronoi cell
/// on the reference.
const REFINE_SPACINGS: f64 = 2.0;

/// The noise estimate reads up to this many evenly spread δ (the median of more moves by
/// less than the noise's own scatter).
const NOISE_SAMPLES: usize = 20_000;

/// The tail of |δ| that checks the noise for a mixture: its 90th percentile ...
const TAIL_QUANTILE: f64 = 0.9;

/// ... is this many standard deviations for Gaussian noise (Φ⁻¹(0.95)).
const TAIL_Z: f64 = 1.644_853_626_951_472;

/// The tail's noise estimate beyond this many times the median's is a mixture of noise levels:
/// a merged turntable scan (each surface seen by 1-4 views, voxels averaging 1-4 points with
/// line-of-sight noise) has 1.37-1.44 (issue 36, seeds 1-5), a single scan with Gaussian noise
/// 1.00-1.02 (same seeds' full scans). The peak models' guards and the model fill then read
/// the tail's (their residual SD and χ² tests assume one noise level: with the median's they
/// rejected the models of most defects on merged scans, and cylinders read the flanks).
const MIXTURE_RATIO: f64 = 1.2;

/// The core-point spacing reads the area shares of up to this many evenly spread core points.
const SPACING_SAMPLES: usize = 1000;

/// Fewer core points than this have no spacing (0): an area share needs the point's
/// neighbours (`area_share`), and a median of a handful says little.
const MIN_SPACING_POINTS: usize = 9;

/// The context of the adaptive variant for the core points `core` (with normals) and the
/// candidate `radii` over `clouds` (in their grids' storage order).
pub(super) fn prepare<'a>(
    clouds: &'a Clouds<'a>,
    core: &'a PointCloud,
    radii: &[f64],
    cfg: &CompareConfig,
) -> Result<Context<'a>> {
    let a = &cfg.adaptive;
    let ref_normals = clouds.reference.normals.as_deref().ok_or_else(|| {
        anyhow::anyhow!("the adaptive method needs reference normals (give a mesh or normals)")
    })?;
    // A scan point inside a cylinder around a reference point is within `reach` of it.
    let r_max = *radii.last().expect("radii");
    let reach = r_max.hypot(cfg.max_distance.max(r_max)) * (1.0 + REACH_MARGIN);
    let cos_limit = a.max_normal_angle.to_radians().cos();
    let pairing = Pairing::new(clouds, ref_normals, cos_limit);
    // Per scan point: its reference point's normal and the pair distance.
    let nearest = pairing.pair_scan_points(reach);
    let cover2 = cover_radius2(clouds.scan_density);
    let (delta, covered): (Vec<f64>, Vec<bool>) =
        one_sided_distances(clouds, ref_normals, &nearest, cos_limit, reach, cover2)
            .into_iter()
            .unzip();
    let (noise, model_noise) = match a.noise {
        Some(s) => (s, s),
        None => noise_levels(&delta),
    };
    let ref_slots = clouds
        .ref_grid
        .slot_ids()
        .par_iter()
        .map(|&i| {
            let d = delta[i as usize].abs();
            let w = (-d / a.h).exp();
            RefSlot {
                normal: ref_normals[i as usize],
                terms: [w, w * d],
                covered: covered[i as usize],
            }
        })
        .collect();
    let scan_slots = match clouds.scan_grid.numbered_in_storage_order() {
        true => nearest,
        false => (clouds.scan_grid.slot_ids().par_iter())
            .map(|&j| nearest[j as usize])
            .collect(),
    };
    let core_index = Neighbours::new(&core.points);
    Ok(Context {
        clouds,
        ref_normals,
        ref_slots,
        scan_slots,
        pairing,
        radii: radii.to_vec(),
        radii2: radii.iter().map(|r| r * r).collect(),
        half_length: cfg.max_distance.max(radii[0]),
        refine_radius: REFINE_SPACINGS * spacing(&core_index, &core.points),
        core: &core.points,
        core_index,
        noise,
        model_noise,
        cos_limit,
        delta,
        limits: Thresholds {
            tolerance: cfg.tolerance,
            refine_above: cfg.refine_above(),
            densify_above: cfg.densify_above(),
        },
        min_peak_window: a.peak.min_window,
        scan_per_reference: clouds.scan_density / surface_density(&clouds.ref_grid),
    })
}

/// δ_i for every reference point: along its normal, to the scan point (of its 3 nearest
/// within `reach`, paired with a reference point whose normal is within the normal filter's
/// angle of its own: `nearest` per scan point, [`Pairing`]) closest to its normal line; NaN
/// when there is none (unscanned surface: left out of the similarity and of the noise
/// estimate). With it, whether any of those scan points (of any face) lies within `cover2`
/// (squared) of the point's normal line (`cover.rs`).
/// Beside a sharp edge the nearest scan points of a reference point are often the
/// other face's, 0.05-0.2 mm off its tangent plane, which would make a perfect match look
/// like a defect.
fn one_sided_distances(
    clouds: &Clouds,
    ref_normals: &[Vector3<f64>],
    nearest: &[Option<(Vector3<f64>, f64)>],
    cos_limit: f64,
    reach: f64,
    cover2: f64,
) -> Vec<(f64, bool)> {
    let scan = &clouds.scan.points;
    let (reference, scan_grid) = (&clouds.ref_grid, &clouds.scan_grid);
    let points = &clouds.reference.points;
    each_nearest(
        scan_grid,
        reference,
        points,
        DELTA_NEIGHBOURS,
        reach,
        |i, found| {
            let (x, n) = (&clouds.reference.points[i], &ref_normals[i]);
            let mut best = (f64::INFINITY, f64::NAN);
            for &(_, j) in found {
                let same_face =
                    nearest[j as usize].is_some_and(|(normal, _)| normal.dot(n) >= cos_limit);
                if !same_face {
                    continue;
                }
                let d = scan[j as usize] - x;
                let t = d.dot(n);
                let across = d.norm_squared() - t * t;
                if across < best.0 {
                    best = (across, t);
                }
            }
            // Covered across the normal only: under a defect taller than the cover radius the
            // scan lies that far off along the normal (dense scans: the 1.2M suite's RMS went
            // NaN with the 3-D distance).
            let covered = found.iter().any(|&(_, j)| {
                let d = scan[j as usize] - x;
                let t = d.dot(n);
                d.norm_squared() - t * t <= cover2
            });
            (best.1, covered)
        },
    )
}

/// The noise along the normal from up to 20,000 evenly spread δ: [σ, σ_models]. σ = 1.4826 ×
/// median |δ| (the noise when most of the part is in tolerance). σ_models = σ unless the
/// tail's estimate, the 90th percentile of |δ| / Φ⁻¹(0.95), exceeds [`MIXTURE_RATIO`] σ:
/// then the latter (δ is a mixture of noise levels).
fn noise_levels(delta: &[f64]) -> (f64, f64) {
    let step = (delta.len() / NOISE_SAMPLES).max(1);
    let mut abs: Vec<f64> = delta
        .iter()
        .step_by(step)
        .filter(|d| d.is_finite())
        .map(|d| d.abs())
        .collect();
    if abs.is_empty() {
        return (0.0, 0.0);
    }
    let abs_len = abs.len();
    let mid = abs_len / 2;
    let (_, m, upper) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    let sd = MAD_TO_SD * *m;
    // The 90th percentile lies in the upper half (`upper` follows the median): its rank there.
    let k = (TAIL_QUANTILE * abs_len as f64) as usize;
    let tail = match k.checked_sub(mid + 1) {
        Some(rank) if rank < upper.len() => {
            *upper.select_nth_unstable_by(rank, f64::total_cmp).1 / TAIL_Z
        }
        _ => sd,
    };
    (sd, if tail > MIXTURE_RATIO * sd { tail } else { sd })
}

/// Core-point spacing: the square root of the median [`area_share`] over up to 1,000 evenly
/// spread core points (regions take it over all of them).
fn spacing(index: &Neighbours, points: &[Point3<f64>]) -> f64 {
    if points.len() < MIN_SPACING_POINTS {
        return 0.0;
    }
    let mut shares: Vec<f64> = points
        .iter()
        .step_by((points.len() / SPACING_SAMPLES).max(1))
        .filter_map(|p| area_share(index, p))
        .collect();
    let mid = shares.len() / 2;
    shares.select_nth_unstable_by(mid, f64::total_cmp).1.sqrt()
}

#[cfg(test)]
mod tests {
    use super::noise_levels;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// `n` draws of zero-mean Gaussian noise whose SD is `sd_big` with probability `share_big`
    /// and 1 otherwise (Box-Muller).
    fn mixture(n: usize, share_big: f64, sd_big: f64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(36);
        (0..n)
            .map(|_| {
                let (u, v): (f64, f64) = (rng.gen(), rng.gen());
                let z = (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos();
                let sd = if rng.gen::<f64>() < share_big {
                    sd_big
                } else {
                    1.0
                };
                z * sd
            })
            .collect()
    }

    /// One noise level: the models read the median's estimate itself (full scans keep their
    /// numbers), about 1.
    #[test]
    fn gaussian_noise_has_one_level() {
        let (sd, models) = noise_levels(&mixture(20_000, 0.0, 1.0));
        assert_eq!(sd, models);
        assert!((sd - 1.0).abs() < 0.03, "{sd}");
    }

    /// A mixture (3 in 4 of SD 1, 1 in 4 of SD 3; the quantiles of |δ| from scipy's
    /// `norm.cdf` and `brentq`: median 0.830847, 90th percentile 2.654797): σ = 1.4826 ×
    /// 0.830847 = 1.2318, σ_models = 2.654797 / 1.644854 = 1.6140 (ratio 1.31 > 1.2).
    #[test]
    fn a_mixture_of_noise_levels_gives_the_models_the_tail() {
        let (sd, models) = noise_levels(&mixture(20_000, 0.25, 3.0));
        assert!((sd - 1.2318).abs() < 0.03, "{sd}");
        assert!((models - 1.6140).abs() < 0.04, "{models}");
    }

    #[test]
    fn no_finite_delta_is_no_noise() {
        assert_eq!(noise_levels(&[f64::NAN; 4]), (0.0, 0.0));
        let (sd, models) = noise_levels(&[0.01]);
        assert_eq!((sd, models), (1.4826 * 0.01, 1.4826 * 0.01));
    }
}

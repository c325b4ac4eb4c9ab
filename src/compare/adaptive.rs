//! Adaptive M3C2: per core point, the cylinder radius follows the RWME similarity of the
//! reference part X and the scan part Y inside it, and the distance is the offset between the
//! two surfaces' crossings of the normal line (a point pair), from local quadric fits.
//!
//! RWME (the seed paper): R(X, Y) = Σ w_i |X_i| / (λ + Σ w_i d(X_i, Y)), w_i = exp(-d(X_i, Y)/h),
//! with X_i a reference point and |X_i| its area share (cylinder disc area / count), and
//! d(X_i, Y) = |δ_i| the one-sided distance from X_i to the scan along X_i's normal (to the
//! scan point nearest to that normal line among X_i's 8 nearest scan points). The similarity
//! s(r) = R / R0 compares with a perfect match at the noise level (every d = d0 = σ sqrt(2/π)).
//! The radius grows through the candidate set while s >= threshold. docs/ALGORITHMS.md has
//! the details.
use anyhow::{ensure, Result};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;

use super::cylinder::{members, Member};
use super::fit::{fit, Local};
use super::{radius_for_count, Clouds, CompareConfig, Deviation, Reason};
use crate::cloud::PointCloud;

/// Fewest scan points a fit may keep before the radius grows.
const FIT_MIN: usize = 6;

/// Per-cloud data shared by all core points.
struct Prepared<'a> {
    clouds: &'a Clouds<'a>,
    ref_normals: &'a [Vector3<f64>],
    /// Signed one-sided distance from each reference point to the scan along its normal.
    delta: Vec<f64>,
    /// Nearest reference point of each scan point.
    scan_nearest_ref: Vec<u32>,
    /// Point-pair distance of each scan point: along its nearest reference point's normal,
    /// from that point's tangent plane.
    scan_pair: Vec<f64>,
    radii: Vec<f64>,
    noise: f64,
    cos_limit: f64,
}

/// Runs the adaptive variant at every core point; returns the results, the noise used and
/// the candidate radii.
pub fn run(
    clouds: &Clouds,
    core: &PointCloud,
    normals: &[Vector3<f64>],
    cfg: &CompareConfig,
) -> Result<(Vec<Deviation>, f64, Vec<f64>)> {
    let a = &cfg.adaptive;
    let ref_normals = clouds.reference.normals.as_deref().ok_or_else(|| {
        anyhow::anyhow!("the adaptive method needs reference normals (give a mesh or normals)")
    })?;
    ensure!(
        a.lambda > 0.0 && a.h > 0.0,
        "adaptive lambda and h must be positive"
    );
    let radii = if a.radii.is_empty() {
        let r0 = radius_for_count(clouds, 12.0);
        (0..4).map(|k| r0 * 2f64.sqrt().powi(k)).collect()
    } else {
        a.radii.clone()
    };
    ensure!(
        radii.windows(2).all(|w| w[0] < w[1]) && radii[0] > 0.0,
        "adaptive radii must be positive and ascending"
    );
    let delta = one_sided_distances(clouds, ref_normals);
    let noise = match a.noise {
        Some(s) => s,
        None => robust_sd(&delta),
    };
    let (scan_nearest_ref, scan_pair): (Vec<u32>, Vec<f64>) = clouds
        .scan
        .points
        .par_iter()
        .map(|y| {
            let i = clouds.ref_index.nearest(y).map_or(0, |n| n.index);
            let x = clouds.reference.points[i];
            (i as u32, ref_normals[i].dot(&(y - x)))
        })
        .unzip();
    let prep = Prepared {
        clouds,
        ref_normals,
        delta,
        scan_nearest_ref,
        scan_pair,
        radii: radii.clone(),
        noise,
        cos_limit: a.max_normal_angle.to_radians().cos(),
    };
    let values = super::run(core, normals, |p, n| at(&prep, p, n, cfg));
    Ok((values, noise, radii))
}

/// δ_i for every reference point: along its normal, to the scan point (of its 8 nearest)
/// closest to its normal line.
fn one_sided_distances(clouds: &Clouds, ref_normals: &[Vector3<f64>]) -> Vec<f64> {
    let scan = &clouds.scan.points;
    clouds
        .reference
        .points
        .par_iter()
        .zip(ref_normals.par_iter())
        .map(|(x, n)| {
            let mut best = (f64::INFINITY, f64::NAN);
            for nb in clouds.scan_index.knn(x, 8) {
                let d = scan[nb.index] - x;
                let t = d.dot(n);
                let across = d.norm_squared() - t * t;
                if across < best.0 {
                    best = (across, t);
                }
            }
            best.1
        })
        .collect()
}

/// 1.4826 × median |δ| over up to 20,000 evenly spread values (the noise along the normal
/// when most of the part is in tolerance).
fn robust_sd(delta: &[f64]) -> f64 {
    let step = (delta.len() / 20_000).max(1);
    let mut abs: Vec<f64> = delta
        .iter()
        .step_by(step)
        .filter(|d| d.is_finite())
        .map(|d| d.abs())
        .collect();
    if abs.is_empty() {
        return 0.0;
    }
    let mid = abs.len() / 2;
    let (_, m, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *m
}

/// Two unit vectors completing `n` to a right-handed frame.
fn tangent_frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let e1 = n.cross(&helper).normalize();
    (e1, n.cross(&e1))
}

/// Members sorted by distance from the axis.
fn by_rho(mut m: Vec<Member>) -> Vec<Member> {
    m.sort_by(|a, b| a.rho2.total_cmp(&b.rho2).then(a.index.cmp(&b.index)));
    m
}

/// Similarity s(r) of the reference members within `r` (see the module doc).
fn similarity(prep: &Prepared, refs: &[Member], r: f64, h: f64, lambda: f64) -> f64 {
    let inside: Vec<f64> = refs
        .iter()
        .take_while(|m| m.rho2 <= r * r)
        .map(|m| prep.delta[m.index].abs())
        .filter(|d| d.is_finite())
        .collect();
    if inside.is_empty() {
        return 0.0;
    }
    let m = inside.len() as f64;
    let share = std::f64::consts::PI * r * r / m;
    let (sw, swd) = inside.iter().fold((0.0, 0.0), |(sw, swd), d| {
        let w = (-d / h).exp();
        (sw + w, swd + w * d)
    });
    let rwme = sw * share / (lambda + swd * share);
    let d0 = prep.noise * (2.0 / std::f64::consts::PI).sqrt();
    let w0 = (-d0 / h).exp();
    let ideal = m * w0 * share / (lambda + m * w0 * d0 * share);
    rwme / ideal
}

/// The adaptive result at core point `p` with outward unit normal `n`.
fn at(prep: &Prepared, p: &Point3<f64>, n: &Vector3<f64>, cfg: &CompareConfig) -> Deviation {
    let a = &cfg.adaptive;
    let c = prep.clouds;
    let r_max = *prep.radii.last().expect("radii");
    let agrees = |i: usize| prep.ref_normals[i].dot(n) >= prep.cos_limit;
    let refs = by_rho(
        members(
            &c.ref_index,
            &c.reference.points,
            p,
            n,
            r_max,
            cfg.max_distance,
        )
        .into_iter()
        .filter(|m| agrees(m.index))
        .collect(),
    );
    let scans = by_rho(
        members(&c.scan_index, &c.scan.points, p, n, r_max, cfg.max_distance)
            .into_iter()
            .filter(|m| agrees(prep.scan_nearest_ref[m.index] as usize))
            .collect(),
    );
    let count = |ms: &[Member], r: f64| ms.iter().take_while(|m| m.rho2 <= r * r).count();
    let min = cfg.min_points.max(1);
    // Grow through the radii while every one so far is similar (stay at the smallest when
    // it is not); then further only as far as needed to hold min_points each.
    let mut k = 0;
    for (j, &r) in prep.radii.iter().enumerate() {
        if similarity(prep, &refs, r, a.h, a.lambda) < a.similarity {
            break;
        }
        k = j;
    }
    while k + 1 < prep.radii.len()
        && (count(&refs, prep.radii[k]) < min || count(&scans, prep.radii[k]) < min)
    {
        k += 1;
    }
    let (e1, e2) = tangent_frame(n);
    let local = |m: &Member| -> Local {
        let d = c.scan.points[m.index] - p;
        [d.dot(&e1), d.dot(&e2), prep.scan_pair[m.index]]
    };
    // The fit must keep at least FIT_MIN points after trimming, else the next radius.
    let (r, n_ref, _, fs) = loop {
        let r = prep.radii[k];
        let (n_ref, n_scan) = (count(&refs, r), count(&scans, r));
        let last = k + 1 == prep.radii.len();
        if n_ref < min {
            return Deviation::missing(Reason::FewReference, r, n_ref, n_scan);
        }
        if n_scan < min {
            return Deviation::missing(Reason::FewScan, r, n_ref, n_scan);
        }
        let pairs: Vec<Local> = scans[..n_scan].iter().map(local).collect();
        match fit(&pairs, r, 4.0 * prep.noise, prep.noise) {
            Some(fs) if fs.n >= FIT_MIN || last => break (r, n_ref, n_scan, fs),
            _ if last => return Deviation::missing(Reason::FewScan, r, n_ref, n_scan),
            _ => k += 1,
        }
    };
    let lod = 1.96 * (fs.se + cfg.registration_error);
    Deviation {
        distance: fs.t0,
        uncertainty: lod,
        significant: false,
        radius: r,
        n_ref,
        n_scan: fs.n,
        direction: Vector3::zeros(),
        spread: [0.0, fs.sigma],
        reason: Reason::Ok,
    }
    .finish(n)
}

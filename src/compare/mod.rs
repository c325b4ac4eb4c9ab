//! Scan-versus-reference deviations at core points: classic M3C2 (Lague et al. 2013, the
//! py4dgeo 1.2 semantics) and the adaptive M3C2 whose cylinder radius follows the local RWME
//! similarity (the default). Distances are signed along the outward normal: + is material in
//! excess. Formulas and choices: docs/ALGORITHMS.md.
//!
//! Front: [`compare`]; core points and their normals: [`core_points`].
mod adaptive;
mod classic;
mod clouds;
mod config;
mod core;
mod cover;
mod deviation;

use std::borrow::Cow;

use anyhow::{ensure, Result};

use self::clouds::{in_storage_order, run, surface_density, Clouds};
pub use self::config::{
    AdaptiveConfig, Aggregate, CompareConfig, DensifyConfig, FillConfig, Method, PeakConfig,
    DEFAULT_TOLERANCE, MAX_LENGTH_MM, MAX_RADII,
};
pub use self::core::{
    area_share, area_shares, cloud_reference, core_points, default_count, mesh_reference,
    CoreConfig, CoreSelection,
};
pub use self::deviation::{
    add_coverage_fields, to_cloud, Deviation, Deviations, Reason, PEAK_LOD_RATIO,
};
use crate::cloud::PointCloud;
use crate::spatial::Grid;

/// The classic radius by default holds about this many scan points at the scan's median
/// density (enough for a mean and a standard deviation per cylinder).
const CLASSIC_RADIUS_POINTS: f64 = 20.0;

/// The smallest adaptive candidate radius r0 by default holds about this many scan points (a
/// quadric's six terms with a few residual degrees of freedom).
const ADAPTIVE_R0_POINTS: f64 = 12.0;

/// Compares `scan` with `reference` at the core points `core` (points with outward unit
/// normals, reference frame; see [`core_points`]). The scan must already be registered.
pub fn compare(
    core: &PointCloud,
    reference: &PointCloud,
    scan: &PointCloud,
    cfg: &CompareConfig,
) -> Result<Deviations> {
    let normals = core
        .normals
        .as_ref()
        .ok_or_else(|| anyhow::anyhow!("core points have no normals"))?;
    ensure!(!reference.is_empty(), "reference has no points");
    ensure!(!scan.is_empty(), "scan has no points");
    cfg.check().map_err(|m| anyhow::anyhow!("[compare] {m}"))?;
    // The grids' cells only set the speed (every query is exact); the scan's density, from
    // its grid, sets the default radii.
    let (mut ref_grid, mut scan_grid) = rayon::join(
        || Grid::for_points(&reference.points),
        || Grid::for_points(&scan.points),
    );
    let scan_density = surface_density(&scan_grid);
    let radius_for = |count: f64| (count / (std::f64::consts::PI * scan_density)).sqrt();
    let (classic_radius, adaptive_radii) = match cfg.method {
        Method::Classic => {
            let radius = cfg
                .radius
                .unwrap_or_else(|| radius_for(CLASSIC_RADIUS_POINTS));
            ensure!(
                radius > 0.0 && radius.is_finite(),
                "the default classic radius {radius} mm (from the scan's density) is not positive"
            );
            (radius, Vec::new())
        }
        Method::Adaptive => {
            let r0 = match cfg.adaptive.radii.is_empty() {
                true => radius_for(ADAPTIVE_R0_POINTS),
                false => f64::NAN,
            };
            let radii = adaptive::radii(&cfg.adaptive, r0)?;
            (radii[0], radii)
        }
    };
    // The adaptive variant reads per-point data of every point near each cylinder: it gets
    // both clouds in their grid's storage order (results are per core point, so the order
    // is invisible outside; those reads then stay in cache). Classic reads few; the copy
    // would cost it more than it saves.
    let (reference, scan) = match cfg.method {
        Method::Classic => (Cow::Borrowed(reference), Cow::Borrowed(scan)),
        Method::Adaptive => rayon::join(
            || Cow::Owned(in_storage_order(reference, &ref_grid.renumber())),
            || Cow::Owned(in_storage_order(scan, &scan_grid.renumber())),
        ),
    };
    let clouds = Clouds {
        reference: &reference,
        scan: &scan,
        ref_grid,
        scan_grid,
        scan_density,
    };
    let (values, noise, radii, points, normals) = match cfg.method {
        Method::Classic => {
            let values = run(&clouds.ref_grid, core, normals, |buf, p, n| {
                classic::at(&clouds, p, n, classic_radius, cfg, buf)
            });
            (
                values,
                f64::NAN,
                vec![classic_radius],
                core.points.clone(),
                normals.clone(),
            )
        }
        Method::Adaptive => {
            let all = adaptive::run(&clouds, core, normals, &adaptive_radii, cfg)?;
            (
                all.values,
                all.noise,
                adaptive_radii,
                all.points,
                all.normals,
            )
        }
    };
    Ok(Deviations {
        points,
        normals,
        values,
        given: core.len(),
        method: cfg.method,
        noise,
        radii,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};
    use rand::{Rng, SeedableRng};

    /// A plane with a Gaussian bump (0.2 mm high, σ 0.8 mm) at the origin, scanned with
    /// 0.005 mm noise; the reference plane has a 3 mm hole around (6, 6).
    fn bump_case() -> (PointCloud, PointCloud) {
        let lattice = (0..80 * 80).map(|i| {
            Point3::new(
                (i % 80) as f64 * 0.25 - 10.0,
                (i / 80) as f64 * 0.25 - 10.0,
                0.0,
            )
        });
        let points: Vec<Point3<f64>> = lattice
            .filter(|p| (p.x - 6.0).hypot(p.y - 6.0) > 3.0)
            .collect();
        let reference = PointCloud {
            normals: Some(vec![Vector3::z(); points.len()]),
            points,
            fields: Vec::new(),
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let scan = PointCloud::from_points(
            (0..8000)
                .map(|_| {
                    let (x, y): (f64, f64) =
                        (rng.gen_range(-10.0..10.0), rng.gen_range(-10.0..10.0));
                    let bump = 0.2 * (-(x * x + y * y) / (2.0 * 0.8 * 0.8)).exp();
                    Point3::new(x, y, bump + 0.005 * (rng.gen::<f64>() - 0.5) * 3.46)
                })
                .collect(),
        );
        (reference, scan)
    }

    #[test]
    fn adaptive_measures_a_bump_whatever_the_input_order() {
        let (reference, scan) = bump_case();
        let core = PointCloud {
            points: vec![
                Point3::origin(),
                Point3::new(-6.0, -6.0, 0.0),
                // In the reference's hole, 0.8 mm from its rim: the cylinder holds rim points,
                // and scan points farther from every reference point than any cylinder
                // around a reference point reaches (looked up when met).
                Point3::new(6.0 - 2.2 / 2f64.sqrt(), 6.0 - 2.2 / 2f64.sqrt(), 0.0),
                // The hole's centre: no reference point in reach.
                Point3::new(6.0, 6.0, 0.0),
            ],
            normals: Some(vec![Vector3::z(); 4]),
            fields: Vec::new(),
        };
        let cfg = CompareConfig::default();
        let dev = compare(&core, &reference, &scan, &cfg).unwrap();
        let [top, flat, rim, hole] = [0, 1, 2, 3].map(|i| dev.values[i]);
        assert!((top.distance - 0.2).abs() < 0.02, "{top:?}");
        assert!(top.significant && top.peak >= top.distance);
        assert!(flat.distance.abs() < 0.01 && !flat.significant, "{flat:?}");
        assert!(rim.distance.abs() < 0.02 && rim.n_ref >= 3, "{rim:?}");
        assert_eq!(hole.reason, Reason::FewReference, "{hole:?}");
        assert!(hole.distance.is_nan());
        // The clouds are reordered internally: reversed input gives the same answers.
        let reversed = |c: &PointCloud| {
            let idx: Vec<usize> = (0..c.len()).rev().collect();
            c.select(&idx)
        };
        let again = compare(&core, &reversed(&reference), &reversed(&scan), &cfg).unwrap();
        for (a, b) in dev.values.iter().zip(&again.values) {
            let same = (a.distance - b.distance).abs() < 1e-12 || a.distance.is_nan();
            assert!(same && a.reason == b.reason, "{a:?} {b:?}");
            assert_eq!((a.radius, a.n_ref, a.n_scan), (b.radius, b.n_ref, b.n_scan));
        }
    }
}

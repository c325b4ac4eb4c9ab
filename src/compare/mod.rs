//! Scan-versus-reference deviations at core points: classic M3C2 (Lague et al. 2013, the
//! py4dgeo 1.2 semantics) and the adaptive M3C2 whose cylinder radius follows the local RWME
//! similarity (the default). Distances are signed along the outward normal: + is material in
//! excess. Formulas and choices: docs/ALGORITHMS.md.
//!
//! Front: [`compare`]; core points and their normals: [`core_points`].
mod adaptive;
mod classic;
mod config;
mod core;
mod cover;

use std::borrow::Cow;

use anyhow::{ensure, Result};
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub use self::config::{
    AdaptiveConfig, Aggregate, CompareConfig, DensifyConfig, FillConfig, Method, PeakConfig,
    DEFAULT_TOLERANCE,
};
pub use self::core::{
    area_share, area_shares, cloud_reference, core_points, default_count, mesh_reference,
    CoreConfig, CoreSelection,
};
use crate::cloud::PointCloud;
use crate::spatial::{in_index_order, Grid};

/// The normal quantile of a two-sided 95 % level (the LoD's factor on the registration error,
/// as in Lague et al.).
pub(crate) const Z95: f64 = 1.96;

/// The classic radius by default holds about this many scan points at the scan's median
/// density (enough for a mean and a standard deviation per cylinder).
const CLASSIC_RADIUS_POINTS: f64 = 20.0;

/// The smallest adaptive candidate radius r0 by default holds about this many scan points (a
/// quadric's six terms with a few residual degrees of freedom).
const ADAPTIVE_R0_POINTS: f64 = 12.0;

/// Core points are handed to the threads in chunks of this many (speed only: a chunk shares
/// one scratch buffer).
const CHUNK: usize = 512;

/// The surface density reads the distance to this many nearest neighbours ...
const DENSITY_NEIGHBOURS: usize = 12;

/// ... of up to this many evenly spread points (its median moves by less than a per cent).
const DENSITY_SAMPLES: usize = 1000;

/// Density assumed (points per mm²) when no sampled point has enough neighbours: a few
/// points, whose radii the caller's checks refuse anyway.
const FALLBACK_DENSITY: f64 = 1.0;

/// A peak evaluation counts only when its LoD is at most this many times that of what it is
/// compared with: a refined evaluation against its core point's, a region member against the
/// region's median (a fit through a few points at a face border or a scan gap is no peak).
pub const PEAK_LOD_RATIO: f64 = 2.0;

/// Why a core point has no distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reason {
    /// A distance was computed.
    Ok,
    /// Fewer than `min_points` reference points in the cylinder.
    FewReference,
    /// Fewer than `min_points` scan points in the cylinder (adaptive: none in the smallest
    /// disc, which the scan does not fill): a hole in the scan, or surface it did not see.
    FewScan,
    /// The distance is the height of a peak model fitted to a defect: around the top of a
    /// defect that the cylinders cannot resolve (adaptive densification), or inside a defect
    /// whose model follows the scan points (adaptive model fill); `n_ref` 0, `radius` the
    /// model's window, `n_scan` the scan points it used.
    PeakModel,
    /// The distance is one point pair's, from the reference point's tangent plane to the scan
    /// point nearest its normal line: under a defect narrower than a peak model can pin
    /// (adaptive densification); `radius` 0, `n_ref` and `n_scan` 1.
    PointPair,
    /// Adaptive only: the scan lies on one side of the core point (135° of the annulus
    /// around it hold reference points but no scan point), or fills not even the smallest
    /// disc, though that disc holds scan points: the border of the scan or of a hole in it.
    /// A cylinder there sees the surface on one side only, and its fit extrapolates to the
    /// core point (`FewScan` when the smallest disc holds no scan point).
    ScanBorder,
}

impl Reason {
    /// Numeric code for files: 0 ok, 1 few reference points, 2 few scan points (a hole),
    /// 3 peak model, 4 point pair, 5 scan border.
    pub fn code(self) -> u8 {
        match self {
            Reason::Ok => 0,
            Reason::FewReference => 1,
            Reason::FewScan => 2,
            Reason::PeakModel => 3,
            Reason::PointPair => 4,
            Reason::ScanBorder => 5,
        }
    }
}

/// The result at one core point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deviation {
    /// Signed distance along the outward normal, mm (+ = material in excess); NaN when
    /// `reason` is not Ok.
    pub distance: f64,
    /// Level of detection at 95 %, mm (NaN when it cannot be computed).
    pub uncertainty: f64,
    /// |distance| > uncertainty.
    pub significant: bool,
    /// Cylinder radius used, mm.
    pub radius: f64,
    /// Reference points used.
    pub n_ref: usize,
    /// Scan points used.
    pub n_scan: usize,
    /// Unit vector from the reference surface point to its paired scan surface point (zero
    /// when the distance is zero or NaN).
    pub direction: Vector3<f64>,
    /// Spread (standard deviation along the normal) of the reference and scan points, mm.
    pub spread: [f64; 2],
    /// Signed distance of largest magnitude around this core point, mm: the adaptive variant
    /// also evaluates the reference points within the smallest radius of a core point whose
    /// |distance| exceeds `adaptive.refine_above` (defect peaks fall between core points), and
    /// at the summits of those peaks it is the height of a fitted peak model when the fit is
    /// accepted (`adaptive.peak_fit`, then `peak_fitted`); otherwise equal to `distance`.
    pub peak: f64,
    /// `peak` comes from a peak-model fit (adaptive `peak_fit`) rather than from the largest
    /// of the quadric estimates: region peaks prefer it.
    pub peak_fitted: bool,
    /// Why the distance is NaN, if it is.
    pub reason: Reason,
}

impl Deviation {
    /// A NaN result for `reason`.
    fn missing(reason: Reason, radius: f64, n_ref: usize, n_scan: usize) -> Deviation {
        Deviation {
            distance: f64::NAN,
            uncertainty: f64::NAN,
            significant: false,
            radius,
            n_ref,
            n_scan,
            direction: Vector3::zeros(),
            spread: [f64::NAN; 2],
            peak: f64::NAN,
            peak_fitted: false,
            reason,
        }
    }

    /// Fills `significant` and `direction` from `distance` and `uncertainty`.
    fn finish(mut self, normal: &Vector3<f64>) -> Deviation {
        self.significant = self.distance.abs() > self.uncertainty;
        self.peak = self.distance;
        if self.distance != 0.0 && self.distance.is_finite() {
            self.direction = normal * self.distance.signum();
        }
        self
    }
}

/// Deviations at every core point.
#[derive(Debug, Clone)]
pub struct Deviations {
    /// Core points (reference frame).
    pub points: Vec<Point3<f64>>,
    /// Their outward unit normals.
    pub normals: Vec<Vector3<f64>>,
    /// One result per core point.
    pub values: Vec<Deviation>,
    /// The first `given` core points are those given to [`compare`]; the others were added
    /// by densification around the summits of defects (adaptive `densify_above`).
    pub given: usize,
    /// Variant used.
    pub method: Method,
    /// Scan noise used by the adaptive variant (mm; NaN for classic).
    pub noise: f64,
    /// Candidate radii (adaptive) or the one radius (classic), mm.
    pub radii: Vec<f64>,
}

impl Deviations {
    /// Core points added by densification (the last rows).
    pub fn added(&self) -> usize {
        self.values.len() - self.given
    }

    /// Core points whose distance is a defect model's height ([`Reason::PeakModel`]).
    pub fn modelled(&self) -> usize {
        let model = |v: &&Deviation| v.reason == Reason::PeakModel;
        self.values.iter().filter(model).count()
    }

    /// Core points measured by one point pair each ([`Reason::PointPair`]).
    pub fn point_pairs(&self) -> usize {
        let pair = |v: &&Deviation| v.reason == Reason::PointPair;
        self.values.iter().filter(pair).count()
    }

    /// One line on the core points: how many, how many added, measured by defect models
    /// (and by single point pairs, when any: the peaks of those defects are lower bounds),
    /// and with a distance.
    pub fn summary(&self) -> String {
        let valid = self
            .values
            .iter()
            .filter(|v| v.distance.is_finite())
            .count();
        let pairs = match self.point_pairs() {
            0 => String::new(),
            n => format!(
                ", {n} measured by single point pairs under defects too narrow for a model \
                 (their peaks are lower bounds)"
            ),
        };
        format!(
            "{} ({} added around defects, {} measured by defect models{pairs}, {} with a distance)",
            self.values.len(),
            self.added(),
            self.modelled(),
            valid
        )
    }
}

/// Data every variant reads: the two clouds and their grids.
pub(crate) struct Clouds<'a> {
    pub reference: &'a PointCloud,
    pub scan: &'a PointCloud,
    pub ref_grid: Grid,
    pub scan_grid: Grid,
    /// The scan's median surface density, points per mm² ([`surface_density`]).
    pub scan_density: f64,
}

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
    ensure!(
        cfg.max_distance.is_finite() && cfg.max_distance >= 0.0,
        "max_distance must be a finite non-negative number"
    );
    ensure!(
        cfg.registration_error.is_finite() && cfg.registration_error >= 0.0,
        "registration_error must be a finite non-negative number"
    );
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
                "radius must be positive"
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

/// The points and normals of `cloud` in the order `ids` (scalar fields are not needed here).
fn in_storage_order(cloud: &PointCloud, ids: &[u32]) -> PointCloud {
    PointCloud {
        points: ids.par_iter().map(|&i| cloud.points[i as usize]).collect(),
        normals: cloud
            .normals
            .as_ref()
            .map(|n| ids.par_iter().map(|&i| n[i as usize]).collect()),
        fields: Vec::new(),
    }
}

/// Runs `f` at every core point in parallel (one result each), with a progress bar; `f` gets
/// a scratch value (one per chunk of core points) to reuse. Core points are visited in the
/// grid's spatial order (cache-friendly); the results come back in the core points' order.
fn run<S, T, F>(grid: &Grid, core: &PointCloud, normals: &[Vector3<f64>], f: F) -> Vec<T>
where
    S: Default,
    T: Copy + Send,
    F: Fn(&mut S, &Point3<f64>, &Vector3<f64>) -> T + Sync,
{
    let bar = crate::progress::bar(core.len() as u64, "compare");
    let order = grid.spatial_order(&core.points);
    let done: Vec<T> = order
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            let mut scratch = S::default();
            let done: Vec<T> = chunk
                .iter()
                .map(|&i| f(&mut scratch, &core.points[i], &normals[i]))
                .collect();
            bar.inc(done.len() as u64);
            done
        })
        .collect();
    bar.finish_and_clear();
    in_index_order(order.iter().copied(), done)
}

/// The median surface density (points per mm²) of the points of `grid` (the scan's, or the
/// reference's), from the 12th-neighbour distance of up to 1,000 of them evenly spread over
/// the grid's storage order (spatial: the answer does not depend on the order of the points
/// in the file).
fn surface_density(grid: &Grid) -> f64 {
    let n = grid.slot_ids().len();
    let step = (n / DENSITY_SAMPLES).max(1);
    let mut found = Vec::new();
    let mut densities: Vec<f64> = (0..n)
        .step_by(step)
        .filter_map(|s| {
            grid.knn(
                &Point3::from(*grid.slot_point(s)),
                DENSITY_NEIGHBOURS + 1,
                f64::INFINITY,
                &mut found,
            );
            let d2 = found.last()?.0;
            let k = DENSITY_NEIGHBOURS as f64;
            (found.len() == DENSITY_NEIGHBOURS + 1 && d2 > 0.0)
                .then(|| k / (std::f64::consts::PI * d2))
        })
        .collect();
    if densities.is_empty() {
        return FALLBACK_DENSITY;
    }
    densities.sort_by(f64::total_cmp);
    densities[densities.len() / 2]
}

/// The deviations as a cloud with the columns of deviations.csv/.ply (DESIGN.md):
/// x,y,z,nx,ny,nz,distance,uncertainty,significant,radius,n_ref,n_scan,region.
pub fn to_cloud(dev: &Deviations, region: &[i64]) -> PointCloud {
    let mut cloud = PointCloud {
        points: dev.points.clone(),
        normals: Some(dev.normals.clone()),
        fields: Vec::new(),
    };
    let col = |f: &dyn Fn(&Deviation) -> f64| dev.values.iter().map(f).collect::<Vec<f64>>();
    cloud.set_field("distance", col(&|d| d.distance));
    cloud.set_field("uncertainty", col(&|d| d.uncertainty));
    cloud.set_field("significant", col(&|d| d.significant as u8 as f64));
    cloud.set_field("radius", col(&|d| d.radius));
    cloud.set_field("n_ref", col(&|d| d.n_ref as f64));
    cloud.set_field("n_scan", col(&|d| d.n_scan as f64));
    cloud.set_field("region", region.iter().map(|&r| r as f64).collect());
    cloud
}

/// Adds deviations.ply's coverage fields to `cloud` (the rows of `dev`): `measured` (1 where
/// the core point got a distance, 0 where not: a hole, a scan border, no reference) and
/// `reason` ([`Reason::code`]).
pub fn add_coverage_fields(dev: &Deviations, cloud: &mut PointCloud) {
    let col = |f: &dyn Fn(&Deviation) -> f64| dev.values.iter().map(f).collect::<Vec<f64>>();
    cloud.set_field("measured", col(&|d| d.distance.is_finite() as u8 as f64));
    cloud.set_field("reason", col(&|d| d.reason.code() as f64));
}

#[cfg(test)]
mod tests {
    use super::*;
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

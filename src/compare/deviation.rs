//! What the comparison answers per core point ([`Deviation`], [`Reason`]) and in all
//! ([`Deviations`]), and the columns of deviations.csv/.ply.
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::config::Method;
use crate::cloud::PointCloud;

/// The normal quantile of a two-sided 95 % level (the LoD's factor on the registration error,
/// as in Lague et al.).
pub(crate) const Z95: f64 = 1.96;

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
    pub(crate) fn missing(reason: Reason, radius: f64, n_ref: usize, n_scan: usize) -> Deviation {
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
    pub(crate) fn finish(mut self, normal: &Vector3<f64>) -> Deviation {
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

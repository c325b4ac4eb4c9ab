//! Settings of the comparison: [`CompareConfig`] (`[compare]` of a `--config` file) and the
//! adaptive variant's nested settings (`[compare.adaptive]`, `[compare.adaptive.peak]`,
//! `[compare.adaptive.densify]`, `[compare.adaptive.fill]`). Every default is written once,
//! in the `Default` impls here, with its reason; docs/ALGORITHMS.md has the method. Unknown
//! keys are refused (a typo would otherwise run the default silently).
use serde::{Deserialize, Serialize};

use crate::settings::{above, at_least, in_range};

/// The tolerance on |distance| the comparison works to when its caller gives none, mm
/// (`inspect`'s default `[regions] tolerance`; a test checks that they agree).
pub const DEFAULT_TOLERANCE: f64 = 0.05;

/// Which M3C2 variant to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Cylinder radius chosen per core point from the RWME similarity; quadric point pairs.
    #[default]
    Adaptive,
    /// One fixed cylinder radius; difference of the cylinder means (py4dgeo's M3C2).
    Classic,
}

/// How classic M3C2 sums up each cylinder's positions along the normal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Aggregate {
    /// Mean and sample standard deviation (Lague et al.; py4dgeo's default).
    #[default]
    Mean,
    /// Median and interquartile range, robust to outliers in a cylinder (py4dgeo's
    /// `robust_aggr=True`: its quartiles, and the IQR in place of the standard deviation in
    /// the LoD, which makes the LoD about 1.35 × the mean's for Gaussian noise).
    Median,
}

/// Settings of [`super::compare`].
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CompareConfig {
    /// Variant (default adaptive).
    pub method: Method,
    /// Classic cylinder radius d, mm (default: none = the radius that holds about 20 scan
    /// points at the scan's median density).
    pub radius: Option<f64>,
    /// Half-length L of the cylinder along the normal, mm (py4dgeo's `max_distance`; a value
    /// below the radius means the radius, as in py4dgeo). Default 1.0.
    pub max_distance: f64,
    /// Registration error added to the level of detection, mm (default 0; `inspect` puts the
    /// registration's `registration_error` here unless given).
    pub registration_error: f64,
    /// Classic only: mean or median of each cylinder (default mean).
    pub aggregate: Aggregate,
    /// Fewest points each cloud must have in a cylinder; fewer gives NaN with a reason
    /// (default 3; 1 reproduces py4dgeo, which only fails on empty cylinders).
    pub min_points: usize,
    /// The tolerance on |distance| the adaptive variant works to, mm: it sets where peaks are
    /// refined and core points added (`adaptive.refine_above`, `adaptive.densify_above`) and
    /// which narrow defects a peak model looks for. An input of the caller, not a key of the
    /// `[compare]` table: `inspect` gives its `[regions] tolerance` (default
    /// [`DEFAULT_TOLERANCE`]).
    #[serde(skip)]
    pub tolerance: f64,
    /// Settings of the adaptive variant.
    pub adaptive: AdaptiveConfig,
}

impl Default for CompareConfig {
    fn default() -> Self {
        CompareConfig {
            method: Method::Adaptive,
            radius: None,
            max_distance: 1.0,
            registration_error: 0.0,
            aggregate: Aggregate::Mean,
            min_points: 3,
            tolerance: DEFAULT_TOLERANCE,
            adaptive: AdaptiveConfig::default(),
        }
    }
}

impl CompareConfig {
    /// `adaptive.refine_above`, or the tolerance when unset.
    pub fn refine_above(&self) -> f64 {
        self.adaptive.refine_above.unwrap_or(self.tolerance)
    }

    /// `adaptive.densify_above`, or half the tolerance when unset.
    pub fn densify_above(&self) -> f64 {
        self.adaptive
            .densify_above
            .unwrap_or(DENSIFY_SHARE * self.tolerance)
    }
}

/// Core points are added around summits beyond this share of the tolerance: a defect narrower
/// than the cylinders reads at about half its height there, and one just beyond the tolerance
/// must still be caught (docs/ACCURACY.md, step 11).
const DENSIFY_SHARE: f64 = 0.5;

/// Settings of the adaptive (RWME) variant (`[compare.adaptive]`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdaptiveConfig {
    /// Candidate radii, ascending, mm (default: none = four radii from r0 to 2.83 r0 in steps
    /// of sqrt 2, r0 holding about 12 scan points at the scan's median density).
    pub radii: Vec<f64>,
    /// RWME regulariser lambda (default 0.43, the paper's value).
    pub lambda: f64,
    /// Weight scale h of w = exp(-d/h), mm (default 0.05, the default tolerance).
    pub h: f64,
    /// A radius is kept while its similarity, relative to a perfect match at the noise
    /// level, is at least this (default 0.5).
    pub similarity: f64,
    /// Reference points whose normal is more than this many degrees off the core point's are
    /// another surface (across a sharp edge) and are left out, with the scan points nearest
    /// to them (default 35).
    pub max_normal_angle: f64,
    /// Scan noise (one standard deviation along the normal), mm (default: none = estimated
    /// from the data: the median's estimate, and for the peak models and the fill the tail's
    /// when the scan mixes noise levels, as a merged scan does; set, it is both).
    pub noise: Option<f64>,
    /// Beyond the RWME radius the radius keeps growing while the fits' confidence intervals
    /// t_k ± gamma·se_k all intersect (intersection of confidence intervals); 0 turns this
    /// off (default 2.0).
    pub gamma: f64,
    /// A fit whose residual standard deviation exceeds this many times the noise does not
    /// describe the surface at its radius (the quadric flattens a narrow peak): the radius
    /// stops growing before it, and it does not count for a peak (default 1.3).
    pub max_misfit: f64,
    /// Significant core points with |distance| above this (mm) get their `peak` from the
    /// reference points around them (default: none = the tolerance; infinity turns it off).
    pub refine_above: Option<f64>,
    /// Fit a peak model (an elliptic Gaussian on a plane) to the scan points around the top of
    /// each defect and report its height as the `peak` of the error point whose cell holds
    /// the top, when the fit passes its guard (default true; docs/ALGORITHMS.md).
    pub peak_fit: bool,
    /// Around each summit of the significant core points with |distance| above this (mm) and
    /// LoD at most twice this, whose cylinder is mostly covered by the reference surface,
    /// every reference point within the refine radius becomes a core point too: a defect
    /// narrower than about twice the core spacing is otherwise sampled by one or two core
    /// points (default: none = half the tolerance; infinity turns densification off, with
    /// its narrow-defect models).
    pub densify_above: Option<f64>,
    /// Inside a defect that an accepted peak model describes (those of `peak_fit` and of the
    /// narrow defects densification measures), the model's height replaces the cylinder
    /// estimate at the core points whose surrounding scan points agree with it (a
    /// lack-of-fit test); those rows become `Reason::PeakModel` (default true;
    /// docs/ACCURACY.md, step 13).
    pub model_fill: bool,
    /// The peak fit's window (`[compare.adaptive.peak]`).
    pub peak: PeakConfig,
    /// Densification and the narrow-defect search (`[compare.adaptive.densify]`).
    pub densify: DensifyConfig,
    /// The model fill (`[compare.adaptive.fill]`).
    pub fill: FillConfig,
}

impl Default for AdaptiveConfig {
    fn default() -> Self {
        AdaptiveConfig {
            radii: Vec::new(),
            lambda: 0.43,
            h: 0.05,
            similarity: 0.5,
            max_normal_angle: 35.0,
            noise: None,
            gamma: 2.0,
            max_misfit: 1.3,
            refine_above: None,
            peak_fit: true,
            densify_above: None,
            model_fill: true,
            peak: PeakConfig::default(),
            densify: DensifyConfig::default(),
            fill: FillConfig::default(),
        }
    }
}

/// Settings of the peak fit's window (`[compare.adaptive.peak]`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PeakConfig {
    /// Smallest radius of a peak fit's window, mm (default 2.0: the window must reach the foot
    /// of a defect up to 2 mm wide at half height, whose 5 % level lies 2.1 mm from its core,
    /// or the model's plane and amplitude trade off; seed 11 at 1.2M read IoU 0.936 instead
    /// of 0.956 with the cylinder-based 1.43 mm).
    pub min_window: f64,
}

impl Default for PeakConfig {
    fn default() -> Self {
        PeakConfig { min_window: 2.0 }
    }
}

/// Settings of densification and of the narrow-defect search (`[compare.adaptive.densify]`;
/// docs/ACCURACY.md, steps 11 and 12).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DensifyConfig {
    /// A summit's cylinder (and a narrow-defect window) must hold at least this share of the
    /// points a full disc of its radius holds (default 0.6: fits through the few points of a
    /// narrow face or a strip beside an edge, a third or less, give chance error points).
    pub min_coverage: f64,
    /// A top found from the scan's heights needs this many reference points within the
    /// smallest radius whose δ is beyond the tolerance (default 2: seed 45 at 300k had two
    /// under a 0.134 mm deep, 0.51 mm wide pit; one fits twice as many tops for one more
    /// defect in 48 cases).
    pub min_cluster: usize,
    /// ... and this many scan points within the refine radius beyond the tolerance (default
    /// 2: a top of noise has at most one; with 0.015 mm noise two of the 100-200 such a radius
    /// holds at 300k read beyond 0.05 mm about once in 500 tops).
    pub min_near_beyond: usize,
    /// Fewest scan points where a narrow defect's Gaussian is at least 10 % of its height
    /// (default 5: at 19 scan points/mm² a 0.44 mm wide bump has about 8 points on it).
    pub min_support: usize,
    /// A narrow defect's Gaussian must be at least this many scan spacings wide (default 0.5:
    /// a narrower one passes between the points; seed 24 at 300k fitted 0.14 mm where the
    /// truth is 0 with 0.083 mm across a 0.23 mm spacing).
    pub min_width: f64,
    /// A top whose model does not pin it is measured by its point pairs when this many scan
    /// points lie `far_noise` noise SDs beyond the tolerance (default 3: by chance about 1e-7
    /// among 12 with Gaussian noise).
    pub min_far_points: usize,
    /// How many noise SDs beyond the tolerance those scan points lie (default 3.0).
    pub far_noise: f64,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        DensifyConfig {
            min_coverage: 0.6,
            min_cluster: 2,
            min_near_beyond: 2,
            min_support: 5,
            min_width: 0.5,
            min_far_points: 3,
            far_noise: 3.0,
        }
    }
}

/// Settings of the model fill (`[compare.adaptive.fill]`; docs/ACCURACY.md,
/// step 13).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FillConfig {
    /// A core point is inside a model's defect where the defect term is at least this share
    /// of its amplitude (default 0.05: about 2.4 standard deviations of a Gaussian from its
    /// core).
    pub min_share: f64,
    /// The mean residual of the scan points around a core point against the model must be
    /// within this many of its standard errors (default 3.0: beyond, the model does not
    /// describe the surface there).
    pub lack_of_fit: f64,
    /// Fewest scan points around a core point, and per level of the profile test (default 4:
    /// fewer, the model would extrapolate into a hole and the cylinder value stays).
    pub min_local: usize,
    /// A model is refitted over a window of this many of its narrow standard deviations when
    /// that is larger than its own (default 3.5: the defect's 5 % level lies at 2.45 σ, and
    /// enough plane beyond it).
    pub wide_window: f64,
    /// A widened window is at most this many times the model's own (default 2.0).
    pub max_widening: f64,
}

impl Default for FillConfig {
    fn default() -> Self {
        FillConfig {
            min_share: 0.05,
            lack_of_fit: 3.0,
            min_local: 4,
            wide_window: 3.5,
            max_widening: 2.0,
        }
    }
}

/// Largest cylinder radius, half-length, weight scale `h`, noise or registration error
/// accepted, mm: a fifth of a femoral component, as `inspect`'s largest tolerance. The default
/// radii are 0.3-0.9 mm; a wider cylinder averages across the part's curvature and each core
/// point reads most of the cloud (classic `radius = 1e308` ran past 120 s).
pub const MAX_LENGTH_MM: f64 = 10.0;

/// Most candidate radii of the adaptive variant (`adaptive.radii`): each costs a quadric fit
/// per core point; the default is 4 (r0 to 2.83 r0), and 10,000 radii ran past 120 s.
pub const MAX_RADII: usize = 16;

impl CompareConfig {
    /// Checks every setting: a refusal is one line naming the key within `[compare]` (dotted
    /// below it, `adaptive.h`) in backticks, with its range, for `ConfigFile::refuse`.
    pub fn check(&self) -> Result<(), String> {
        let len = MAX_LENGTH_MM;
        if let Some(r) = self.radius {
            above("radius", r, 0.0, len, "mm")?;
        }
        in_range("max_distance", self.max_distance, 0.0, len, "mm")?;
        in_range(
            "registration_error",
            self.registration_error,
            0.0,
            len,
            "mm",
        )?;
        at_least("min_points", self.min_points, 1, "points")?;
        let radii = &self.adaptive.radii;
        if radii.len() > MAX_RADII {
            return Err(format!(
                "`adaptive.radii` lists {} radii, more than {MAX_RADII} (each costs a fit per core point)",
                radii.len()
            ));
        }
        for &r in radii {
            above("adaptive.radii", r, 0.0, len, "mm")?;
        }
        if !radii.windows(2).all(|w| w[0] < w[1]) {
            return Err("`adaptive.radii` must be in strictly ascending order".into());
        }
        self.check_adaptive()
    }

    /// Checks the settings the adaptive variant reads (every key of `[compare.adaptive]` but
    /// the radii, and the tolerance): one line naming the key, as [`CompareConfig::check`].
    fn check_adaptive(&self) -> Result<(), String> {
        let (a, inf) = (&self.adaptive, f64::INFINITY);
        above("adaptive.lambda", a.lambda, 0.0, inf, "(factor)")?;
        above("adaptive.h", a.h, 0.0, MAX_LENGTH_MM, "mm")?;
        in_range("adaptive.similarity", a.similarity, 0.0, 1.0, "(share)")?;
        in_range(
            "adaptive.max_normal_angle",
            a.max_normal_angle,
            0.0,
            180.0,
            "deg",
        )?;
        if let Some(n) = a.noise {
            above("adaptive.noise", n, 0.0, MAX_LENGTH_MM, "mm")?;
        }
        in_range("adaptive.gamma", a.gamma, 0.0, inf, "(SDs)")?;
        above("adaptive.max_misfit", a.max_misfit, 0.0, inf, "(noise SDs)")?;
        for (key, v) in [
            ("refine_above", a.refine_above),
            ("densify_above", a.densify_above),
        ] {
            if let Some(v) = v.filter(|v| v.is_nan() || *v < 0.0) {
                return Err(format!(
                    "`adaptive.{key}` = {v:?} mm is not a number of mm >= 0 (inf turns it off)"
                ));
            }
        }
        in_range("tolerance", self.tolerance, 0.0, inf, "mm")?;
        above(
            "adaptive.peak.min_window",
            a.peak.min_window,
            0.0,
            inf,
            "mm",
        )?;
        let d = &a.densify;
        in_range(
            "adaptive.densify.min_coverage",
            d.min_coverage,
            0.0,
            1.0,
            "(share)",
        )?;
        above(
            "adaptive.densify.min_width",
            d.min_width,
            0.0,
            inf,
            "(spacings)",
        )?;
        above(
            "adaptive.densify.far_noise",
            d.far_noise,
            0.0,
            inf,
            "(noise SDs)",
        )?;
        let f = &a.fill;
        above("adaptive.fill.min_share", f.min_share, 0.0, 1.0, "(share)")?;
        if f.min_share == 1.0 {
            return Err("`adaptive.fill.min_share` = 1.0 (share) must be below 1".into());
        }
        above(
            "adaptive.fill.lack_of_fit",
            f.lack_of_fit,
            0.0,
            inf,
            "(SEs)",
        )?;
        above(
            "adaptive.fill.wide_window",
            f.wide_window,
            0.0,
            inf,
            "(SDs)",
        )?;
        in_range(
            "adaptive.fill.max_widening",
            f.max_widening,
            1.0,
            inf,
            "(factor)",
        )?;
        at_least("adaptive.fill.min_local", f.min_local, 1, "points")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_pass_and_each_bad_value_names_its_key() {
        assert_eq!(CompareConfig::default().check(), Ok(()));
        let refused = |set: fn(&mut CompareConfig)| {
            let mut c = CompareConfig::default();
            set(&mut c);
            c.check().unwrap_err()
        };
        let e = refused(|c| c.radius = Some(1e308));
        assert!(e.starts_with("`radius` = 1e308 mm"), "{e}");
        let e = refused(|c| c.adaptive.radii = vec![0.1; MAX_RADII + 1]);
        assert!(e.starts_with("`adaptive.radii` lists 17"), "{e}");
        let e = refused(|c| c.adaptive.noise = Some(f64::NAN));
        assert!(e.starts_with("`adaptive.noise`"), "{e}");
        let e = refused(|c| c.adaptive.densify.min_coverage = 2.0);
        assert!(e.starts_with("`adaptive.densify.min_coverage`"), "{e}");
        let mut c = CompareConfig::default();
        c.adaptive.densify_above = Some(f64::INFINITY);
        c.adaptive.gamma = 0.0;
        assert_eq!(c.check(), Ok(()));
    }
}

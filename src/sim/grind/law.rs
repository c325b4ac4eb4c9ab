//! The simulator's true removal law: spring force from penetration, a Hertz contact patch,
//! Preston's law with exponents, and a smooth local variation of k. Written for the simulator
//! alone: the planner's removal model is separate code with separate parameters.
use nalgebra::{Point3, Vector3};

use super::GrindConfig;
use crate::sim::model::splitmix64;

/// A contact of the ball on the surface: force and Hertz patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HertzContact {
    /// Normal force, N (spring rate x penetration).
    pub force_n: f64,
    /// Radius of the contact patch, mm.
    pub radius_mm: f64,
    /// Peak (centre) pressure, MPa = N/mm^2.
    pub peak_mpa: f64,
}

impl HertzContact {
    /// The contact of a ball of radius `ball_mm` pressed `penetration_mm` into a flat surface
    /// through a spring of `spring_n_mm`, on a pair of effective modulus `modulus_mpa`
    /// (Hertz, Johnson's Contact Mechanics eq. 4.22-4.23: a = (3 F R / (4 E*))^(1/3),
    /// p0 = 3 F / (2 pi a^2)). None at zero or negative penetration.
    pub fn hertz(
        penetration_mm: f64,
        spring_n_mm: f64,
        ball_mm: f64,
        modulus_mpa: f64,
    ) -> Option<HertzContact> {
        if penetration_mm.is_nan() || penetration_mm <= 0.0 {
            return None;
        }
        let force_n = spring_n_mm * penetration_mm;
        let radius_mm = (3.0 * force_n * ball_mm / (4.0 * modulus_mpa)).cbrt();
        let peak_mpa = 3.0 * force_n / (2.0 * std::f64::consts::PI * radius_mm * radius_mm);
        Some(HertzContact {
            force_n,
            radius_mm,
            peak_mpa,
        })
    }

    /// Hertz pressure at distance `r_mm` from the patch centre, MPa (0 outside the patch).
    pub fn pressure(&self, r_mm: f64) -> f64 {
        let s = r_mm / self.radius_mm;
        if s >= 1.0 {
            0.0
        } else {
            self.peak_mpa * (1.0 - s * s).sqrt()
        }
    }
}

/// Preston's law with exponents, mm/s: `k p_ref v_ref (p / p_ref)^alpha (v / v_ref)^beta`,
/// which is the linear law `k p v` when both exponents are 1 (k in mm^2/N, p in MPa, v in
/// mm/s).
pub fn preston_rate(k: f64, pressure_mpa: f64, speed_mm_s: f64, cfg: &GrindConfig) -> f64 {
    if pressure_mpa <= 0.0 || speed_mm_s <= 0.0 {
        return 0.0;
    }
    let p = cfg.reference_pressure_mpa
        * (pressure_mpa / cfg.reference_pressure_mpa).powf(cfg.pressure_exponent);
    let v =
        cfg.reference_speed_mm_s * (speed_mm_s / cfg.reference_speed_mm_s).powf(cfg.speed_exponent);
    k * p * v
}

/// Plane waves summed in the k noise field: enough for an irregular pattern, few enough to
/// evaluate at every contact point every step.
const NOISE_WAVES: usize = 8;

/// The true Preston coefficient over the part: nominal k x factor x (1 + amplitude x s(x)),
/// s a smooth seeded field in [-1, 1] (a mean of plane waves of one wavelength in random
/// directions and phases, in the reference frame).
#[derive(Debug, Clone)]
pub struct KField {
    base: f64,
    amplitude: f64,
    waves: Vec<(Vector3<f64>, f64)>,
}

impl KField {
    /// The field of `cfg` (its seed, wavelength, amplitude, k and factor).
    pub fn new(cfg: &GrindConfig) -> KField {
        let mut state = cfg.seed;
        let mut uniform = || (splitmix64(&mut state) >> 11) as f64 / (1u64 << 53) as f64;
        let wavenumber = std::f64::consts::TAU / cfg.k_noise_wavelength_mm;
        let waves = (0..NOISE_WAVES)
            .map(|_| {
                // uniform direction on the sphere (Archimedes: z uniform, azimuth uniform)
                let z = 2.0 * uniform() - 1.0;
                let phi = std::f64::consts::TAU * uniform();
                let rho = (1.0 - z * z).sqrt();
                let dir = Vector3::new(rho * phi.cos(), rho * phi.sin(), z);
                (dir * wavenumber, std::f64::consts::TAU * uniform())
            })
            .collect();
        KField {
            base: cfg.preston_k * cfg.k_factor,
            amplitude: cfg.k_noise,
            waves,
        }
    }

    /// True k at `p` (reference frame, mm), mm^2/N.
    pub fn at(&self, p: &Point3<f64>) -> f64 {
        let s = self
            .waves
            .iter()
            .map(|(w, phase)| (w.dot(&p.coords) + phase).cos())
            .sum::<f64>()
            / NOISE_WAVES as f64;
        self.base * (1.0 + self.amplitude * s)
    }
}

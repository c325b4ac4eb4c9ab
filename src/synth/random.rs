//! Random draws shared by defect placement, outliers and the turntable's scanner model.
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// A standard normal sample (Box-Muller).
pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.gen::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

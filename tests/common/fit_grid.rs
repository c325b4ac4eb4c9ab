//! A flat grid of core points with two predicted removal bumps, the closed-form case of the
//! removal fit's tests (tests/calibrate_removal.rs, tests/removal_matching.rs).
use nalgebra::{Point3, Vector3};
use polishbot::motion::{Inspection, RegionInfo, SurfacePoint};
use polishbot::removal::fit::FitConfig;
use rand::{Rng, SeedableRng};

/// The plan's k in these cases, mm^2/N (the shipped tool.toml's).
pub const PLAN_K: f64 = 5e-6;
/// Grid spacing of the synthetic core points, mm.
pub const STEP: f64 = 0.25;
/// Grid half width in steps: 41 x 41 points over 10 x 10 mm.
pub const HALF: i64 = 20;

/// A region of the grid's inspection (`repairable` or a pit).
pub fn region(id: usize, repairable: bool) -> RegionInfo {
    serde_json::from_value(serde_json::json!({"id": id, "centroid": [0.0, 0.0, 0.0],
        "normal": [0.0, 0.0, 1.0], "area": 1.0, "peak": 0.2, "mean": 0.1, "volume": 1.0,
        "points": 1, "repairable": repairable}))
    .unwrap()
}

/// A flat grid with three regions by x (left: repairable 0, middle: repairable 1, right: a
/// pit, 2), a predicted removal bump p over both halves and the deviation before grinding
/// 0.05 mm above it; returns the inspection before and p per point.
pub fn before() -> (Inspection, Vec<f64>) {
    let mut points = Vec::new();
    let mut p = Vec::new();
    for i in -HALF..=HALF {
        for j in -HALF..=HALF {
            let (x, y) = (i as f64 * STEP, j as f64 * STEP);
            let bump = |cx: f64| 0.2 * (-((x - cx).powi(2) + y * y) / 4.0).exp();
            let removal = bump(-2.5) + bump(2.5);
            let region = match x {
                x if x < 0.0 => 0,
                x if x < 3.0 => 1,
                _ => 2,
            };
            points.push(SurfacePoint {
                position: Point3::new(x, y, 0.0),
                normal: Vector3::z(),
                distance: removal + 0.05,
                uncertainty: 0.0,
                region,
            });
            p.push(removal);
        }
    }
    let regions = vec![region(0, true), region(1, true), region(2, false)];
    let inspection = Inspection {
        dir: "before".into(),
        tolerance: Some(0.05),
        regions,
        points,
        fine: Vec::new(),
    };
    (inspection, p)
}

/// The inspection after a grind that removed `removed[i]` at each point.
pub fn after(before: &Inspection, removed: &[f64]) -> Inspection {
    let mut a = before.clone();
    for (pt, r) in a.points.iter_mut().zip(removed) {
        pt.distance -= r;
    }
    a
}

/// Points the fit should use: repairable, predicted at least the default threshold.
pub fn expected_used(b: &Inspection, p: &[f64]) -> Vec<usize> {
    let cfg = FitConfig::default();
    (0..p.len())
        .filter(|&i| b.points[i].region < 2 && p[i] >= cfg.min_predicted_mm)
        .collect()
}

/// The removal field `p` moved by `s` (mm, in the plane) and scaled by `scale`, plus Gaussian
/// noise of `sigma` mm: what a grind did whose tool landed `s` off its plan.
pub fn landed(b: &Inspection, scale: f64, s: [f64; 2], sigma: f64, seed: u64) -> Vec<f64> {
    landed_each(b, scale, [s, s], sigma, seed)
}

/// [`landed`] with the bump at x = -2.5 mm moved by `s[0]`, the one at +2.5 mm by `s[1]`.
pub fn landed_each(
    b: &Inspection,
    scale: f64,
    s: [[f64; 2]; 2],
    sigma: f64,
    seed: u64,
) -> Vec<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    b.points
        .iter()
        .map(|pt| {
            let bump = |cx: f64, s: [f64; 2]| {
                let (x, y) = (pt.position.x - s[0], pt.position.y - s[1]);
                0.2 * (-((x - cx).powi(2) + y * y) / 4.0).exp()
            };
            // Box-Muller
            let (u1, u2): (f64, f64) = (rng.gen_range(1e-12..1.0), rng.gen());
            let noise = sigma * (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            scale * (bump(-2.5, s[0]) + bump(2.5, s[1])) + noise
        })
        .collect()
}

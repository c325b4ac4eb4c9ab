//! Removal planning against a closed-form case: a flat plate with a Gaussian excess, a Hertz
//! footprint, dwell solved by the planner, and the predicted residual checked against an
//! independent numerical integration of Preston's law along the moving tool (written here
//! from the textbook formulas, not calling the planner's influence code).
use nalgebra::{Point3, Vector3};
use polishbot::plan::removal::{solve_region, Contact, Influence, RemovalConfig, ToolModel};
use polishbot::plan::SurfacePoint;

/// Ball radius of the shipped tool, mm.
const BALL_MM: f64 = 3.0;
/// Gaussian excess: height and width, mm.
const PEAK_MM: f64 = 0.3;
const SIGMA_MM: f64 = 1.2;
/// The plate's core points: a square grid of this pitch and half-width, mm.
const PITCH_MM: f64 = 0.1;
const HALF_MM: f64 = 4.0;
/// Raster half-width, mm: the excess is under 0.5 % of its peak past 3.9 sigma.
const RASTER_HALF_MM: f64 = 3.0;

fn plate() -> Vec<SurfacePoint> {
    let n = (2.0 * HALF_MM / PITCH_MM).round() as i32;
    let mut out = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let (x, y) = (
                -HALF_MM + i as f64 * PITCH_MM,
                -HALF_MM + j as f64 * PITCH_MM,
            );
            out.push(SurfacePoint {
                position: Point3::new(x, y, 0.0),
                normal: Vector3::z(),
                distance: PEAK_MM * (-(x * x + y * y) / (2.0 * SIGMA_MM * SIGMA_MM)).exp(),
                region: 0,
            });
        }
    }
    out
}

/// Zig-zag strokes along x, `stepover` apart, contact pieces `spacing` long; the spindle
/// leans toward +x.
fn raster(spacing: f64, stepover: f64) -> Vec<Contact> {
    let lines = (2.0 * RASTER_HALF_MM / stepover).floor() as i32;
    let per_line = (2.0 * RASTER_HALF_MM / spacing).floor() as i32;
    let mut out = Vec::new();
    for l in 0..=lines {
        let y = -RASTER_HALF_MM + l as f64 * stepover;
        let dir = if l % 2 == 0 { 1.0 } else { -1.0 };
        for k in 0..=per_line {
            let x = dir * (-RASTER_HALF_MM + k as f64 * spacing);
            out.push(Contact {
                point: Point3::new(x, y, 0.0),
                normal: Vector3::z(),
                along: Vector3::x() * dir,
                tilt_dir: Vector3::x(),
                length: spacing,
            });
        }
    }
    out
}

/// Preston's removal rate at surface point `p` under a tool whose contact patch is centred at
/// `c` on the plate z = 0, mm/s: Hertz pressure (Johnson, Contact Mechanics, eq. 4.22-4.23)
/// times the speed of the ball's surface, |omega x r| of the spinning ball.
fn preston_rate(tool: &ToolModel, c: &Point3<f64>, p: &Point3<f64>) -> f64 {
    let force = tool.spring_rate_n_mm * tool.preload_mm;
    let a = (3.0 * force * BALL_MM / (4.0 * tool.modulus_mpa)).powf(1.0 / 3.0);
    let p0 = 3.0 * force / (2.0 * std::f64::consts::PI * a * a);
    let rho2 = (p - c).norm_squared();
    if rho2 >= a * a {
        return 0.0;
    }
    let pressure = p0 * (1.0 - rho2 / (a * a)).sqrt();
    let omega_mag = tool.spindle_rpm / 60.0 * 2.0 * std::f64::consts::PI;
    let tilt = tool.tilt_deg * std::f64::consts::PI / 180.0;
    // spin axis leaning toward +x from the inward normal -z, through the ball centre above c
    let omega = Vector3::new(tilt.sin(), 0.0, -tilt.cos()) * omega_mag;
    let centre = c + Vector3::new(0.0, 0.0, BALL_MM);
    let velocity = omega.cross(&(p - centre));
    tool.preston_k_mm2_n * pressure * velocity.norm()
}

/// Removal at `p` of the whole program: each contact's tool moves at constant speed over its
/// piece during its dwell, integrated with `steps` midpoint steps per piece.
fn integrate(tool: &ToolModel, contacts: &[Contact], dwell: &[f64], p: &Point3<f64>) -> f64 {
    let steps = 64;
    let reach = 1.0 + contacts[0].length;
    contacts
        .iter()
        .zip(dwell)
        .filter(|(c, _)| (c.point - p).norm() < reach)
        .map(|(c, t)| {
            (0..steps)
                .map(|s| {
                    let f = (s as f64 + 0.5) / steps as f64 - 0.5;
                    let centre = c.point + c.along * (f * c.length);
                    preston_rate(tool, &centre, p) * t / steps as f64
                })
                .sum::<f64>()
        })
        .sum()
}

#[test]
fn gaussian_excess_on_a_plate_matches_an_independent_integration() {
    let tool = ToolModel::default();
    let influence = Influence::new(&tool, BALL_MM);
    let a = influence.patch_radius();
    assert!(a > 0.3 && a < 1.0, "patch radius {a} mm");
    let config = RemovalConfig::default();
    let cores = plate();
    let contacts = raster(config.spacing_share * a, config.stepover_share * a);
    let plan = solve_region(&influence, &contacts, &cores, 0.0, &config).expect("dwell");
    let residual = plan.residual();
    let mut worst_diff = 0.0f64;
    let (mut worst_inside, mut lowest) = (0.0f64, f64::INFINITY);
    for (j, c) in cores.iter().enumerate() {
        let removed = integrate(&tool, &contacts, &plan.dwell, &c.position);
        worst_diff = worst_diff.max((c.distance - removed - residual[j]).abs());
        let r = c.position.coords.xy().norm();
        if r < RASTER_HALF_MM - a {
            worst_inside = worst_inside.max(residual[j].abs());
        }
        lowest = lowest.min(residual[j]);
    }
    println!(
        "patch {a:.3} mm, {} contacts, dwell {:.1} s; |planner - integration| {worst_diff:.5} \
         mm, |residual| inside {worst_inside:.4} mm, lowest {lowest:.4} mm",
        contacts.len(),
        plan.dwell.iter().sum::<f64>()
    );
    assert!(
        worst_diff <= 0.02 * PEAK_MM,
        "predicted residual differs from the integration by {worst_diff} mm"
    );
    assert!(
        worst_inside < 0.05,
        "residual {worst_inside} mm over the raster"
    );
    assert!(lowest > -0.05, "over-ground to {lowest} mm");
    // the plan removes the excess: most of the peak is gone
    let centre = cores
        .iter()
        .position(|c| c.position.coords.norm() < 1e-9)
        .unwrap();
    assert!(
        residual[centre].abs() < 0.1 * PEAK_MM,
        "{}",
        residual[centre]
    );
}

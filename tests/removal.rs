//! Removal planning against a closed-form case: a flat plate with a Gaussian excess, a Hertz
//! footprint, dwell solved by the planner, and the predicted residual checked against an
//! independent numerical integration of Preston's law along the moving tool (written here
//! from the textbook formulas, not calling the planner's influence code).
mod common;

use nalgebra::{Point3, Vector3};
use polishbot::removal::force::{joint_torques, overload, DEFAULT_FORCE_SHARE};
use polishbot::removal::influence::Reach;
use polishbot::removal::montecarlo::{
    spread, tip_error, JointError, MonteCarloConfig, DEFAULT_TIP_ERROR_MM,
};
use polishbot::removal::{
    solve_region, targets, Contact, Influence, RegionRemoval, RemovalConfig, ToolModel,
};
use polishbot::repair::SurfacePoint;

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
/// Tolerance of the Monte Carlo test, mm: the demo's.
const TOLERANCE_MM: f64 = 0.05;

fn plate() -> Vec<SurfacePoint> {
    plate_of(SIGMA_MM)
}

/// The plate with a Gaussian excess of `PEAK_MM` and width `sigma` mm.
fn plate_of(sigma: f64) -> Vec<SurfacePoint> {
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
                distance: PEAK_MM * (-(x * x + y * y) / (2.0 * sigma * sigma)).exp(),
                uncertainty: 0.0,
                region: 0,
            });
        }
    }
    out
}

/// The spindle axis (shank to tip) tilted `tilt_deg` from the plate's inward normal -z,
/// leaning toward the azimuth `toward_deg` from +x.
fn spindle(tilt_deg: f64, toward_deg: f64) -> Vector3<f64> {
    let (t, a) = (tilt_deg.to_radians(), toward_deg.to_radians());
    Vector3::new(t.sin() * a.cos(), t.sin() * a.sin(), -t.cos())
}

/// The shipped tool's precession: 20 degrees, leaning toward +x.
fn leaning() -> Vector3<f64> {
    spindle(20.0, 0.0)
}

/// Zig-zag strokes along x, `stepover` apart, contact pieces `spacing` long; the spindle
/// held along `spin`.
fn raster(spacing: f64, stepover: f64, spin: Vector3<f64>) -> Vec<Contact> {
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
                spin,
                length: spacing,
                force_ratio: 1.0,
                offset: Vector3::zeros(),
                depth_mm: 2.0,
            });
        }
    }
    out
}

/// Preston's removal rate at surface point `p` under a tool whose contact patch is centred at
/// `c` on the plate z = 0, mm/s: Hertz pressure (Johnson, Contact Mechanics, eq. 4.22-4.23)
/// times the speed of the ball's surface, |omega x r| of the ball spinning about `spin`.
fn preston_rate(tool: &ToolModel, spin: &Vector3<f64>, c: &Point3<f64>, p: &Point3<f64>) -> f64 {
    let force = tool.spring_rate_n_mm * tool.preload_mm;
    let a = (3.0 * force * BALL_MM / (4.0 * tool.modulus_mpa)).powf(1.0 / 3.0);
    let p0 = 3.0 * force / (2.0 * std::f64::consts::PI * a * a);
    let rho2 = (p - c).norm_squared();
    if rho2 >= a * a {
        return 0.0;
    }
    let pressure = p0 * (1.0 - rho2 / (a * a)).sqrt();
    let omega_mag = tool.spindle_rpm / 60.0 * 2.0 * std::f64::consts::PI;
    // spin axis through the ball centre above c
    let omega = spin * omega_mag;
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
                    preston_rate(tool, &c.spin, &centre, p) * t / steps as f64
                })
                .sum::<f64>()
        })
        .sum()
}

/// The dwell solve asked to take every core point's whole excess (allowance and tolerance 0).
fn solve_whole(
    influence: &Influence,
    contacts: &[Contact],
    cores: &[SurfacePoint],
    config: &RemovalConfig,
) -> RegionRemoval {
    solve_region(
        influence,
        contacts,
        cores,
        &targets(cores, 0.0, 0.0),
        config,
    )
    .expect("dwell")
}

#[test]
fn gaussian_excess_on_a_plate_matches_an_independent_integration() {
    let tool = ToolModel::default();
    let influence = Influence::new(&tool, BALL_MM);
    let a = influence.patch_radius();
    assert!(a > 0.3 && a < 1.0, "patch radius {a} mm");
    let config = RemovalConfig::default();
    let cores = plate();
    let contacts = raster(
        config.spacing_share * a,
        config.stepover_share * a,
        leaning(),
    );
    let plan = solve_whole(&influence, &contacts, &cores, &config);
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

/// The per-contact spindle axis: the same plate planned with the spindle held at 0, 2, 20
/// and 45 degrees from the normal (leaning 30 degrees off the strokes, so the patch's own
/// axes are not the plate's), each prediction against the independent integration about
/// that axis. At 0 the pole does not cut and the rate peaks off centre; at 2 the centre runs
/// at a tenth of 20's speed; the planner's removal must follow the integration at every one.
#[test]
fn the_plate_at_every_spindle_tilt_matches_the_integration() {
    let tool = ToolModel::default();
    let influence = Influence::new(&tool, BALL_MM);
    let a = influence.patch_radius();
    let config = RemovalConfig::default();
    let cores = plate();
    let mut centre_rates = Vec::new();
    for tilt in [0.0, 2.0, 20.0, 45.0] {
        let spin = spindle(tilt, 30.0);
        let contacts = raster(config.spacing_share * a, config.stepover_share * a, spin);
        let plan = solve_whole(&influence, &contacts, &cores, &config);
        let (mut worst, mut most) = (0.0f64, 0.0f64);
        for (j, c) in cores.iter().enumerate() {
            let removed = integrate(&tool, &contacts, &plan.dwell, &c.position);
            worst = worst.max((removed - plan.removal[j]).abs());
            most = most.max(removed);
        }
        let rate = preston_rate(&tool, &spin, &Point3::origin(), &Point3::origin());
        println!(
            "tilt {tilt:>4} deg: most removed {most:.4} mm, |planner - integration| \
             {worst:.6} mm, centre rate {rate:.5} mm/s"
        );
        assert!(most > 0.0, "tilt {tilt}: nothing removed");
        assert!(worst <= 0.02 * most, "tilt {tilt}: {worst} mm of {most} mm");
        centre_rates.push(rate);
    }
    // the integration itself: the pole still at 0, omega R sin(tilt) at the others
    let sin = |deg: f64| deg.to_radians().sin();
    assert!(centre_rates[0] == 0.0);
    for (rate, tilt) in centre_rates[1..].iter().zip([2.0, 20.0, 45.0]) {
        assert!((rate / centre_rates[2] - sin(tilt) / sin(20.0)).abs() < 1e-9);
    }
}

/// A contact's spindle axis is the one the arm holds: the simulator's own forward kinematics
/// (sim::grind::fk, from DOFBOT.md's joint table, not the planner's k chain) at the piece's
/// first and last joint angles, averaged, turned into the reference frame by the inverse of
/// the workcell's rotation; the tilt it reports is that axis's angle from the inward normal.
#[test]
fn a_contacts_spindle_axis_is_the_arms_at_its_joint_angles() {
    use polishbot::motion::dwell::{contact, reference_from_robot};
    use polishbot::motion::{PlannedPass, PlannedPoint, StrokeKind};
    let robot = common::dofbot();
    let wc = polishbot::robot::Workcell::load(&common::calib("workcell.toml")).unwrap();
    let tip = robot.tool.tip_offset;
    let normal = Vector3::new(0.2, -0.9, 0.3).normalize();
    let point = |q: [f64; 5], x: f64| PlannedPoint {
        surface_mm: [x, -30.0, -20.0],
        normal: normal.into(),
        offset_mm: -2.0,
        tip_m: [0.0; 3],
        axis: [0.0; 3],
        q: q.to_vec(),
        landed_mm: None,
    };
    let (qa, qb) = ([0.1, 0.5, -0.7, -0.9, 0.3], [0.14, 0.47, -0.66, -0.95, 0.3]);
    let piece = PlannedPass {
        region: 0,
        layer: 0,
        kind: StrokeKind::Pass,
        feed_mm_s: 5.0,
        dwell_s: None,
        contact_normal: None,
        points: vec![point(qa, 1.0), point(qb, 1.2)],
    };
    let c = contact(&piece, &robot, &reference_from_robot(&wc));
    let r = wc
        .robot_from_reference
        .fixed_slice::<3, 3>(0, 0)
        .into_owned();
    let sim_axis = |q: [f64; 5]| polishbot::sim::grind::fk::tool(&q, &tip).1;
    let want = (r.transpose() * (sim_axis(qa) + sim_axis(qb))).normalize();
    assert!((c.spin - want).norm() < 1e-12, "{} vs {want}", c.spin);
    let (tilt, lean) = c.tilt();
    let angle = c.spin.angle(&-normal);
    assert!(
        (tilt.angle() - angle).abs() < 1e-12,
        "{} vs {angle}",
        tilt.angle()
    );
    assert!(lean.dot(&normal).abs() < 1e-12 && (lean.norm() - 1.0).abs() < 1e-12);
    println!("spindle {:.2} deg from the normal", angle.to_degrees());
}

/// The static torques J^T F against virtual work by central differences of the tool tip
/// (FK through k): tau_i = F . d tip / d q_i.
#[test]
fn joint_torques_match_virtual_work_and_overloads_name_the_joint() {
    let robot = common::dofbot();
    let q = [0.3, 0.4, -0.6, -0.5, 0.2];
    let force = Vector3::new(0.5, -1.0, 1.8);
    let tau = joint_torques(&robot, &q, &force);
    let h = 1e-6;
    for (i, t) in tau.iter().enumerate() {
        let (mut up, mut down) = (q, q);
        up[i] += h;
        down[i] -= h;
        let d = (robot.fk(&up).position - robot.fk(&down).position) / (2.0 * h);
        let want = d.dot(&force);
        assert!((t - want).abs() < 1e-6, "joint {i}: {t} vs {want}");
    }
    // the default tool's 2 N along the axis at this pose is held; 200 N is not, and the
    // refusal names the first joint past its share
    let axis = robot.fk(&q).axis;
    assert_eq!(
        overload(&robot, &q, &(-axis * 2.0), DEFAULT_FORCE_SHARE),
        None
    );
    let o = overload(&robot, &q, &(-axis * 200.0), DEFAULT_FORCE_SHARE).expect("overload");
    assert!(
        o.torque_nm > o.limit_nm && o.name.starts_with("arm_joint"),
        "{o:?}"
    );
    assert!((o.limit_nm - 0.5 * 1.47).abs() < 1e-12 || (o.limit_nm - 0.5 * 0.59).abs() < 1e-12);
}

/// Tip displacement per joint for the Monte Carlo tests: one joint moving the tip along +x by
/// 200 mm per rad (a 0.2 m lever), quantised at 0.05 degrees.
fn lever(n: usize) -> Vec<JointError> {
    let sensitivity = nalgebra::DMatrix::from_column_slice(3, 1, &[200.0, 0.0, 0.0]);
    let half_count = vec![0.025f64.to_radians()];
    vec![
        JointError {
            sensitivity,
            half_count,
        };
        n
    ]
}

#[test]
fn monte_carlo_without_errors_is_the_nominal_and_errors_make_it_over_grind() {
    let tool = ToolModel {
        preston_k_rel_sd: 0.0,
        ..ToolModel::default()
    };
    let influence = Influence::new(&tool, BALL_MM);
    let a = influence.patch_radius();
    let config = RemovalConfig::default();
    let cores = plate();
    let contacts = raster(
        config.spacing_share * a,
        config.stepover_share * a,
        leaning(),
    );
    let plan = solve_whole(&influence, &contacts, &cores, &config);
    let still = MonteCarloConfig {
        draws: 3,
        backlash_deg: 0.0,
        tip_error_mm: 0.0,
        ..MonteCarloConfig::default()
    };
    let mut joints = lever(contacts.len());
    for j in &mut joints {
        j.half_count = vec![0.0];
    }
    let geometry: Vec<_> = cores
        .iter()
        .map(|c| (c.position, c.normal, c.distance))
        .collect();
    let s = spread(
        &tool,
        BALL_MM,
        &contacts,
        &joints,
        &plan.dwell,
        &geometry,
        &still,
    );
    for draw in &s.draws {
        for (got, want) in draw.iter().zip(plan.residual()) {
            assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        }
    }
    // The tip error is the cell's record when it has one (tool.toml's verified_tip_error_mm,
    // written by calibrate verify), not the setting: a record of 0 mm under the default
    // setting (0.12 mm) draws the nominal, a record of 0.2 mm under a setting of 0 does not.
    let recorded = |mm: f64| ToolModel {
        verified_tip_error_mm: Some(mm),
        ..tool.clone()
    };
    let draw = |tool: &ToolModel, mc: &MonteCarloConfig| {
        let s = spread(
            tool,
            BALL_MM,
            &contacts,
            &joints,
            &plan.dwell,
            &geometry,
            mc,
        );
        let nominal = plan.residual();
        (s.draws.iter().flatten().zip(nominal.iter().cycle()))
            .map(|(got, want)| (got - want).abs())
            .fold(0.0f64, f64::max)
    };
    let setting = MonteCarloConfig {
        tip_error_mm: DEFAULT_TIP_ERROR_MM,
        ..still.clone()
    };
    assert!(draw(&recorded(0.0), &setting) < 1e-12);
    assert!(draw(&recorded(0.2), &still) > 1e-3);
    assert_eq!(tip_error(&recorded(0.2), &still).mm, 0.2);
    let fallback = tip_error(&tool, &setting);
    assert_eq!(fallback.mm, DEFAULT_TIP_ERROR_MM);
    assert!(fallback.source.contains("no calibrate verify record"));
    // 1 degree of backlash on a 0.2 m lever moves the patch up to 1.7 mm: the nominal plan
    // over-grinds beside the peak at the Monte Carlo's quantile (what makes the planner raise
    // a region's allowance: tests/removal_plan.rs), while the nominal residual does not
    let shaky = MonteCarloConfig::default();
    let moved = spread(
        &ToolModel::default(),
        BALL_MM,
        &contacts,
        &lever(contacts.len()),
        &plan.dwell,
        &geometry,
        &shaky,
    );
    let deepest = |low: Vec<f64>| low.iter().copied().fold(f64::INFINITY, f64::min);
    let nominal = deepest(plan.residual());
    let low = deepest(moved.low(shaky.quantile));
    println!("nominal lowest {nominal:.4} mm, deepest 5 % residual {low:.4} mm");
    assert!(nominal > -TOLERANCE_MM && low < -TOLERANCE_MM);
}

/// The Monte Carlo takes each contact's core points once, within twice its reach, and picks a
/// moved contact's column from them (`Reach::column_among`): the columns must be those of the
/// index's own radius query (`Reach::column`), value for value, for contacts moved up to half
/// the reach and for patches grown and shrunk by a changed force (`Contact::force_ratio`).
#[test]
fn columns_among_gathered_candidates_equal_the_direct_query() {
    let cores = plate();
    let geometry: Vec<_> = cores.iter().map(|c| (c.position, c.normal)).collect();
    let reach = Reach::new(&geometry);
    let tool = ToolModel::default();
    let a = Influence::new(&tool, BALL_MM).patch_radius();
    let contacts = raster(0.33 * a, 0.5 * a, leaning());
    let mut compared = 0;
    for (k, c) in contacts.iter().enumerate().step_by(7) {
        let gathered = reach.candidates(&c.point, 2.0 * (a + 0.5 * c.length));
        let influence = Influence::new(&tool, BALL_MM);
        for (shift, ratio) in [(0.0, 1.0), (0.2, 0.85), (0.3, 1.15)] {
            let angle = k as f64;
            let moved = Contact {
                point: c.point + Vector3::new(angle.cos(), angle.sin(), 0.0) * shift,
                force_ratio: ratio,
                ..*c
            };
            let mut direct = reach.column(&influence, &moved);
            let mut among = reach.column_among(&influence, &moved, &gathered);
            direct.sort_by_key(|e| e.0);
            among.sort_by_key(|e| e.0);
            assert!(!direct.is_empty());
            assert_eq!(
                direct, among,
                "contact {k} moved {shift} mm, force ratio {ratio}"
            );
            compared += direct.len();
        }
    }
    assert!(compared > 1000, "{compared} entries compared");
}

/// Lifting over what needs nothing: a narrow excess (sigma 0.5 mm) in the middle of the 6 mm
/// raster. Ground at every contact (`lift_share` 0), each contact passes at least at full feed
/// and the plate around the excess, with nothing to remove, is cut by that floor; with the
/// default `lift_share` the contacts far from the excess are lifted over (dwell 0), the kept
/// ones stay within their bounds, the floor is gone (by the independent integration) and
/// the excess is removed as well as before.
#[test]
fn contacts_that_need_nothing_are_lifted_over_and_the_floor_goes() {
    let tool = ToolModel::default();
    let influence = Influence::new(&tool, BALL_MM);
    let a = influence.patch_radius();
    let lifting = RemovalConfig::default();
    let grinding = RemovalConfig {
        lift_share: 0.0,
        ..RemovalConfig::default()
    };
    let cores = plate_of(0.5);
    let contacts = raster(
        lifting.spacing_share * a,
        lifting.stepover_share * a,
        leaning(),
    );
    let far = |p: &Point3<f64>| p.coords.norm() > 2.5;
    let mut floors = Vec::new();
    for config in [&grinding, &lifting] {
        let plan = solve_whole(&influence, &contacts, &cores, config);
        let t_min = contacts[0].length / config.feed_max_mm_s;
        let lifted = plan.lifted.iter().filter(|l| **l).count();
        for ((t, l), c) in plan.dwell.iter().zip(&plan.lifted).zip(&contacts) {
            match l {
                true => assert_eq!(*t, 0.0),
                false => assert!(*t >= t_min * (1.0 - 1e-9), "{t} < {t_min} at {:?}", c.point),
            }
        }
        let floor = cores
            .iter()
            .filter(|c| far(&c.position) && c.position.coords.abs().max() < RASTER_HALF_MM)
            .map(|c| integrate(&tool, &contacts, &plan.dwell, &c.position))
            .fold(0.0f64, f64::max);
        let centre = plan.residual()[cores.len() / 2];
        println!(
            "lift_share {}: {lifted} of {} contacts lifted, removal away from the excess \
             {floor:.5} mm, residual at the centre {centre:.4} mm",
            config.lift_share,
            contacts.len()
        );
        assert!(centre.abs() < 0.1 * PEAK_MM, "{centre}");
        floors.push((lifted, floor));
    }
    assert_eq!(floors[0].0, 0, "lift_share 0 lifted contacts");
    assert!(floors[1].0 > contacts.len() / 2, "{floors:?}");
    // 0.0019 mm at the 20 mm/s feed; the joints allow about 2.8 mm/s on the cycle's cases,
    // seven times that floor
    assert!(floors[0].1 > 0.001, "no floor without lifting: {floors:?}");
    assert!(floors[1].1 < 0.1 * floors[0].1, "{floors:?}");
}

/// The LoD95 guard (issue 50: "no plan removes at a point that is not above the tolerance by
/// more than its measurement uncertainty"), closed form: a plate 0.08 mm high everywhere at a
/// tolerance of 0.05 mm, its left half (x < 0) measured with an uncertainty of 0.04 mm
/// (0.08 - 0.04 < 0.05: not proven out of tolerance), its right half with 0.01 mm (0.07 >
/// 0.05: proven). The target is 0.08 mm on the right and 0 on the left; the tool lifts over
/// the left half, so the removal there is exactly 0 farther than a patch and a piece from
/// the halves' border, while the right half is taken down to nominal. Without the guard the
/// left half would be ground like the right.
#[test]
fn no_removal_where_the_excess_is_within_its_uncertainty_of_the_tolerance() {
    let tool = ToolModel::default();
    let influence = Influence::new(&tool, BALL_MM);
    let config = RemovalConfig::default();
    let (height, tolerance) = (0.08, TOLERANCE_MM);
    let cores: Vec<SurfacePoint> = plate()
        .into_iter()
        .map(|c| SurfacePoint {
            distance: height,
            uncertainty: if c.position.x < 0.0 { 0.04 } else { 0.01 },
            ..c
        })
        .collect();
    let r = targets(&cores, 0.0, tolerance);
    for (c, r) in cores.iter().zip(&r) {
        assert_eq!(*r, if c.position.x < 0.0 { 0.0 } else { height });
    }
    let a = influence.patch_radius();
    let contacts = raster(
        config.spacing_share * a,
        config.stepover_share * a,
        leaning(),
    );
    let plan = solve_region(&influence, &contacts, &cores, &r, &config).expect("dwell");
    let border = a + config.spacing_share * a + 0.5;
    let (mut left_max, mut right) = (0.0f64, Vec::new());
    for (c, removed) in cores.iter().zip(&plan.removal) {
        let p = c.position;
        if p.x < -border {
            left_max = left_max.max(*removed);
        } else if p.x > border && p.x < 2.5 && p.y.abs() < 2.5 {
            right.push(*removed);
        }
    }
    assert_eq!(left_max, 0.0, "removal on the guarded half");
    let mean = right.iter().sum::<f64>() / right.len() as f64;
    assert!(
        (mean - height).abs() < 0.1 * height,
        "mean removal {mean} mm on the proven half, target {height} mm"
    );
    // Without the guard (targets at a tolerance of 0 and no uncertainty) the left half is
    // ground like the right.
    let bare = targets(&cores, 0.0, 0.0);
    let plan = solve_region(&influence, &contacts, &cores, &bare, &config).expect("dwell");
    let left: Vec<f64> = (cores.iter().zip(&plan.removal))
        .filter(|(c, _)| c.position.x < -border && c.position.x > -2.5)
        .filter(|(c, _)| c.position.y.abs() < 2.5)
        .map(|(_, r)| *r)
        .collect();
    let mean = left.iter().sum::<f64>() / left.len() as f64;
    assert!(
        mean > 0.5 * height,
        "unguarded mean removal {mean} mm on the left half"
    );
}

//! `calibrate turntable` (issue 33): the tool tip touches one fiducial on the table at several
//! table angles on the simulated arm (1-count read noise); the plane and circle fit recover a
//! planted axis and centre; bad inputs and bad fits are refused with the reason.
mod common;

use nalgebra::{Point3, Rotation3, Unit, UnitQuaternion, Vector3};
use polishbot::bus::{Bus, BusConfig, Journal};
use polishbot::calibrate::jog::{Cell, Scripted, Touch};
use polishbot::calibrate::turntable::{fit_turntable, patch_workcell, turntable};
use polishbot::calibrate::{CalibError, CalibrationConfig};
use polishbot::motion::frames;
use polishbot::robot::{IkConfig, IkTarget, Robot, Turntable, Workcell};
use polishbot::sim::{Mechanics, SimArm, SimOptions};

/// The planted table: an axis tilted off robot x and its centre, metres.
fn planted() -> (Unit<Vector3<f64>>, Point3<f64>) {
    (
        Unit::new_normalize(Vector3::new(1.0, 0.03, -0.02)),
        Point3::new(0.004, 0.28, 0.24),
    )
}

/// Radius of the fiducial's circle about the axis, metres.
const RADIUS: f64 = 0.05;

/// The fiducial at table angle `deg` (degrees), robot frame.
fn fiducial(deg: f64) -> Vector3<f64> {
    let (axis, c) = planted();
    let r0 = axis.cross(&Vector3::z()).normalize().cross(&axis) * RADIUS;
    let turned = UnitQuaternion::from_axis_angle(&axis, deg.to_radians()) * r0;
    c.coords + turned
}

/// Joints that put the tool tip on `p` (the arm's own closed-form IK; the truth is the
/// planted circle, not this).
fn reach(robot: &Robot, p: Vector3<f64>) -> [f64; 5] {
    // tool axes from slightly up through level to down and back; the first pose clear of
    // every joint limit by 0.02 rad (a noisy read at a servo's end count may land past it)
    for k in 0..12 {
        let tilt = -0.6 + 0.3 * f64::from(k);
        let target = IkTarget {
            position: p,
            axis: Vector3::new(0.0, tilt.cos(), -tilt.sin()),
            roll: Some(0.0),
        };
        if let Ok(s) = robot.ik(&target, &[0.0; 5], &IkConfig::default()) {
            if robot.limit_violation(&s.q, -0.02).is_none() {
                return s.q.try_into().unwrap();
            }
        }
    }
    panic!("the arm reaches no pose at {p:?}");
}

/// `polishbot calibrate ROUTINE --sim --cell calibration/turntable`.
fn on_the_table_cell(routine: &str) -> std::process::Command {
    let mut cmd = common::polishbot();
    cmd.args(["calibrate", routine, "--sim", "--cell"])
        .arg(common::calib("turntable"));
    cmd
}

/// One line of a joint targets file.
fn target_line(q: &[f64; 5]) -> String {
    let v: Vec<String> = q.iter().map(|x| format!("{x:?}")).collect();
    v.join(", ") + "\n"
}

fn sim_bus(robot: &Robot) -> (SimArm, Bus<polishbot::sim::SimTransport>) {
    let cfg = BusConfig {
        servo_map: frames::servo_map(robot).unwrap(),
        ..BusConfig::default()
    };
    let options = SimOptions {
        mechanics: Mechanics {
            read_noise_counts: 1,
            noise_seed: 33,
            ..Mechanics::default()
        },
        ..SimOptions::default()
    };
    let arm = SimArm::new(&options, &cfg.servo_map).unwrap();
    let bus = Bus::connect(arm.transport(), cfg, Journal::none()).unwrap();
    (arm, bus)
}

/// Touches at nine table angles over 240 degrees on the simulated arm (+-1 count read noise)
/// recover the planted axis within 0.2 degree and the centre within 0.3 mm; the fit written
/// into the shipped turntable cell's workcell.toml keeps every comment and loads back.
#[test]
fn the_sim_recovers_a_planted_axis_and_centre() {
    let robot = common::dofbot();
    let angles = [-120.0, -90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0, 120.0];
    let targets: Vec<[f64; 5]> = angles.iter().map(|&a| reach(&robot, fiducial(a))).collect();
    let (_arm, mut bus) = sim_bus(&robot);
    let map = bus.config().servo_map.clone();
    let cfg = CalibrationConfig::default();
    let cell = Cell {
        robot: &robot,
        map: &map,
        gripper_deg: 90.0,
        cfg: &cfg,
    };
    let mut turned = Vec::new();
    let mut turn = |_: &mut Bus<_>, a: f64| -> Result<(), CalibError> {
        turned.push(a);
        Ok(())
    };
    let mut source = Scripted::new(targets);
    let fit = turntable(&mut bus, &cell, &angles, &mut turn, &mut source).unwrap();
    assert_eq!(turned, angles);
    let (axis, centre) = planted();
    let tilt = Vector3::from(fit.axis).angle(&axis).to_degrees();
    let off = (Point3::from(fit.centre) - centre).norm() * 1000.0;
    println!(
        "axis off by {tilt:.3} deg, centre by {off:.3} mm, radius {:.2} mm, RMS {:.3} mm",
        fit.radius_mm, fit.rms_mm
    );
    assert!(tilt < 0.2, "axis off by {tilt} deg");
    assert!(off < 0.3, "centre off by {off} mm");
    assert!((fit.radius_mm - RADIUS * 1000.0).abs() < 0.3);

    let shipped = common::calib("turntable/workcell.toml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    let patched = patch_workcell(&text, &fit);
    for line in text.lines().filter(|l| l.trim_start().starts_with('#')) {
        assert!(patched.contains(line), "comment lost: {line}");
    }
    let dir = common::tempdir();
    std::fs::write(dir.path().join("workcell.toml"), &patched).unwrap();
    let table = Turntable::load(
        &common::calib("turntable/servos.toml"),
        &dir.path().join("workcell.toml"),
    )
    .unwrap()
    .unwrap();
    assert!((table.axis.into_inner() - Vector3::from(fit.axis)).norm() < 1e-12);
    assert_eq!(table.centre, Point3::from(fit.centre));
}

fn touch(p: Vector3<f64>) -> Touch {
    Touch {
        label: "t".into(),
        joints: [0.0; 5],
        tip: p.into(),
    }
}

/// Too few angles, angles spanning too little, and a touch that missed the fiducial are
/// refused, each with its reason.
#[test]
fn bad_turntable_fits_are_refused_with_the_reason() {
    let cfg = CalibrationConfig::default();
    let err = |angles: &[f64], moved: Option<(usize, f64)>| {
        let touches = angles
            .iter()
            .enumerate()
            .map(|(i, &a)| {
                let shift = moved.filter(|m| m.0 == i).map_or(0.0, |m| m.1);
                touch(fiducial(a) + Vector3::new(0.0, 0.0, shift))
            })
            .collect();
        fit_turntable(angles, touches, &cfg)
            .unwrap_err()
            .to_string()
    };
    let few = err(&[0.0, 30.0, 60.0, 90.0], None);
    assert!(few.contains("need at least 5"), "{few}");
    let short = err(&[0.0, 10.0, 20.0, 30.0, 40.0], None);
    assert!(short.contains("span 40.0 deg"), "{short}");
    let missed = err(&[-60.0, -30.0, 0.0, 30.0, 60.0, 90.0], Some((2, 0.005)));
    assert!(missed.contains("RMS residual"), "{missed}");
    // exact touches fit exactly
    let angles = [-60.0, -30.0, 0.0, 30.0, 60.0, 90.0];
    let touches = angles.iter().map(|&a| touch(fiducial(a))).collect();
    let fit = fit_turntable(&angles, touches, &cfg).unwrap();
    assert!(fit.rms_mm < 1e-9, "{}", fit.rms_mm);
}

/// Degenerate touches (issue 52) are refused with the reason: five touches at one point
/// (radius 0), touches over 1.2 degrees of arc for 120 degrees of table, and the angles listed
/// in another order than the touches (which flipped the axis silently).
#[test]
fn degenerate_turntable_touches_are_refused_with_the_reason() {
    let cfg = CalibrationConfig::default();
    let angles = [-60.0, -30.0, 0.0, 30.0, 60.0];
    let fit = |angles: &[f64], at: &dyn Fn(f64) -> Vector3<f64>, listed: &[f64]| {
        let touches = angles.iter().map(|&a| touch(at(a))).collect();
        fit_turntable(listed, touches, &cfg)
    };
    let one = fit(&angles, &|_| fiducial(0.0), &angles)
        .unwrap_err()
        .to_string();
    assert!(
        one.contains("radius") && one.contains("need at least 10 mm"),
        "{one}"
    );
    let tiny = fit(&angles, &|a| fiducial(a / 100.0), &angles)
        .unwrap_err()
        .to_string();
    assert!(tiny.contains("did not turn with the table"), "{tiny}");
    let swapped = [-60.0, 0.0, -30.0, 30.0, 60.0];
    let order = fit(&angles, &fiducial, &swapped).unwrap_err().to_string();
    assert!(order.contains("not in the order of the touches"), "{order}");
    // the same touches in their own order fit, with the planted axis's sign
    let good = fit(&angles, &fiducial, &angles).unwrap();
    assert!(
        Vector3::from(good.axis).dot(&planted().0) > 0.999,
        "{:?}",
        good.axis
    );
}

/// `calibrate turntable --sim --cell calibration/turntable --targets FILE`: the table turns to
/// each angle (0x19 frames for servo 7), the scripted touches find the planted circle, and
/// workcell.toml in --out gets the fitted axis and centre; too few angles are refused before
/// the arm is opened, with one line.
#[test]
fn calibrate_turntable_on_the_cli_writes_the_fitted_axis_and_centre() {
    let robot = common::dofbot();
    let angles = [-120.0, -90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0, 120.0];
    let dir = common::tempdir();
    let targets = dir.path().join("targets.txt");
    let mut text = String::from("# joint targets, rad, one per table angle\n");
    for &a in &angles {
        text.push_str(&target_line(&reach(&robot, fiducial(a))));
    }
    std::fs::write(&targets, text).unwrap();
    let list: Vec<String> = angles.iter().map(|a| a.to_string()).collect();
    let out = dir.path().join("cell");
    common::succeed(
        on_the_table_cell("turntable")
            .arg("--out")
            .arg(&out)
            .arg("--targets")
            .arg(&targets)
            .arg(format!("--angles={}", list.join(","))),
    );
    let table = Turntable::load(
        &common::calib("turntable/servos.toml"),
        &out.join("workcell.toml"),
    )
    .unwrap()
    .unwrap();
    let (axis, centre) = planted();
    assert!(table.axis.angle(&axis).to_degrees() < 0.2);
    assert!((table.centre - centre).norm() * 1000.0 < 0.3);
    let few = on_the_table_cell("turntable")
        .arg("--out")
        .arg(&out)
        .args(["--angles", "0,10,20"])
        .output()
        .unwrap();
    assert!(common::one_line_failure(&few).contains("need at least 5"));
}

/// `calibrate workcell --sim --cell calibration/turntable`: touching four fiducials placed by
/// the shipped turntable workcell rewrites `robot_from_reference` (it reads back within 1 mm
/// and 0.5 degree of the shipped placement, as tests/calibrate.rs) and keeps the `[turntable]`
/// section, its comments and the axis and centre the table loads with, unchanged.
#[test]
fn calibrate_workcell_on_a_turntable_cell_keeps_the_turntable() {
    let cell = |name: &str| common::calib(&format!("turntable/{name}"));
    let robot = Robot::load(
        &cell("dofbot.urdf"),
        &cell("tool.toml"),
        &cell("servos.toml"),
    )
    .unwrap();
    let shipped = Workcell::load(&cell("workcell.toml")).unwrap();
    // fiducials on the part's arm-facing side (part -y), reference frame, mm
    let fiducials = [
        [20.0, -30.0, 15.0],
        [-20.0, -30.0, 15.0],
        [0.0, -30.0, -20.0],
        [15.0, -20.0, -25.0],
    ];
    let dir = common::tempdir();
    let mut fixture = String::new();
    let mut targets = String::new();
    for (k, p) in fiducials.iter().enumerate() {
        fixture.push_str(&format!(
            "[[fiducial]]\nname = \"F{k}\"\nposition = [{:?}, {:?}, {:?}]\n",
            p[0], p[1], p[2]
        ));
        let at = shipped.point_from_reference_mm(&Point3::from(*p));
        targets.push_str(&target_line(&reach(&robot, at.coords)));
    }
    std::fs::write(dir.path().join("fixture.toml"), fixture).unwrap();
    std::fs::write(dir.path().join("targets.txt"), targets).unwrap();
    let out = dir.path().join("cell");
    common::succeed(
        on_the_table_cell("workcell")
            .arg("--out")
            .arg(&out)
            .arg("--fixture")
            .arg(dir.path().join("fixture.toml"))
            .arg("--targets")
            .arg(dir.path().join("targets.txt")),
    );
    let written = out.join("workcell.toml");
    let w = Workcell::load(&written).unwrap();
    let (a, b) = (w.robot_from_reference, shipped.robot_from_reference);
    let moved = (a.fixed_slice::<3, 1>(0, 3) - b.fixed_slice::<3, 1>(0, 3)).norm() * 1000.0;
    let r = a.fixed_slice::<3, 3>(0, 0).transpose() * b.fixed_slice::<3, 3>(0, 0);
    let turned = Rotation3::from_matrix_unchecked(r).angle().to_degrees();
    println!("workcell: {moved:.3} mm, {turned:.4} deg off the shipped placement");
    // as tests/calibrate.rs: count quantisation of the touches leaves tenths of a mm
    assert!(moved < 1.0 && turned < 0.5, "{moved} mm, {turned} deg");
    let text = std::fs::read_to_string(&written).unwrap();
    assert!(text.starts_with("# Written by `polishbot calibrate workcell`"));
    let old = std::fs::read_to_string(cell("workcell.toml")).unwrap();
    let from = old.find("# The part turntable").unwrap();
    assert!(
        text.ends_with(&old[from..]),
        "[turntable] not kept:\n{text}"
    );
    let want = Turntable::load(&cell("servos.toml"), &cell("workcell.toml"))
        .unwrap()
        .unwrap();
    let got = Turntable::load(&cell("servos.toml"), &written)
        .unwrap()
        .unwrap();
    assert_eq!((got.axis, got.centre), (want.axis, want.centre));
}

/// `calibrate verify --sim --cell calibration/turntable` (+-1 count read noise) turns the
/// table to each default check angle, commanding the raw count of DOFBOT.md's 270-degree servo
/// scale (0..270 deg on raw 380..3700, zero at 135 deg) and reading it back within the noise;
/// each error is reported in counts and in degrees (0.0813 deg a count, the commanded count's
/// rounding included). With a tolerance of 0
/// counts the same noise fails verify with one line; an angle outside the table's range is
/// refused before anything moves, naming the config key.
#[test]
fn calibrate_verify_turns_the_table_and_reports_its_read_back_error() {
    let dir = common::tempdir();
    let verify = |name: &str, extra: &str| {
        let config = dir.path().join(name);
        let text = format!("[sim.mechanics]\nread_noise_counts = 1\nnoise_seed = 7\n{extra}");
        std::fs::write(&config, text).unwrap();
        // --out: verify writes its measured tip error into a tool.toml; never the shipped cell's
        on_the_table_cell("verify")
            .arg("--config")
            .arg(&config)
            .arg("--out")
            .arg(dir.path())
            .output()
            .unwrap()
    };
    let ok = verify("ok.toml", "");
    let stdout = String::from_utf8_lossy(&ok.stdout).to_string();
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let lines: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("calibrate verify: table "))
        .collect();
    let angles = [-90.0, -30.0, 30.0, 90.0, 0.0];
    assert_eq!(lines.len(), angles.len(), "{stdout}");
    let per_count = 270.0 / (3700.0 - 380.0);
    for (line, a) in lines.iter().zip(angles) {
        println!("{line}");
        let words: Vec<&str> = line.split_whitespace().collect();
        let num = |i: usize| -> f64 {
            words[i]
                .trim_matches(|c| "()+:".contains(c))
                .parse()
                .unwrap()
        };
        assert_eq!(num(3), a, "{line}");
        let exact = 380.0 + (135.0 + a) / 270.0 * 3320.0_f64;
        assert_eq!(num(6), exact.round(), "{line}");
        let (counts, deg) = (num(9), num(11));
        assert!(counts.abs() <= 1.0, "{line}");
        // degrees: the mean read-back's angle, so the commanded count's rounding is in them
        let want = (exact.round() + counts - exact) * per_count;
        assert!((deg - want).abs() < 0.002, "{line}: want {want:.4} deg");
    }
    assert!(
        stdout.contains("calibrate verify: worst table error "),
        "{stdout}"
    );
    assert!(
        stdout.contains("calibrate verify: worst servo error"),
        "{stdout}"
    );

    // (config file, its [calibrate] lines, what the one-line failure names)
    let refused = [
        (
            "strict.toml",
            "max_verify_table_error_counts = 0",
            ["table read-back error", "above 0 counts"],
        ),
        (
            "far.toml",
            "verify_table_angles_deg = [0.0, 200.0]",
            ["verify_table_angles_deg", "outside"],
        ),
    ];
    for (name, setting, words) in refused {
        let line = common::one_line_failure(&verify(name, &format!("[calibrate]\n{setting}\n")));
        assert!(words.iter().all(|w| line.contains(w)), "{line}");
    }
}

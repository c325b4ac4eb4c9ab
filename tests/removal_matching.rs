//! Where a grind really removed, core point by core point (`removal::matching`,
//! `cell::removal_shift`): a removal landed beside its plan registered and carried, and a
//! densified point of the inspection before read from the core points measured around it.
mod common;

use common::fit_grid::{after, before, expected_used, landed, landed_each, PLAN_K, STEP};
use nalgebra::{Point3, Vector3};
use polishbot::motion::SurfacePoint;
use polishbot::removal::fit::{fit, FitConfig, GrindPair};

#[test]
fn a_removal_landed_beside_its_plan_is_registered_and_k_is_fitted_after_the_shift() {
    use polishbot::cell::removal_shift::{carry, register, shifted_prediction, ShiftConfig};
    use polishbot::motion::aim::Aim;
    let (b, p) = before();
    let cfg = ShiftConfig::default();
    // 0.3 mm along x, -0.2 along y, the tool 1.3 x faster than planned, the rescan's noise
    let a = after(&b, &landed(&b, 1.3, [0.3, -0.2], 0.015, 5));
    let shifts = register(&GrindPair::new(&b, &a), &p, &cfg);
    assert_eq!(shifts.len(), 2, "{shifts:?}");
    for r in &shifts {
        let e = (r.shift_mm - Vector3::new(0.3, -0.2, 0.0)).norm();
        assert!(
            e <= 0.11,
            "region {}: shift {} off by {e} mm",
            r.region,
            r.shift_mm
        );
        assert!((r.scale - 1.3).abs() < 0.05 * 1.3, "{r:?}");
        assert!(r.rms_mm[1] < 0.02 && r.rms_mm[0] > r.rms_mm[1], "{r:?}");
    }
    // carried into the next plan: each region's shift, the cell-wide one their mean
    let next = carry(&shifts, &Aim::default(), &cfg).expect("consistent shifts are carried");
    let common = Vector3::from(next.aim.common_mm);
    assert!(
        (common - Vector3::new(0.3, -0.2, 0.0)).norm() <= 0.11,
        "{common}"
    );
    assert_eq!(next.aim.regions.len(), 2);
    assert!(
        next.regions.iter().all(|r| r.measured_mm.is_some()),
        "{next:?}"
    );
    assert_eq!(
        next.aim.first_pass_share, None,
        "a shift is known: no first-pass cap"
    );
    // k on the prediction as planned reads the misplaced removal as a slower tool; moved by
    // the measured shift it finds the tool's 1.3 x
    let fit_k =
        |pred: &[f64]| fit(&GrindPair::new(&b, &a), pred, PLAN_K, &FitConfig::default()).unwrap();
    let plain = fit_k(&p).k_mm2_n / PLAN_K;
    let moved = fit_k(&shifted_prediction(&b, &p, &shifts, &cfg)).k_mm2_n / PLAN_K;
    assert!(
        (moved - 1.3).abs() < 0.03 * 1.3,
        "moved {moved} plain {plain}"
    );
    assert!(plain < moved - 0.02, "moved {moved} plain {plain}");
    // 0.8 mm off in both regions: carried (the next plan aims back by it) ...
    let far = after(&b, &landed(&b, 1.0, [0.8, 0.0], 0.015, 6));
    let far = register(&GrindPair::new(&b, &far), &p, &cfg);
    let next = carry(&far, &Aim::default(), &cfg).expect("one arm error, carried");
    let common = Vector3::from(next.aim.common_mm);
    assert!(
        (common - Vector3::new(0.8, 0.0, 0.0)).norm() <= 0.11,
        "{common}"
    );
    // ... but not on top of 1.8 mm already carried: 2.6 mm is over what the plan aims back by
    let carried = Aim {
        common_mm: [1.8, 0.0, 0.0],
        ..Aim::default()
    };
    let why = carry(&far, &carried, &cfg).expect_err("a stop");
    assert!(
        why.starts_with("region 0: the removal landed 0.8") && why.contains("over the 2.4 mm"),
        "{why}"
    );
    // the two regions landed 2.8 mm apart (1.4 mm off along -y and +y): each 1.4 mm from the
    // cell-wide shift, over the 1.2 mm bound: not one arm error, the loop stops naming one
    let apart = after(
        &b,
        &landed_each(&b, 1.0, [[0.0, -1.4], [0.0, 1.4]], 0.015, 7),
    );
    let apart = register(&GrindPair::new(&b, &apart), &p, &cfg);
    let why = carry(&apart, &Aim::default(), &cfg).expect_err("a stop");
    assert!(
        why.starts_with("region ") && why.contains("regions may disagree"),
        "{why}"
    );
    // regions ground too little to measure (0.03 mm at most) keep the shift carried to them
    let small: Vec<f64> = p.iter().map(|v| 0.15 * v).collect();
    let faint = after(&b, &landed(&b, 0.15, [0.8, 0.0], 0.015, 8));
    let faint = register(&GrindPair::new(&b, &faint), &small, &cfg);
    let carried = Aim {
        common_mm: [0.5, 0.0, 0.0],
        ..Aim::default()
    };
    let next = carry(&faint, &carried, &cfg).expect("nothing measured: nothing to stop on");
    assert_eq!(next.regions.len(), 2, "{next:?}");
    for r in &next.regions {
        assert_eq!(r.measured_mm, None, "{r:?}");
        assert!((Vector3::from(r.carried_mm) - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-9);
    }
}

#[test]
fn a_densified_point_reads_the_removal_measured_around_it() {
    let (mut b, mut p) = before();
    let bump = |x: f64, y: f64| 0.2 * (-((x + 2.5).powi(2) + y * y) / 4.0).exp();
    // two points only the first inspection has (its densification around a defect): one
    // between the grid's points near the bump's top, one facing the other way (a thin wall's
    // far side), which reads nothing around it
    let (x, y) = (-2.5 + STEP / 2.0, STEP / 2.0);
    let added = b.points.len();
    for normal in [Vector3::z(), -Vector3::z()] {
        b.points.push(SurfacePoint {
            position: Point3::new(x, y, 0.0),
            normal,
            distance: bump(x, y) + 0.05,
            uncertainty: 0.0,
            region: 0,
        });
        p.push(bump(x, y));
    }
    let grid: Vec<f64> = p[..added].iter().map(|v| 1.3 * v).collect();
    let mut a = after(&b, &grid);
    a.points.truncate(added);
    let pair = GrindPair::new(&b, &a);
    assert_eq!(pair.removal(added), None);
    let read = pair.removal_near(added).expect("read around it");
    // the inverse-distance mean of a smooth field over points 0.18 mm away
    assert!((read - 1.3 * bump(x, y)).abs() < 2e-3, "{read}");
    assert_eq!(pair.removal_near(added + 1), None);
    // the fit takes the one read around it and counts the other unmatched
    let f = fit(&pair, &p, PLAN_K, &FitConfig::default()).unwrap();
    assert_eq!(f.unmatched, 1);
    assert_eq!(f.points, expected_used(&b, &p).len() - 1);
}

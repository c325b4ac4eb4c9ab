//! Removal mode end to end through the CLI on the demo part: the predicted part meets the
//! tolerance (issue 28's acceptance) where it grinds, every contact is entered touching the surface
//! and pressed in to the tool's preload under the grinding rule only, and the collision re-check
//! `run` makes accepts the preload exactly where the plan grinds.
mod common;

use std::path::Path;

use common::polishbot;
use common::removal::TOLERANCE_MM;
use nalgebra::{Point3, Vector3};
use polishbot::motion::{
    collide, plan_part, CollisionConfig, Inspection, Plan, PlanConfig, PlanError, RegionInfo,
    SegmentKind, SurfacePoint,
};
use polishbot::removal::ALLOWANCE_STEP_SHARE;
use polishbot::robot::Workcell;

/// The shipped tool.toml's preload, mm.
const PRELOAD_MM: f64 = 2.0;
/// A test patch's plateau under its bump, mm: excess everywhere on the region.
const PLATEAU_MM: f64 = 0.06;
/// The bump of the out-of-reach test, mm (0.16 mm peak with the plateau).
const LOW_MM: f64 = 0.1;
/// A bump that over-grinds at the Monte Carlo's quantile with the default allowance (0 mm), mm:
/// with the shipped k uncertainty the 5 % quantile removes 1.47x the nominal, so its 0.31 mm
/// peak ground to nominal is cut about 0.15 mm too deep there (docs/ALGORITHMS.md, "What one
/// pass can promise").
const TALL_MM: f64 = 0.25;

#[test]
fn removal_contacts_are_pressed_in_and_out_only_under_the_grinding_rule() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("removal_plan");
    let _ = std::fs::remove_dir_all(&dir);
    let d = |f: &str| dir.join(f).display().to_string();
    // the demo part (five defects where the arm reaches), planned again in removal mode
    common::succeed(polishbot().args(["demo", "--out", &d("")]));
    let out = common::succeed(polishbot().args([
        "plan",
        "--mode",
        "removal",
        "--inspection",
        &d("inspection"),
        "-o",
        &d("plan.json"),
    ]));
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let plan = Plan::load(&dir.join("plan.json")).unwrap();
    let removal = plan.removal.as_ref().expect("a removal report");
    assert_eq!(removal.preload_mm, PRELOAD_MM);
    // every repairable region of the demo planned (its four bumps and ridges; the fifth
    // defect is a pit); a contact left out is one of a region the removal planner left out
    // (it over-grinds at the Monte Carlo's quantile), or one the collision check refused: the
    // demo's region 3 has 4 of its 103 path points next to a face 67 degrees away, where the
    // ball pressed by the preload does not fit on the retract ("tool does not fit"); under the
    // rim guard 2 of them, refused on the way in to a stroke ("no collision-free way in")
    assert!(
        removal.regions.len() >= 4,
        "{} regions",
        removal.regions.len()
    );
    let planned: Vec<usize> = removal.regions.iter().map(|r| r.region).collect();
    let mut refused = 0;
    for u in &plan.reachability.unreachable {
        if planned.contains(&u.region) {
            let collision = ["tool does not fit", "no collision-free way in"];
            assert!(collision.iter().any(|c| u.reason.contains(c)), "{u:?}");
            refused += 1;
        } else {
            assert!(u.reason.contains("over-grinds"), "{}", u.reason);
        }
    }
    let path_points: usize = plan
        .reachability
        .regions
        .iter()
        .map(|r| r.path_points)
        .sum();
    assert!(
        refused * 20 <= path_points,
        "{refused} of {path_points} path points refused"
    );
    // issue 28's acceptance as far as it holds: excess removed, no over-grind (nominal or at
    // the Monte Carlo's quantile); the residual peaks are printed
    println!("{}", common::removal::accept(&plan, "demo"));

    // every entry: approach (touching), press in, grinding ..., press out, retract
    let kinds: Vec<SegmentKind> = plan.segments.iter().map(|s| s.kind).collect();
    let grinds = kinds.iter().filter(|k| **k == SegmentKind::Grind).count();
    assert!(grinds > 0, "nothing ground");
    for (i, k) in kinds.iter().enumerate() {
        match k {
            SegmentKind::Approach => assert_eq!(kinds[i + 1], SegmentKind::Press, "at {i}"),
            SegmentKind::Retract => assert_eq!(kinds[i - 1], SegmentKind::Press, "at {i}"),
            SegmentKind::Grind => assert!(
                matches!(kinds[i - 1], SegmentKind::Press | SegmentKind::Grind),
                "grinding segment {i} entered from {:?}",
                kinds[i - 1]
            ),
            _ => {}
        }
    }

    // run's re-check (the defaults and solids.toml) accepts the plan ...
    let robot = common::dofbot();
    let workcell_file = common::calib("workcell.toml");
    let wc = Workcell::load(&workcell_file).unwrap();
    let mut cfg = CollisionConfig::default();
    cfg.solids
        .extend(collide::solids_beside(&workcell_file).unwrap());
    let inspection = Inspection::load(&dir.join("inspection")).unwrap();
    plan.check_clearance(&inspection, &robot, &wc, &cfg)
        .expect("the plan passes run's collision check");
    // ... and read as a rigid plan (no preload) it is refused only where the ball is pressed
    let mut rigid = plan.clone();
    rigid.removal = None;
    let Err(PlanError::Collides(hits)) = rigid.check_clearance(&inspection, &robot, &wc, &cfg)
    else {
        panic!("a pressed ball passed the rigid contact tolerance");
    };
    for h in &hits {
        assert!(
            matches!(h.kind, Some(SegmentKind::Grind | SegmentKind::Press)),
            "{h}"
        );
        // pressed by the preload, beyond the contact tolerance, within preload + tolerance
        let inside = -h.hit.clearance_mm;
        assert!(
            inside > cfg.contact_tolerance_mm && inside <= PRELOAD_MM + cfg.contact_tolerance_mm,
            "{h}"
        );
    }
}

/// A 12 mm square patch of the part at `centre` (reference frame, facing -y like the distal
/// surface the default workcell presents to the arm, 0.5 mm pitch) with a round bump 3 mm in
/// radius, `height` mm of paraboloid on a 0.06 mm plateau, as region `id`.
fn patch(centre: Point3<f64>, id: usize, height: f64) -> (Vec<SurfacePoint>, RegionInfo) {
    let mut points = Vec::new();
    for i in 0..=24 {
        for k in 0..=24 {
            let p = centre + Vector3::new(-6.0 + 0.5 * i as f64, 0.0, -6.0 + 0.5 * k as f64);
            let r = (p - centre).norm();
            let inside = r <= 3.0;
            points.push(SurfacePoint {
                position: p,
                normal: -Vector3::y(),
                distance: if inside {
                    height * (1.0 - (r / 3.0).powi(2)) + PLATEAU_MM
                } else {
                    0.0
                },
                uncertainty: 0.0,
                region: if inside { id as i64 } else { -1 },
            });
        }
    }
    let members = points.iter().filter(|p| p.region == id as i64).count();
    let region = RegionInfo {
        id,
        centroid: [centre.x, centre.y, centre.z],
        normal: [0.0, -1.0, 0.0],
        area: members as f64 * 0.25,
        peak: height + PLATEAU_MM,
        peak_lower_bound: false,
        // a paraboloid's mean over its disc is half its height
        mean: 0.5 * height + PLATEAU_MM,
        volume: 1.0,
        points: members,
        repairable: true,
        measured_share: 1.0,
        touches_unmeasured: false,
    };
    (points, region)
}

/// A repairable region the arm cannot reach at all (half a metre past the part) is not
/// reported as planned (no removal entry of "peak 0 -> 0" over no core points): every one of
/// its points is left out with a reason, while the reachable region beside it is planned.
#[test]
fn a_region_out_of_reach_is_left_out_with_reasons_not_planned_as_nothing() {
    let (mut points, near) = patch(Point3::new(5.0, -35.0, -25.0), 0, LOW_MM);
    let (far_points, far) = patch(Point3::new(5.0, -35.0, 475.0), 1, LOW_MM);
    points.extend(far_points);
    let inspection = Inspection {
        dir: "out_of_reach".into(),
        tolerance: Some(0.05),
        regions: vec![near, far],
        points,
        fine: Vec::new(),
    };
    let robot = common::dofbot();
    let wc = Workcell::load(&common::calib("workcell.toml")).unwrap();
    let p = plan_part(&inspection, &robot, &wc, &PlanConfig::default()).expect("plan");
    let removal = p.removal.as_ref().expect("a removal report");
    let planned: Vec<usize> = removal.regions.iter().map(|r| r.region).collect();
    assert!(
        !planned.contains(&1),
        "region 1 reported as planned: {planned:?}"
    );
    assert!(removal.regions.iter().all(|r| r.core_points > 0));
    let left: Vec<_> = p
        .reachability
        .unreachable
        .iter()
        .filter(|u| u.region == 1)
        .collect();
    assert!(
        !left.is_empty(),
        "region 1's points not recorded as unreachable"
    );
    assert!(left.iter().all(|u| !u.reason.is_empty()), "{:?}", left[0]);
    println!(
        "region 1: {} points left out: {}",
        left.len(),
        left[0].reason
    );
    println!("{}", common::removal::accept(&p, "near patch"));
}

/// The tall bump (`TALL_MM`) planned alone with one pass's removal capped at `max_pass` mm;
/// the plan must keep it (one region planned).
fn tall_bump_plan(name: &str, max_pass: f64) -> (Plan, PlanConfig) {
    let (points, region) = patch(Point3::new(5.0, -35.0, -25.0), 0, TALL_MM);
    let inspection = Inspection {
        dir: name.into(),
        tolerance: Some(TOLERANCE_MM),
        regions: vec![region],
        points,
        fine: Vec::new(),
    };
    let robot = common::dofbot();
    let wc = Workcell::load(&common::calib("workcell.toml")).unwrap();
    let mut config = PlanConfig::default();
    config.removal.max_pass_mm = max_pass;
    let p = plan_part(&inspection, &robot, &wc, &config).expect("plan");
    let planned = p.removal.as_ref().expect("a removal report").regions.len();
    assert_eq!(planned, 1, "{:?}", p.reachability.unreachable.first());
    (p, config)
}

/// The planner's real path to a region's allowance (`motion/by_region.rs`: set_dwell, the
/// rehearsal's Monte Carlo, the re-solve): a tall bump is planned, not left out, at an
/// allowance where its Monte Carlo quantile stays within the tolerance. Before the rim guard
/// (issue 50) the bump over-ground at the quantile with the default allowance and was raised
/// by whole steps of `ALLOWANCE_STEP_SHARE` x tolerance; under it every core point within a
/// contact's reach plus the landing margin keeps its removal within its budget under the
/// landing shifts, and the bump plans at the default allowance (measured 0 mm, 2026-12-06).
/// A raise, where one is taken, is a whole step or a step halved or bisected back
/// (`ALLOWANCE_STEP_HALVINGS` and `ALLOWANCE_BISECTIONS`, 2 each: sixteenths of a step at the
/// finest), never below the default.
#[test]
fn a_tall_bump_is_planned_at_an_allowance_its_monte_carlo_passes() {
    // no cap on one pass's removal here (the next test has it)
    let (p, config) = tall_bump_plan("tall_bump", 1.0);
    let removal = p.removal.as_ref().expect("a removal report");
    let allowance = removal.regions[0].allowance_mm;
    let sixteenths =
        16.0 * (allowance - config.allowance_mm) / (ALLOWANCE_STEP_SHARE * TOLERANCE_MM);
    println!("allowance {allowance:.4} mm ({sixteenths:.3} sixteenths of a step)");
    assert!(
        sixteenths > -1e-9 && (sixteenths - sixteenths.round()).abs() < 1e-6,
        "allowance {allowance} mm from {} mm",
        config.allowance_mm
    );
    // the quantile within the tolerance, excess removed
    println!("{}", common::removal::accept(&p, "tall bump"));
}

/// One pass removes at most `removal.max_pass_mm`: the same tall bump (0.31 mm) with a cap
/// of 0.1 mm is planned at an allowance of at least its highest deviation less the cap, and
/// the predicted peak after the pass stays above it.
#[test]
fn one_pass_removes_at_most_the_cap() {
    let (p, _) = tall_bump_plan("tall_bump_capped", 0.1);
    let removal = p.removal.as_ref().expect("a removal report");
    let r = &removal.regions[0];
    println!(
        "peak {:.3} -> {:.3} mm at allowance {:.3} mm (cap 0.1 mm)",
        r.before.peak_mm, r.after.peak_mm, r.allowance_mm
    );
    assert!(
        r.allowance_mm >= r.before.peak_mm - 0.1 - 1e-12,
        "{}",
        r.allowance_mm
    );
    assert!(
        r.after.peak_mm > r.before.peak_mm - 0.1 - TOLERANCE_MM,
        "{:?}",
        r.after
    );
}

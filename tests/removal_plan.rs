//! Removal mode end to end through the CLI on the demo part: the predicted part meets the
//! tolerance (issue 28's acceptance), every contact is entered touching the surface and pressed
//! in to the tool's preload under the grinding rule only, and the collision re-check `run`
//! makes accepts the preload exactly where the plan grinds.
mod common;

use std::path::Path;

use common::polishbot;
use polishbot::plan::{collide, CollisionConfig, Inspection, Plan, PlanError, SegmentKind};
use polishbot::robot::Workcell;

/// The shipped tool.toml's preload, mm.
const PRELOAD_MM: f64 = 2.0;

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
    // every region of the demo ground, none of its contacts left out
    assert_eq!(
        removal.regions.len(),
        5,
        "{:?}",
        plan.reachability.unreachable.first()
    );
    assert!(plan.reachability.unreachable.is_empty());
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

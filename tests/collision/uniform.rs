//! Issue 51's acceptance case: defects uniform over femoral_dm's articular surface (placed by
//! the seed, not for the arm), planned in the shipped cell designed for femoral components
//! (calibration/femoral/, by `polishbot cell design`): the share of the repairable area
//! planned, and this suite's clearance check of every sample with the part turned by the test
//! at each sample's table angle. In rigid mode and in removal mode (`plan`'s default), where
//! the ball is pressed its preload (2 mm) into the part on purpose while it grinds and presses
//! in and out: there the check lets it be that much (plus 0.1 mm) inside and counts the shank
//! from where it leaves the ball (`heldout::pressing`); everything else as in rigid mode.
use polishbot::motion::{plan, Inspection, Plan, PlanMode};

use super::heldout::{accept, turned_tally};
use crate::common::femoral::{
    cell, ground_at, library, planned_area, reasons, setups, split_plan, uniform_case,
};
use crate::common::variants::{self, VARIANTS};

/// Least share of the repairable area planned: issue 51's 0.9. The designed cell reaches
/// 86 % of the articular surface (the design's own score: the notch walls and the condyles'
/// side faces, whose normals lie along the table axis, stay out of the arm's 45 degree cone at
/// every table angle); this seed's defects plan to 100 % here and to 90.6 % in removal mode.
const PLANNED_FLOOR: f64 = 0.90;

#[test]
fn uniform_defects_on_the_femoral_component_in_the_designed_cell() {
    let insp = uniform_case(5100);
    let (robot, wc, table, config) = cell("femoral/");
    let table = table.expect("the designed cell has a turntable");
    let plan = plan(&insp, &robot, &wc, Some(&table), &config).expect("plan");
    let (c, t) = planned_area(&plan);
    println!(
        "designed cell: repairable {t:.1} mm^2, planned {:.1} %, left out {:?}",
        100.0 * c / t,
        reasons(&plan)
    );
    let tally = turned_tally(&plan, &robot, &insp, &wc, "femoral/");
    accept("uniform defects, designed cell", &plan, &tally);
    assert!(c / t >= PLANNED_FLOOR, "planned {:.3}", c / t);
}

/// The same case planned in removal mode (`plan`'s default), through the same check with the
/// preload the plan states: every free sample keeps the ball out of the part, every pressing
/// and grinding sample keeps it within the preload, no ball on a second face, shank and links
/// clear.
#[test]
fn uniform_defects_in_removal_mode_keep_the_ball_within_its_preload() {
    let insp = uniform_case(5100);
    let (robot, wc, table, mut config) = cell("femoral/");
    config.mode = PlanMode::Removal;
    let table = table.expect("the designed cell has a turntable");
    let plan = plan(&insp, &robot, &wc, Some(&table), &config).expect("plan");
    let preload = plan.removal.as_ref().expect("removal mode").preload_mm;
    assert!(preload > 0.5, "the ball is pressed in: {preload} mm");
    let tally = turned_tally(&plan, &robot, &insp, &wc, "femoral/");
    accept(
        "uniform defects, designed cell, removal mode",
        &plan,
        &tally,
    );
}

/// The two-setup plan of seed 5101 (a region there no table angle of setup 1 brings into the
/// cone goes to setup 2), removal mode: each setup's plan through the same check, its part
/// placed as that setup's workcell.toml places it and turned by this test at each sample's
/// table angle.
#[test]
fn a_two_setup_plan_keeps_the_ball_within_its_preload_in_each_setup() {
    let (_, checked) = two_setups_checked("uniform defects", &uniform_case(5101));
    assert_eq!(checked, 2, "both setups grind");
}

/// Plans `insp` over the designed cell's two setups (removal mode, the cell's tool.toml) and
/// puts each setup's plan that grinds through this suite's check, the part placed as that
/// setup's workcell.toml places it and turned at each sample's table angle. The plan, and
/// how many setups' plans were checked.
fn two_setups_checked(what: &str, insp: &Inspection) -> (Plan, usize) {
    let (robot, cells, mut config) = setups("femoral/");
    config.mode = PlanMode::Removal;
    let plan = polishbot::motion::setups::plan(insp, &library("femoral/", true), &cells, &config)
        .expect("plan");
    let mut checked = 0;
    for (part, dir) in plan.setups.iter().zip(["femoral/", "femoral/setup-2/"]) {
        let k = part.setup - 1;
        let p = part.plan.as_deref().unwrap_or(&plan);
        if p.passes.is_empty() {
            continue;
        }
        let tally = turned_tally(p, &robot, insp, &cells[k].workcell, dir);
        println!(
            "{what}, setup {}: contacts the removal's limits lifted: {} ground softer, {} lifted",
            part.setup, p.reachability.softened, p.reachability.lifted
        );
        accept(&format!("{what}, setup {}", part.setup), p, &tally);
        checked += 1;
    }
    (plan, checked)
}

/// Least share of the repairable area planned on the implant designs the cell was not designed
/// on ([`unseen_designs_plan_the_issues_share_collision_free`]): issue 51's 0.90, "the same on
/// implant designs you have not seen". Measured over the two setups (tests/unseen.rs's survey,
/// seeds 5100 / 5101): femoral_dm 0.85 x 0.939 / 0.938, 1.15 x 0.918 / 0.935, mirrored (the
/// left knee on the right knee's placement) 0.930 / 0.933, mirrored and 1.15 x 0.919 / 0.963,
/// synth's parametric part 0.924 / 0.942.
const UNSEEN_FLOOR: f64 = 0.90;

/// Issue 51's acceptance on implant designs the shipped cell was not designed on: the left knee
/// at the large end of the family (femoral_dm mirrored and 1.15 x, seed 5100, its lowest
/// measured share) and the small right knee (0.85 x, seed 5101), defects uniform over the
/// articular surface, mounted as the cell's fixture holds femoral_dm (centroid on the table
/// centre; tests/common/variants.rs). Each plans at least [`UNSEEN_FLOOR`] of its repairable
/// area over the shipped cell's two setups, and every setup's plan passes this suite's
/// clearance check.
#[test]
fn unseen_designs_plan_the_issues_share_collision_free() {
    let tmp = crate::common::tempdir();
    for (v, seed) in [(VARIANTS[3], 5100), (VARIANTS[0], 5101)] {
        let insp = variants::case(&variants::variant_config(tmp.path(), &v, seed));
        let (plan, checked) = two_setups_checked(&format!("{}, seed {seed}", v.name), &insp);
        let (c, t) = planned_area(&plan);
        println!(
            "{}, seed {seed}: planned {:.1} % of {t:.1} mm^2 over two setups; left out {:?}",
            v.name,
            100.0 * c / t,
            reasons(&plan)
        );
        assert!(checked >= 1, "{}: no setup grinds", v.name);
        assert!(
            c / t >= UNSEEN_FLOOR,
            "{}, seed {seed}: planned {:.3}",
            v.name,
            c / t
        );
    }
}

/// Issue 51, the table as a sixth axis at stroke granularity: the uniform case whose plan in
/// the designed femoral cell splits regions by table angle (`common::femoral::SPLIT_SEED`). Each
/// split region is ground at two or more table angles, its pieces add coverage, the split
/// plans more than the same plan without splitting (`table_pieces` 0), and every sample
/// passes this suite's clearance check with the part turned by this test at its table angle.
#[test]
fn a_region_split_by_table_angle_is_ground_at_each_angle_collision_free() {
    let (robot, wc, table, mut config, insp, plan) = split_plan();
    let tp = plan.turntable.as_ref().expect("a table part");
    let split: Vec<_> = tp.regions.iter().filter(|r| !r.pieces.is_empty()).collect();
    assert!(!split.is_empty(), "no region split");
    for r in &split {
        let at = ground_at(&plan, r.region);
        println!(
            "region {}: ground at {at:?} deg; pieces {:?}",
            r.region, r.pieces
        );
        assert!(at.len() >= 2, "region {} ground at {at:?} only", r.region);
        let covered = r.pieces.iter().map(|p| p.coverage);
        assert!(covered.clone().all(|c| c > 0.0 && c <= 1.0));
        assert!(covered.clone().zip(covered.skip(1)).all(|(a, b)| b > a));
    }
    config.table_pieces = 0;
    let unsplit = polishbot::motion::plan(&insp, &robot, &wc, Some(&table), &config).expect("plan");
    let ((c, t), (c0, _)) = (planned_area(&plan), planned_area(&unsplit));
    println!(
        "split: {:.1} % planned, one angle per region: {:.1} %",
        100.0 * c / t,
        100.0 * c0 / t
    );
    assert!(c > c0, "the split plans no more");
    let tally = turned_tally(&plan, &robot, &insp, &wc, "femoral/");
    accept("regions split by table angle", &plan, &tally);
}

//! Part turntable (issue 33): the cell model, per-region table angles, the table's moves and
//! 0x19 frames in plan.json, and the reach it buys on parts nobody placed for the arm.
mod common;

use common::femoral::{cell, inspection};
use nalgebra::Point3;
use polishbot::plan::{plan_cell, table_file};

/// Covered and total repairable area of a plan, mm^2 (coverage of all the region's points
/// times its area).
fn covered(plan: &polishbot::plan::Plan) -> (f64, f64) {
    plan.reachability
        .regions
        .iter()
        .filter(|r| r.repairable)
        .fold((0.0, 0.0), |(c, t), r| {
            (c + r.coverage_of_all * r.area_mm2, t + r.area_mm2)
        })
}

/// Ten synth parts with random defects on the articular surface: the turntable cell covers at
/// least 90 % of their repairable area; today's figure (the same cell without turning) is
/// printed beside it. Every table move is a valid, rest-to-rest run of 0x19 frames for servo 7.
#[test]
fn the_turntable_reaches_nine_tenths_of_the_repairable_area() {
    let (robot, wc, table, config) = cell("turntable/");
    let table = table.expect("the turntable cell has a turntable");
    let (plain_robot, plain_wc, none, plain) = cell("");
    assert!(none.is_none());
    let (mut with, mut without, mut total) = (0.0, 0.0, 0.0);
    for seed in 0..10 {
        let insp = inspection(1000 + seed, 6);
        let turned = plan_cell(&insp, &robot, &wc, Some(&table), &config).expect("plan");
        // today's planner refuses some of these parts outright (a retract it cannot clear):
        // that case counts as nothing covered
        let (c0, t0) = match plan_cell(&insp, &plain_robot, &plain_wc, None, &plain) {
            Ok(fixed) => covered(&fixed),
            Err(e) => {
                println!("case {seed}: without the table: {e}");
                (0.0, covered(&turned).1)
            }
        };
        let (c, t) = covered(&turned);
        assert!((t - t0).abs() < 1e-9);
        let tp = turned.turntable.as_ref().expect("table part");
        println!(
            "case {seed}: repairable {t:.1} mm^2, covered {:.1} % with the table ({} moves, angles {:?} deg), {:.1} % without",
            100.0 * c / t.max(1e-9),
            tp.moves.len(),
            tp.regions.iter().map(|r| r.angle_deg).collect::<Vec<_>>(),
            100.0 * c0 / t0.max(1e-9)
        );
        table_file::check(tp, &table, turned.samples.len(), turned.period).expect("table moves");
        if !tp.moves.is_empty() {
            let refused = turned.check(&robot, &Default::default()).unwrap_err();
            assert!(refused.to_string().contains("turntable"), "{refused}");
        }
        for m in &tp.moves {
            let (a, b) = (m.samples[0], *m.samples.last().unwrap());
            assert!(m
                .samples
                .windows(2)
                .all(|w| (w[1] - w[0]) * (b - a) >= -1e-12));
            let q = &turned.samples[m.at_sample].q;
            let off = q.iter().zip(&config.home).map(|(a, b)| (a - b).abs());
            assert!(
                off.fold(0.0, f64::max) < 1e-9,
                "the arm rests at home while the table turns: {q:?}"
            );
        }
        with += c;
        without += c0;
        total += t;
    }
    println!(
        "repairable area covered over 10 cases: {:.1} % with the turntable, {:.1} % without",
        100.0 * with / total,
        100.0 * without / total
    );
    assert!(with >= 0.9 * total, "{:.1} %", 100.0 * with / total);
}

/// Without a `[turntable]` the cell loads none and the planner is the plain one.
#[test]
fn a_cell_without_a_table_plans_as_before() {
    let (robot, wc, table, config) = cell("");
    assert!(table.is_none());
    let insp = inspection(7, 3);
    let a = plan_cell(&insp, &robot, &wc, None, &config).unwrap();
    let b = polishbot::plan::plan(&insp, &robot, &wc, &config).unwrap();
    assert_eq!(a, b);
    let text = serde_json::to_string(&a).unwrap();
    assert!(!text.contains("turntable"));
}

/// The table's geometry against closed-form cases: a quarter turn about robot x through
/// (0, 0.28, 0.26) takes a part point 10 mm along robot +y to 10 mm along +z; angle 0 is the
/// calibrated placement; raw counts follow DOFBOT.md's 270-degree scale.
#[test]
fn table_motion_and_raw_counts_match_closed_form() {
    let (_, wc, table, _) = cell("turntable/");
    let table = table.unwrap();
    assert_eq!(table.workcell_at(&wc, 0.0), wc);
    let p = table.motion(std::f64::consts::FRAC_PI_2) * Point3::new(0.0, 0.29, 0.26);
    assert!((p - Point3::new(0.0, 0.28, 0.27)).norm() < 1e-12, "{p}");
    // 135 servo degrees of 270 on raw 380..3700: (380 + 3700) / 2 = 2040
    assert_eq!(table.raw(0.0), Ok(2040));
    assert_eq!(table.raw(-135f64.to_radians()), Ok(380));
    assert!(table.raw(136f64.to_radians()).is_err());
}

/// Issue 35: the default cell (no table) plans each of the ten cases above and ten more
/// seeds; before the straight retract it refused four of the twenty ("retract clearance"),
/// among them case 8. Prints the points left out for want of a clear retract (18 s: run
/// with --ignored --nocapture).
#[test]
#[ignore]
fn plans_without_the_table_survey() {
    let (robot, wc, _, config) = cell("");
    let mut refused = 0;
    for seed in (1000..1010).chain(2000..2010) {
        let insp = inspection(seed, 6);
        match plan_cell(&insp, &robot, &wc, None, &config) {
            Ok(p) => {
                let un = &p.reachability.unreachable;
                let retract = un.iter().filter(|u| u.reason.contains("retract")).count();
                println!(
                    "seed {seed}: planned, {} left out ({retract} for no clear retract)",
                    un.len()
                );
                if let Some(u) = un.iter().find(|u| u.reason.contains("retract")) {
                    println!("  {}", u.reason);
                }
            }
            Err(e) => {
                refused += 1;
                println!("seed {seed}: refused: {e}");
            }
        }
    }
    assert_eq!(refused, 0, "refused {refused} of 20");
}

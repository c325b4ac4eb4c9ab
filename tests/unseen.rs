//! Issue 51's acceptance on implant designs the shipped femoral cell was not designed on:
//! femoral_dm scaled to the ends of an implant family (0.85 and 1.15 x), mirrored (the left
//! knee), and synth's parametric femoral part, each with defects uniform over its articular
//! surface and mounted as the cell's fixture holds femoral_dm (tests/common/variants.rs),
//! planned in the shipped designed cell (calibration/femoral/ and its setup-2/) as
//! tests/uniform.rs plans femoral_dm.
//!
//! The survey is long (hours on the shared machine): to run one case, name it (a part of its
//! name in the table) and its seeds, e.g.
//! `UNSEEN_CASE='mirrored x1.15 (mirrored fixture)' UNSEEN_SEEDS=5100,5101 nice cargo test
//! --release --test unseen -- --ignored --nocapture`; `UNSEEN_DETAIL=1` adds a row per region
//! left under the table planner's good coverage (95 %) with the setup that grinds it, its
//! coverage in the setup-1 plan and over the setups, and the rules that left its contacts out.
mod common;

use polishbot::motion::setups::SetupCell;
use polishbot::motion::{Inspection, PlanMode};

use common::femoral::{library, planned_area, reasons, setups, uniform_case};
use common::variants::{self, Variant, VARIANTS};

/// Seeds of the survey: tests/uniform.rs's two, and two more.
const SEEDS: [u64; 4] = [5100, 5101, 5102, 5103];

/// The seeds surveyed: `UNSEEN_SEEDS` (comma-separated) or [`SEEDS`].
fn seeds() -> Vec<u64> {
    std::env::var("UNSEEN_SEEDS").map_or(SEEDS.to_vec(), |s| {
        s.split(',')
            .map(|x| {
                x.trim()
                    .parse()
                    .expect("UNSEEN_SEEDS: numbers, comma-separated")
            })
            .collect()
    })
}

/// Plans `insp` with setup 1 of `cells` alone and with all of them (removal mode, the cell's
/// tool.toml); returns the two shares and the reasons of the two-setup plan's left-out list,
/// after the share of the repairable area lost in regions left mostly unground (under half
/// covered) and in regions ground in part. With `detail`, prints the regions left short.
fn shares(insp: &Inspection, cells: &[SetupCell], detail: bool) -> (f64, f64, String) {
    let (_, _, mut config) = setups("femoral/");
    config.mode = PlanMode::Removal;
    let tools = library("femoral/", true);
    let one = polishbot::motion::setups::plan(insp, &tools, &cells[..1], &config).unwrap();
    let two = polishbot::motion::setups::plan(insp, &tools, cells, &config).unwrap();
    let (c1, t1) = planned_area(&one);
    let (c2, t2) = planned_area(&two);
    if detail {
        short_regions(&one, &two, t2);
    }
    let mut why: Vec<(String, usize)> = reasons(&two).into_iter().collect();
    why.sort_by_key(|w| std::cmp::Reverse(w.1));
    let top: Vec<String> = why
        .iter()
        .take(3)
        .map(|(r, n)| format!("{r} {n}"))
        .collect();
    let lost = |left: bool| {
        let regions = two.reachability.regions.iter().filter(|r| r.repairable);
        let lost = regions.filter(|r| (r.coverage_of_all < 0.5) == left);
        100.0
            * lost
                .map(|r| (1.0 - r.coverage_of_all) * r.area_mm2)
                .sum::<f64>()
            / t2
    };
    let head = format!(
        "lost {:.1} % in regions left out, {:.1} % in regions ground in part",
        lost(true),
        lost(false)
    );
    (c1 / t1, c2 / t2, format!("{head} | {}", top.join("; ")))
}

/// A row per repairable region `two` (the plan over the setups) leaves under 95 % covered:
/// its area, the share of the repairable area `total` it loses, its setup, its coverage in
/// `one` (setup 1 alone) and in `two`, and the rules that left its contacts out.
fn short_regions(one: &polishbot::motion::Plan, two: &polishbot::motion::Plan, total: f64) {
    let of = |p: &polishbot::motion::Plan, id: usize| {
        p.reachability
            .regions
            .iter()
            .find(|r| r.id == id)
            .map_or(0.0, |r| r.coverage_of_all)
    };
    for r in two.reachability.regions.iter().filter(|r| r.repairable) {
        if r.coverage_of_all >= 0.95 {
            continue;
        }
        let mut why = std::collections::BTreeMap::new();
        for u in two
            .reachability
            .unreachable
            .iter()
            .filter(|u| u.region == r.id)
        {
            let rule: String = u.reason.chars().take(60).collect();
            *why.entry(rule).or_insert(0) += 1;
        }
        println!(
            "  region {} ({:.1} mm^2, {} points, peak {:.3}): lost {:.2} % of the area; setup {:?}; setup 1 alone {:.1} %, over the setups {:.1} %; reachable {}/{}; {:?}",
            r.id,
            r.area_mm2,
            r.points,
            r.peak_mm,
            100.0 * (1.0 - r.coverage_of_all) * r.area_mm2 / total,
            r.setup,
            100.0 * of(one, r.id),
            100.0 * r.coverage_of_all,
            r.reachable_points,
            r.points,
            why
        );
    }
}

/// The table of the planners' check (numbers only; `--ignored --nocapture`): per held-out
/// design and seed, the share planned with setup 1 and with the two setups, and the rules
/// most often named for what is left out. The left knee is measured twice: on the right
/// knee's placement (the mandrel from the other anatomical side) and on a mirrored fixture.
#[test]
#[ignore]
fn survey_of_unseen_designs_in_the_shipped_cell() {
    let tmp = common::tempdir();
    let (_, cells, _) = setups("femoral/");
    let p0 = variants::femoral_fixture_point();
    let mirrored = variants::mirrored_fixture(&cells, &p0);
    println!("fixture point {p0:?} mm");
    let identity = Variant {
        name: "femoral_dm",
        scale: 1.0,
        mirror: false,
    };
    let only = std::env::var("UNSEEN_CASE").ok();
    let wanted = |name: &str| only.as_deref().is_none_or(|o| name.contains(o));
    let detail = std::env::var_os("UNSEEN_DETAIL").is_some();
    for seed in seeds() {
        let mut cases: Vec<(String, Inspection, &[SetupCell])> = Vec::new();
        for v in std::iter::once(identity).chain(VARIANTS) {
            let fixed = format!("{} (mirrored fixture)", v.name);
            let mirror_fixture = v.mirror && wanted(&fixed);
            if !wanted(v.name) && !mirror_fixture {
                continue;
            }
            let insp = variants::case(&variants::variant_config(tmp.path(), &v, seed));
            if mirror_fixture {
                cases.push((fixed, insp.clone(), &mirrored));
            }
            if wanted(v.name) {
                cases.push((v.name.to_string(), insp, &cells));
            }
        }
        if wanted("parametric part") {
            let par = variants::case(&variants::parametric_config(tmp.path(), seed));
            cases.push(("parametric part".into(), par, &cells));
        }
        for (name, insp, cells) in &cases {
            let (one, two, why) = shares(insp, cells, detail);
            println!(
                "| {name} | {seed} | {:.1} % | {:.1} % | {why} |",
                100.0 * one,
                100.0 * two
            );
        }
    }
    if only.is_some() {
        return;
    }
    // the unmodified case, as tests/uniform.rs makes it
    let (one, two, _) = shares(&uniform_case(5100), &cells, false);
    println!(
        "uniform_case(5100): {:.1} % / {:.1} %",
        100.0 * one,
        100.0 * two
    );
}

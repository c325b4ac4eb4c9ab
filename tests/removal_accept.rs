//! Issue 28's acceptance on synth cases of the real femoral component (femoral_dm, defects on
//! its articular surface) with bumps and ridges of 0.08-0.5 mm: the removal plan (the default
//! mode) predicts, for the nominal model, a residual within the tolerance over every planned
//! region's reachable core points, no over-grind (nominal and at the Monte Carlo's quantile),
//! and every force check passed or its refusal named. Two seeds run in the suite, ten in the
//! ignored test (`cargo test --release --test removal_accept -- --ignored --nocapture`).
mod common;

use polishbot::plan::{plan, Inspection, PlanConfig, PlanError};
use polishbot::synth::SynthConfig;

/// The defect heights, mm: reachable bumps of 0.08-0.5 mm.
const HEIGHTS_MM: [f64; 2] = [0.08, 0.5];

/// Defects per case: four, as many as fit the articular surface without merging.
const DEFECTS: usize = 4;

/// The synth case of `seed`: bumps and ridges only (a pit is not repairable by grinding).
fn case(seed: u64) -> SynthConfig {
    SynthConfig {
        height_range: HEIGHTS_MM,
        pit_share: 0.0,
        ..common::femoral_synth(seed, DEFECTS)
    }
}

/// Plans synth case `seed` in the default (removal) mode and checks it; a refused force check
/// must name the joint.
fn run_seed(seed: u64) -> String {
    let dir = common::tempdir();
    common::synthetic::inspection(dir.path(), &case(seed));
    let inspection = Inspection::load(dir.path()).expect("inspection");
    let robot = common::dofbot();
    let wc = polishbot::robot::Workcell::load(&common::calib("workcell.toml")).expect("wc");
    let config = PlanConfig::default();
    let started = std::time::Instant::now();
    match plan(&inspection, &robot, &wc, &config) {
        Ok(p) => {
            let line = common::removal::accept(&p, &format!("seed {seed}"));
            format!(
                "{line}; planned in {:.2} s",
                started.elapsed().as_secs_f64()
            )
        }
        Err(PlanError::Config(m)) if m.contains("joint") && m.contains("N m") => {
            format!("seed {seed}: force check refused: {m}")
        }
        Err(e) => panic!("seed {seed}: {e}"),
    }
}

#[test]
fn removal_meets_the_tolerance_on_two_synth_cases() {
    for seed in [9, 11] {
        println!("{}", run_seed(seed));
    }
}

#[test]
#[ignore = "ten synth cases, about a minute in release: run by hand, numbers in the report"]
fn removal_meets_the_tolerance_on_ten_synth_cases() {
    for seed in 1..=10 {
        println!("{}", run_seed(seed));
    }
}

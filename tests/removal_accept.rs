//! Issue 28's acceptance on synth cases of the real femoral component (femoral_dm, defects on
//! its articular surface) with bumps and ridges of 0.08-0.5 mm: the removal plan (the default
//! mode) removes excess from every planned region, predicts no over-grind (nominal and at the
//! Monte Carlo's quantile) and passes every force check or names its refusal. Two seeds run in the
//! suite, ten in the ignored test
//! (`cargo test --release --test removal_accept -- --ignored --nocapture`), each with the shipped
//! tool (Preston's k known to 30 %) and with k known to 10 % (`CALIBRATED_K_REL_SD`). The residual
//! peaks are printed, not held to the tolerance: they are not within it yet (docs/ALGORITHMS.md,
//! "What one pass can promise").
mod common;

use polishbot::motion::{plan_part, Inspection, PlanConfig, PlanError};
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

/// Preston k's relative uncertainty once a spot test or `calibrate removal` has measured it
/// (0.1): with the shipped 0.3 the Monte Carlo's 5 % quantile scales the removal by 1.47, so
/// a bump above 0.26 mm cannot be brought within the tolerance in one pass without risking
/// over-grind (the robust solve raises its allowance to 0.075 mm, the cycle finishes it).
const CALIBRATED_K_REL_SD: f64 = 0.1;

/// Plans synth case `seed` in the default (removal) mode, the tool's k uncertainty set to
/// `k_rel_sd` when given, and checks it; a refused force check must name the joint.
fn run_seed(seed: u64, k_rel_sd: Option<f64>) -> String {
    let dir = common::tempdir();
    common::synthetic::inspection(dir.path(), &case(seed));
    let inspection = Inspection::load(dir.path()).expect("inspection");
    let mut robot = common::dofbot();
    if let (Some(sd), Some(toml::Value::Table(t))) = (k_rel_sd, robot.tool.removal.as_mut()) {
        t.insert("preston_k_rel_sd".into(), toml::Value::Float(sd));
    }
    let wc = polishbot::robot::Workcell::load(&common::calib("workcell.toml")).expect("wc");
    let config = PlanConfig::default();
    let started = std::time::Instant::now();
    let label = format!("seed {seed} (k sd {k_rel_sd:?})");
    match plan_part(&inspection, &robot, &wc, &config) {
        Ok(p) => {
            let line = common::removal::accept(&p, &label);
            format!(
                "{line}; planned in {:.2} s",
                started.elapsed().as_secs_f64()
            )
        }
        Err(PlanError::Config(m)) if m.contains("joint") && m.contains("N m") => {
            format!("{label}: force check refused: {m}")
        }
        Err(e) => panic!("{label}: {e}"),
    }
}

#[test]
fn removal_meets_the_tolerance_on_two_synth_cases() {
    for seed in [9, 11] {
        println!("{}", run_seed(seed, Some(CALIBRATED_K_REL_SD)));
        println!("{}", run_seed(seed, None));
    }
}

#[test]
#[ignore = "ten synth cases, a few minutes in release: run by hand, numbers in the report"]
fn removal_meets_the_tolerance_on_ten_synth_cases() {
    for seed in 1..=10 {
        println!("{}", run_seed(seed, Some(CALIBRATED_K_REL_SD)));
        println!("{}", run_seed(seed, None));
    }
}

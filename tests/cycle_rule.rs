//! The closed loop's stop rule (issue 29, `polishbot cycle`) on hand-made records, and
//! plan.json's optional prediction read. The loop itself: tests/cycle.rs.
use std::path::Path;

use polishbot::cycle::{
    decide, decide_plan, planned_regions, predicted_rms, CycleConfig, IterationRecord, Measured,
    Outcome,
};
use polishbot::motion::Plan;
use polishbot::regions::Verdict;

/// A measurement with `verdict`, `repairable` regions (peak 0.2 mm and RMS 0.1 mm when there
/// are any), `pits` and `volume` mm^3.
fn measured(verdict: Verdict, repairable: usize, pits: usize, volume: f64) -> Measured {
    Measured {
        verdict,
        repairable,
        pits,
        peak_mm: (repairable > 0).then_some(0.2),
        rms_mm: (repairable > 0).then_some(0.1),
        volume_mm3: volume,
        decision: Default::default(),
    }
}

/// A record that was ground: planned `planned` mm^3, the next inspection found `progress`
/// of it removed.
fn ground(k: usize, volume: f64, planned: f64, progress: f64) -> IterationRecord {
    let mut r = IterationRecord::new(k, measured(Verdict::Repairable, 2, 0, volume));
    r.planned_volume_mm3 = Some(planned);
    r.progress = Some(progress);
    r
}

#[test]
fn the_stop_rule_ends_within_tolerance_on_no_progress_and_after_the_last_iteration() {
    let cfg = CycleConfig {
        max_iterations: 2,
        min_progress: 0.05,
        ..CycleConfig::default()
    };
    let fresh = |v| IterationRecord::new(9, measured(Verdict::Repairable, 2, 0, v));
    // a first inspection with excess: grind
    assert_eq!(decide(&[fresh(1.0)], &cfg), Outcome::Continue);
    // within tolerance wins over everything, even with no progress and iterations used up
    let done = IterationRecord::new(3, measured(Verdict::WithinTolerance, 0, 0, 0.0));
    let recs = [ground(1, 1.0, 1.0, 0.9), ground(2, 0.1, 0.1, 0.0), done];
    assert_eq!(decide(&recs, &cfg), Outcome::WithinTolerance);
    // 4 % of the planned volume removed, under 5 %: no progress
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 0.04), fresh(0.96)], &cfg),
        Outcome::NoProgress
    );
    // 6 % removed goes on; after 2 grinds the iterations are used up
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 0.06), fresh(0.94)], &cfg),
        Outcome::Continue
    );
    let two = [
        ground(1, 1.0, 1.0, 0.5),
        ground(2, 0.5, 0.5, 0.5),
        fresh(0.25),
    ];
    assert_eq!(decide(&two, &cfg), Outcome::MaxIterations);
    // undecided under ISO 14253-1 (nothing proven to grind nor proven conform): stop and
    // rescan, before "nothing repairable left" and however much progress was made
    let open = IterationRecord::new(2, measured(Verdict::Undecided, 1, 0, 0.01));
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 1.0), open], &cfg),
        Outcome::Undecided
    );
    // only pits left: nothing to grind
    let pits = IterationRecord::new(2, measured(Verdict::Reject, 0, 1, 0.0));
    assert_eq!(
        decide(&[ground(1, 1.0, 1.0, 1.0), pits], &cfg),
        Outcome::NothingToGrind
    );
    // a plan that grinds none of the excess
    let mut unreachable = fresh(1.0);
    unreachable.planned_volume_mm3 = Some(0.0);
    assert_eq!(decide_plan(&unreachable), Outcome::NothingPlanned);
    assert_eq!(decide_plan(&ground(1, 1.0, 1.0, 0.5)), Outcome::Continue);
    assert!(CycleConfig {
        max_iterations: 0,
        ..cfg.clone()
    }
    .check()
    .is_err());
    assert!(CycleConfig {
        min_progress: 1.5,
        ..cfg.clone()
    }
    .check()
    .is_err());
}

/// A plan.json with the given reachability regions and optional removal object, the rest
/// empty; read through `Plan::parse` (the one schema).
fn plan_with(regions: serde_json::Value, removal: Option<serde_json::Value>) -> Plan {
    let metrics = serde_json::to_value(polishbot::motion::Metrics::default()).unwrap();
    let report = |r: &serde_json::Value| {
        serde_json::json!({"id": r["id"], "repairable": true, "peak_mm": 0.1, "area_mm2": 1.0,
            "layers": r["layers"], "path_points": 0, "unreachable_path_points": 0,
            "points": 1, "reachable_points": 1, "unreachable_share": 0.0,
            "coverage_of_reachable": 1.0, "coverage_of_all": 1.0})
    };
    let mut v = serde_json::json!({"format": "polishbot-plan", "version": 1, "inspection": "i",
        "period": 0.02, "joint_names": [], "tool_radius_mm": 3.0, "stepover_mm": 1.0,
        "footprint_mm": 1.0, "predicted_duration_s": 0.0, "passes": [], "segments": [],
        "samples": [], "frames": [],
        "reachability": {"regions": regions.as_array().unwrap().iter().map(report)
            .collect::<Vec<_>>(), "unreachable": [], "jumps": 0},
        "metrics": metrics});
    if let Some(r) = removal {
        v["removal"] = r;
    }
    Plan::parse(Path::new("plan.json"), &v.to_string()).unwrap()
}

/// One removal region's prediction (plan.json `removal.regions[]`).
fn prediction(region: usize, core_points: usize, rms: f64) -> serde_json::Value {
    let stats = |rms: f64| {
        serde_json::json!({"peak_mm": 0.1, "rms_mm": rms, "volume_above_tolerance_mm3": 0.0,
            "lowest_mm": 0.0})
    };
    serde_json::json!({"region": region, "allowance_mm": 0.0, "dwell": [],
        "core_points": core_points, "before": stats(0.1), "after": stats(rms),
        "after_low_p95_mm": 0.0})
}

#[test]
fn a_rigid_plan_has_no_prediction_and_a_removal_plan_predicts_the_weighted_rms() {
    let rigid = plan_with(
        serde_json::json!([{"id": 0, "layers": 2}, {"id": 1, "layers": 0}, {"id": 2, "layers": 1}]),
        None,
    );
    assert_eq!(planned_regions(&rigid), vec![0, 2]);
    assert_eq!(predicted_rms(&rigid), None);
    // removal mode (issue 28's plan.json): rms over 1 + 3 points of 0.02 and 0.04 mm is
    // sqrt((0.02^2 + 3 x 0.04^2) / 4) = sqrt(0.0013)
    let removal = plan_with(
        serde_json::json!([{"id": 0, "layers": 0}, {"id": 1, "layers": 0}]),
        Some(
            serde_json::json!({"force_n": 2.0, "preload_mm": 0.5, "tolerance_mm": 0.05,
            "regions": [prediction(0, 1, 0.02), prediction(1, 3, 0.04)]}),
        ),
    );
    assert_eq!(planned_regions(&removal), vec![0, 1]);
    let p = predicted_rms(&removal).unwrap();
    assert!((p - 0.0013f64.sqrt()).abs() < 1e-12, "{p}");
}

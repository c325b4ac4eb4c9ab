//! Issue 28's acceptance of a removal plan: the predicted residual within the tolerance over
//! every planned region's reachable core points, no over-grind (nominal and at the Monte
//! Carlo's quantile).
use polishbot::plan::Plan;

/// The tolerance of the demo's and common::synthetic's inspections, mm.
pub const TOLERANCE_MM: f64 = 0.05;

/// Checks a removal plan against the acceptance (the residual peak against the tolerance only
/// when `residual_within`); returns a one-line summary.
pub fn accept(plan: &Plan, label: &str, residual_within: bool) -> String {
    let removal = plan.removal.as_ref().expect("a removal report");
    let mut line = format!("{label}: {} regions", removal.regions.len());
    for r in &removal.regions {
        let why = format!("{label} region {}: {:?}", r.region, r.after);
        assert!(
            !residual_within || r.after.peak_mm <= TOLERANCE_MM,
            "residual above tolerance: {why}"
        );
        assert!(r.after.lowest_mm >= -TOLERANCE_MM, "over-ground: {why}");
        assert!(
            r.after_low_p95_mm >= -TOLERANCE_MM,
            "over-ground at the 95th percentile: {why} ({:.3} mm)",
            r.after_low_p95_mm
        );
        line.push_str(&format!(
            "; {}: peak {:.3} -> {:.3} mm, lowest {:.3}, p95 low {:.3}",
            r.region, r.before.peak_mm, r.after.peak_mm, r.after.lowest_mm, r.after_low_p95_mm
        ));
    }
    let left: Vec<&str> = plan
        .reachability
        .unreachable
        .iter()
        .map(|u| u.reason.as_str())
        .filter(|r| r.contains("removal planner"))
        .collect();
    line.push_str(&format!(
        "; {:.1} s, {} contacts left out by the removal planner",
        plan.predicted_duration_s,
        left.len()
    ));
    line
}

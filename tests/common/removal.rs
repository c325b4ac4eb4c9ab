//! Issue 28's acceptance of a removal plan: no over-grind (nominal and at the Monte Carlo's
//! quantile) over every planned region's reachable core points, and the predicted residual
//! peaks (reported: not yet within the tolerance everywhere).
use polishbot::motion::Plan;

/// The tolerance of the demo's and common::synthetic's inspections, mm.
pub const TOLERANCE_MM: f64 = 0.05;

/// Checks a removal plan against what holds of the acceptance (excess removed, no over-grind,
/// nominal or at the Monte Carlo's quantile); returns a one-line summary with the residual
/// peaks, which issue 28 wants within the tolerance and which are not yet (docs/ALGORITHMS.md).
pub fn accept(plan: &Plan, label: &str) -> String {
    let removal = plan.removal.as_ref().expect("a removal report");
    let mut line = format!("{label}: {} regions", removal.regions.len());
    for r in &removal.regions {
        let why = format!("{label} region {}: {:?}", r.region, r.after);
        assert!(
            r.before.volume_above_tolerance_mm3 == 0.0
                || r.after.volume_above_tolerance_mm3 < r.before.volume_above_tolerance_mm3,
            "no excess removed: {why}"
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

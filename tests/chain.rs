//! The whole chain as the README's main job runs it: `polishbot demo`.
mod common;

use common::{polishbot, tempdir};

#[test]
fn demo_finds_every_planted_repairable_defect_and_completes_the_run() {
    // Run in an empty folder with a relative --out, as after `cargo install` (issue 52): the
    // demo carries its own cell and needs no ./calibration/.
    let dir = tempdir();
    let out = dir.path().join("demo");
    let run = polishbot()
        .current_dir(dir.path())
        .args(["demo", "--out", "demo"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "demo failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("every planted repairable defect found: yes"),
        "{stdout}"
    );
    // Registration within a hundredth of a degree and millimetre of the truth.
    let line = stdout
        .lines()
        .find(|l| l.starts_with("registration error against truth"))
        .expect("registration line");
    let nums: Vec<f64> = line
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter_map(|t| t.parse().ok())
        .collect();
    assert!(
        nums.len() >= 2 && nums[0] < 0.01 && nums[1] < 0.01,
        "{line}"
    );
    for f in [
        "truth.json",
        "inspection/report.html",
        "inspection/regions.json",
        "plan.json",
        "journal.jsonl",
        "trajectory.yaml",
        "calibration/tool.toml",
        "calibration/turntable/workcell.toml",
    ] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // The simulated arm received every planned frame.
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap();
    let frames = plan["frames"].as_array().unwrap().len();
    assert!(frames > 100, "plan has {frames} frames");
    assert!(stdout.contains(&format!("({frames} frames)")), "{stdout}");
    // The loop on the documented arm (issue 50): no grind cuts deeper than the tolerance
    // where it ground (main 7eea059's first grind: -0.143 mm; with compensation, the spindle's
    // aim and the first pass's cap -0.009 / -0.009 / -0.026 mm over the three grinds), and
    // each grind takes material off the repairable regions. After each grind the loop either
    // grinds again with the measured shift carried or stops itself naming the region and the
    // shift it measured (never a second grind on a model the regions disagree with). Not
    // asserted: that every region lands nearer its plan on grind 2 than the best one did on
    // grind 1 (the issue asks the loop to measure and carry the shift and to stop beyond its
    // limits, not that the arm's error shrinks everywhere: 0.10-0.89 mm after grind 1, 0.20-0.50
    // after grind 2); nor the "within tolerance in at most 3 grinds", which the demo
    // does not reach yet (region 0 left out of grinds 2 and 3 by the servo force share,
    // issue 50's force helper; the repairable volume 3.03 -> 1.83 -> 1.51 -> 0.97 mm^3).
    let cycle: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("cycle/cycle.json")).unwrap())
            .unwrap();
    let records = cycle["records"].as_array().unwrap();
    let ground: Vec<&serde_json::Value> = records
        .iter()
        .filter(|r| r["agreement"]["lowest_ground_mm"].is_number())
        .collect();
    assert!(!ground.is_empty(), "no grind judged: {cycle}");
    for (k, r) in ground.iter().enumerate() {
        let lowest = r["agreement"]["lowest_ground_mm"].as_f64().unwrap();
        assert!(lowest >= -0.05, "grind {} cut to {lowest} mm", k + 1);
    }
    let volumes: Vec<f64> = records
        .iter()
        .filter_map(|r| r["measured"]["volume_mm3"].as_f64())
        .collect();
    assert!(
        volumes.windows(2).all(|w| w[1] < w[0]),
        "the repairable volume per inspection {volumes:?}"
    );
    if cycle["outcome"] == "off_plan" {
        let stop = stdout
            .lines()
            .find(|l| l.starts_with("cycle: stop: region "))
            .unwrap_or_else(|| panic!("off plan without naming the region:\n{stdout}"));
        assert!(
            stop.contains(" mm [") && stop.contains("from where the plan aimed"),
            "{stop}"
        );
    }
    // Run again into the same folder, as a user repeating the README's command does: the
    // earlier run's journals and loop iterations must not stop it.
    let again = polishbot()
        .args(["demo", "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        again.status.success(),
        "second demo into the same folder failed:\n{}",
        String::from_utf8_lossy(&again.stderr)
    );
}

//! The synth -> inspect -> plan case the hostile tests (tests/hostile.rs, hostile_cell.rs)
//! run their inputs against: e2e's part (seed 9, three 0.15-0.35 mm defects 2-3 mm wide) with
//! one layer per region.
use std::path::{Path, PathBuf};

use super::{polishbot, succeed};

/// Synthesises the part into `CARGO_TARGET_TMPDIR/name` (`reference_points` and
/// `scan_points` points), inspects it (with `--pose truth.json` when `given_pose`) into
/// `inspection` and plans it into `plan.json` with the package's calibration/; returns the
/// folder. Callers keep it in a `OnceLock` so one test binary makes it once.
pub fn synth_inspect_plan(
    name: &str,
    reference_points: usize,
    scan_points: usize,
    given_pose: bool,
) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("plan.toml"),
        "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n",
    )
    .unwrap();
    let d = dir.display();
    let pose = match given_pose {
        true => format!(" --pose {d}/truth.json"),
        false => String::new(),
    };
    let steps = [
        format!(
            "synth --out {d} --seed 9 --defects 3 --reference-points {reference_points} \
             --scan-points {scan_points} --height-range 0.15,0.35 --width-range 2,3"
        ),
        format!(
            "inspect --reference {d}/reference.ply --scan {d}/scan.ply{pose} -o {d}/inspection"
        ),
        format!("--config {d}/plan.toml plan --inspection {d}/inspection -o {d}/plan.json"),
    ];
    // Run from the package root, whose calibration/ the plan reads.
    for step in steps {
        succeed(polishbot().args(step.split_whitespace()));
    }
    dir
}

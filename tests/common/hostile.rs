//! The synth -> inspect -> plan case the hostile tests (tests/hostile.rs, hostile_plan.rs,
//! hostile_cell.rs) run their inputs against: e2e's part (seed 9, three 0.15-0.35 mm defects
//! 2-3 mm wide) with one layer per region; the check that a hostile input is refused; and
//! the provenance block `run` needs on a plan a test saves through the library.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use serde_json::Value;

use super::{polishbot, succeed};

/// Each case's bound (the probe allows 20 s; these are small inputs).
const CASE_LIMIT: Duration = Duration::from_secs(20);

/// synth -> inspect -> plan once (e2e's case: seed 9, three defects, one layer per region).
pub struct Case {
    dir: PathBuf,
}

impl Case {
    /// The file or folder `name` of the case's folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

/// `p` as a command-line argument.
pub fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The case of tests/hostile.rs and hostile_plan.rs (200,000 reference and 150,000 scan
/// points, registered by inspect), made once per test binary in a folder named after it.
pub fn case() -> &'static Case {
    static CASE: OnceLock<Case> = OnceLock::new();
    CASE.get_or_init(|| Case {
        dir: synth_inspect_plan(env!("CARGO_CRATE_NAME"), 200_000, 150_000, false),
    })
}

/// Runs `cmd`, which must fail within [`CASE_LIMIT`] with one line on stderr that contains
/// every one of `needles` and no panic; returns that line.
pub fn refused(cmd: &mut Command, needles: &[&str]) -> String {
    let start = Instant::now();
    let out: Output = cmd.output().expect("start polishbot");
    let took = start.elapsed();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(took < CASE_LIMIT, "took {took:?}: {err}");
    assert!(!out.status.success(), "accepted: {err}");
    assert_eq!(out.status.code(), Some(1), "exit status: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("polishbot: "))
        .unwrap_or_else(|| panic!("no error line: {err}"))
        .to_string();
    for n in needles {
        assert!(line.contains(n), "{n:?} not in {line:?}");
    }
    assert!(!line.contains(" { "), "Debug text in {line:?}");
    line
}

/// The JSON file at `path`.
pub fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

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

/// The `provenance` block `plan` writes for the inspection in `dir`/inspection (tests/plan.rs's
/// `small_plan`) and the shipped cell: `run` refuses a plan without one (it cannot be checked against the cell and
/// inspection it was made for), so the plans a test saves through the library carry it
/// ([`stamp`]) to reach the checks each test is about.
pub fn provenance_of(dir: &Path) -> serde_json::Value {
    let cfg = dir.join("rigid.toml");
    std::fs::write(&cfg, "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n").unwrap();
    let made = dir.join("made.json");
    super::succeed(
        super::polishbot()
            .arg("--config")
            .arg(&cfg)
            .args(["plan", "--inspection"])
            .arg(dir.join("inspection"))
            .arg("-o")
            .arg(&made),
    );
    let text = std::fs::read_to_string(&made).unwrap();
    serde_json::from_str::<serde_json::Value>(&text).unwrap()["provenance"].clone()
}

/// Writes `provenance` into the plan file `path` (saved by the library, which writes none);
/// returns it.
pub fn stamp(path: &Path, provenance: &serde_json::Value) -> serde_json::Value {
    let mut plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    plan["provenance"] = provenance.clone();
    std::fs::write(path, plan.to_string()).unwrap();
    provenance.clone()
}

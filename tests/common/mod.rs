//! Helpers shared by the integration tests: data paths, the oracle Python, the binary.
#![allow(dead_code)]
use std::path::{Path, PathBuf};
use std::process::Command;

/// A file under the planners' read-only data folder (`../shared/data`).
pub fn shared_data(rel: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    assert!(p.exists(), "missing shared data file {}", p.display());
    p
}

/// True when running in CI, where no oracle test may skip.
pub fn in_ci() -> bool {
    std::env::var("CI")
        .map(|v| v == "true" || v == "1")
        .unwrap_or(false)
}

/// The test venv's python (set by scripts/test.sh as POLISHBOT_PYTHON). Outside CI a missing
/// venv skips the oracle test with a message; in CI it fails the test.
pub fn oracle_python() -> Option<PathBuf> {
    match std::env::var_os("POLISHBOT_PYTHON").map(PathBuf::from) {
        Some(p) if p.exists() => Some(p),
        _ => {
            assert!(
                !in_ci(),
                "POLISHBOT_PYTHON is not set or missing: oracle tests must run in CI"
            );
            eprintln!("skipping oracle test: POLISHBOT_PYTHON not set (run scripts/test.sh)");
            None
        }
    }
}

/// Runs a Python snippet with the oracle python; returns stdout, panics with stderr on failure.
pub fn run_python(python: &Path, script: &str, args: &[&str]) -> String {
    let out = Command::new(python)
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .expect("start python");
    assert!(
        out.status.success(),
        "python failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf8")
}

/// The polishbot binary built for this test run.
pub fn polishbot() -> Command {
    Command::new(env!("CARGO_BIN_EXE_polishbot"))
}

/// A fresh temporary directory.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("tempdir")
}

//! Records the git commit polishbot is built from as `POLISHBOT_GIT_COMMIT` (with `-dirty`
//! when tracked files differ from it), for the provenance block of every report. Without git,
//! or when the package is not the top of a clone (a tarball, a vendored copy), it is
//! "unknown"; a packager may set `POLISHBOT_GIT_COMMIT` in the build environment instead.
use std::path::Path;
use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    let text = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (out.status.success() && !text.is_empty()).then_some(text)
}

fn main() {
    println!("cargo:rerun-if-env-changed=POLISHBOT_GIT_COMMIT");
    println!("cargo:rerun-if-changed=build.rs");
    if let Ok(given) = std::env::var("POLISHBOT_GIT_COMMIT") {
        println!("cargo:rustc-env=POLISHBOT_GIT_COMMIT={given}");
        return;
    }
    let here = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let top = git(&["rev-parse", "--show-toplevel"]);
    let ours = top.is_some_and(|t| {
        let (a, b) = (
            Path::new(&t).canonicalize(),
            Path::new(&here).canonicalize(),
        );
        matches!((a, b), (Ok(a), Ok(b)) if a == b)
    });
    let commit = if ours {
        git(&["rev-parse", "HEAD"])
    } else {
        None
    };
    let Some(commit) = commit else {
        println!("cargo:rustc-env=POLISHBOT_GIT_COMMIT=unknown");
        return;
    };
    // Rerun on a commit, a checkout or staging (HEAD, the branch's ref, the index) and on any
    // edit of the sources (the dirty mark).
    for path in ["HEAD", "index"] {
        if let Some(p) = git(&["rev-parse", "--git-path", path]) {
            println!("cargo:rerun-if-changed={p}");
        }
    }
    if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
        if let Some(p) = git(&["rev-parse", "--git-path", &r]) {
            println!("cargo:rerun-if-changed={p}");
        }
    }
    for p in [
        "src",
        "Cargo.toml",
        "Cargo.lock",
        "firmware-protocol",
        "assets",
    ] {
        println!("cargo:rerun-if-changed={p}");
    }
    let dirty = git(&["status", "--porcelain", "--untracked-files=no"]).is_some();
    let suffix = if dirty { "-dirty" } else { "" };
    println!("cargo:rustc-env=POLISHBOT_GIT_COMMIT={commit}{suffix}");
}

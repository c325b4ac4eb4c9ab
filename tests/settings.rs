//! A typo in a `--config` file is refused before any work, in one line naming the file, the
//! line and the key with its table (every config denies unknown fields).
mod common;

use common::{one_line_failure, pair_args, polishbot, tempdir};

/// Runs `args` with `text` as the `--config` file and checks the one-line refusal holds every
/// needle and the file's name.
fn refused_with(text: &str, args: &[&str], needles: &[&str]) {
    let tmp = tempdir();
    let file = tmp.path().join("typo.toml");
    std::fs::write(&file, text).unwrap();
    let out = polishbot()
        .current_dir(tmp.path())
        .arg("--config")
        .arg(&file)
        .args(args)
        .output()
        .expect("start polishbot");
    let line = one_line_failure(&out);
    for needle in needles.iter().chain(&["typo.toml"]) {
        assert!(line.contains(needle), "{needle:?} not in {line:?}");
    }
}

#[test]
fn a_typo_in_a_stage_section_names_the_file_the_line_and_the_key() {
    let inspect = pair_args("inspect");
    // regions (a stage config inside inspect's settings)
    refused_with(
        "[regions]\ntolerance = 0.05\ntolerence = 0.1\n",
        &inspect,
        &["line 3", "unknown key `regions.tolerence`"],
    );
    // the outlier filter
    refused_with(
        "[filter]\nkk = 30\n",
        &inspect,
        &["line 2", "unknown key `filter.kk`"],
    );
    // registration, its own command's config (top level)
    let register = pair_args("register");
    refused_with(
        "voxel = 1.0\nfeature_max_n = 50\n",
        &register,
        &["line 2", "unknown key `feature_max_n`"],
    );
}

//! The comparison's settings: unknown keys refused with the file, the line and the key; the
//! old keys and the nested tables read; the tolerance an input that sets the thresholds.
mod common;

use common::tempdir;
use polishbot::compare::{CompareConfig, DEFAULT_TOLERANCE};
use polishbot::regions::RegionConfig;

/// Runs `inspect --config` with `toml` (the inputs need not exist: settings are read first).
fn inspect_with_config(toml: &str) -> (std::process::Output, std::path::PathBuf) {
    let tmp = tempdir();
    common::run_with_config("inspect", tmp.path(), toml)
}

#[test]
fn a_typo_under_compare_adaptive_is_a_one_line_error_naming_the_key() {
    for (toml, key, line) in [
        (
            "[compare]\nmax_distance = 1.0\n\n[compare.adaptive]\nlambda = 0.43\nrefine_abov = 0.1\n",
            "refine_abov",
            6,
        ),
        ("[compare.adaptive.fill]\nlack_of_fitt = 3.0\n", "lack_of_fitt", 2),
        ("[compare]\ntolerance = 0.1\n", "tolerance", 2),
    ] {
        let (out, config) = inspect_with_config(toml);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{err}");
        let want = format!("{}: line {line}: ", config.display());
        assert!(lines[0].contains(&want), "{err}");
        // the key with its table path: `compare.adaptive.refine_abov`
        assert!(lines[0].contains("`compare."), "{err}");
        assert!(lines[0].contains(&format!(".{key}`")), "{err}");
    }
}

#[test]
fn old_keys_and_nested_tables_are_read() {
    let cfg: CompareConfig = toml::from_str(
        "[adaptive]\nrefine_above = 0.04\ndensify_above = inf\npeak_fit = false\n\
         [adaptive.peak]\nmin_window = 2.5\n[adaptive.densify]\nmin_cluster = 3\n\
         [adaptive.fill]\nlack_of_fit = 2.5\n",
    )
    .unwrap();
    let a = &cfg.adaptive;
    assert_eq!(a.refine_above, Some(0.04));
    assert_eq!(a.densify_above, Some(f64::INFINITY));
    assert!(!a.peak_fit && a.model_fill);
    assert_eq!(a.peak.min_window, 2.5);
    assert_eq!(a.densify.min_cluster, 3);
    assert_eq!(a.fill.lack_of_fit, 2.5);
    // Untouched keys keep the defaults.
    let defaults = CompareConfig::default();
    assert_eq!(a.fill.min_share, defaults.adaptive.fill.min_share);
    assert_eq!(
        a.densify.min_coverage,
        defaults.adaptive.densify.min_coverage
    );
}

#[test]
fn the_tolerance_sets_the_thresholds_unless_they_are_given() {
    // The comparison's default tolerance is inspect's (`[regions] tolerance`).
    assert_eq!(DEFAULT_TOLERANCE, RegionConfig::default().tolerance);
    let mut cfg = CompareConfig::default();
    assert_eq!(cfg.tolerance, DEFAULT_TOLERANCE);
    // Before 2026-12-02 inspect set refine_above = tolerance, densify_above = tolerance / 2.
    for tolerance in [0.0, 0.02, 0.05, 0.1, 0.3] {
        cfg.tolerance = tolerance;
        assert_eq!(cfg.refine_above(), tolerance);
        assert_eq!(cfg.densify_above(), 0.5 * tolerance);
    }
    cfg.adaptive.refine_above = Some(0.07);
    cfg.adaptive.densify_above = Some(f64::INFINITY);
    assert_eq!(cfg.refine_above(), 0.07);
    assert_eq!(cfg.densify_above(), f64::INFINITY);
}

//! Hostile `--config` settings of `inspect` and `register`: each out-of-range value is one line
//! of error naming the file, the line, the table and the key (no panic, no hang, no exit 0 with
//! a changed answer), and the edge values the docs call valid still load.
mod common;

use common::tempdir;

/// Asserts that `toml` is refused by `command` in one line: `config: line N: [table] `key``.
fn assert_refused(command: &str, toml: &str, table: &str, key: &str, line: usize) {
    let tmp = tempdir();
    let (out, config) = common::run_with_config(command, tmp.path(), toml);
    let err = String::from_utf8_lossy(&out.stderr);
    let err = err.trim_end();
    assert_eq!(out.status.code(), Some(1), "{toml}: {err}");
    assert_eq!(err.lines().count(), 1, "{toml}: {err}");
    assert!(!err.contains("panicked"), "{toml}: {err}");
    let place = format!("{}: line {line}: ", config.display());
    assert!(err.contains(&place), "{toml}: expected {place:?} in {err}");
    let scope = match table.is_empty() {
        true => format!("`{key}`"),
        false => format!("[{table}] `{key}`"),
    };
    assert!(err.contains(&scope), "{toml}: expected {scope:?} in {err}");
}

#[test]
fn register_settings_out_of_range_name_the_key() {
    let cases = [
        ("clique_time_budget = inf", "clique_time_budget"),
        ("clique_time_budget = nan", "clique_time_budget"),
        ("clique_time_budget = 1e308", "clique_time_budget"),
        ("clique_time_budget = 0", "clique_time_budget"),
        ("feature_max_nn = 0", "feature_max_nn"),
        ("max_cliques = 0", "max_cliques"),
        ("top_k = 0", "top_k"),
        ("max_correspondences = 0", "max_correspondences"),
        ("max_keypoints = 0", "max_keypoints"),
        ("icp_max_points = 0", "icp_max_points"),
        ("icp_max_iterations = 0", "icp_max_iterations"),
        ("min_clique = 0", "min_clique"),
        ("min_fitness = nan", "min_fitness"),
        ("icp_relative_tolerance = -1.0", "icp_relative_tolerance"),
        ("compat_sigma = -1.0", "compat_sigma"),
        ("compat_min_score = nan", "compat_min_score"),
        ("feature_radius = -1.0", "feature_radius"),
        ("voxel = 0.0", "voxel"),
        ("voxel = -1.0", "voxel"),
        ("voxel = nan", "voxel"),
        ("rank_candidates = 0", "rank_candidates"),
        ("rank_candidates = 1001", "rank_candidates"),
        ("rank_candidates = 4611686018427387904", "rank_candidates"),
        ("feature_max_nn = 1000000000", "feature_max_nn"),
        ("icp_max_iterations = 10001", "icp_max_iterations"),
        ("max_cliques = 9223372036854775807", "max_cliques"),
        ("top_k = 100001", "top_k"),
        ("max_keypoints = 100000001", "max_keypoints"),
        ("icp_max_points = 100000001", "icp_max_points"),
        ("max_correspondences = 1000001", "max_correspondences"),
        ("min_clique = 1000001", "min_clique"),
        ("min_inliers = 1000001", "min_inliers"),
    ];
    for (setting, key) in cases {
        let toml = format!("# hostile\n[register]\n{setting}\n");
        assert_refused("inspect", &toml, "register", key, 3);
        // `register` reads the same settings at the top level of its file.
        assert_refused("register", &format!("\n{setting}\n"), "", key, 2);
    }
}

#[test]
fn compare_settings_out_of_range_name_the_key() {
    let many: Vec<String> = (1..=10_000)
        .map(|i| format!("{}", i as f64 * 1e-3))
        .collect();
    let many = format!("[compare.adaptive]\nradii = [{}]", many.join(", "));
    let cases = [
        (
            "[compare.adaptive]\nradii = [1e308]",
            "compare",
            "adaptive.radii",
        ),
        (many.as_str(), "compare", "adaptive.radii"),
        (
            "[compare.adaptive]\nradii = [0.5, 0.4]",
            "compare",
            "adaptive.radii",
        ),
        ("[compare.adaptive]\nh = -1.0", "compare", "adaptive.h"),
        (
            "[compare.adaptive]\nlambda = nan",
            "compare",
            "adaptive.lambda",
        ),
        (
            "[compare.adaptive]\nnoise = nan",
            "compare",
            "adaptive.noise",
        ),
        (
            "[compare.adaptive]\nnoise = -0.01",
            "compare",
            "adaptive.noise",
        ),
        (
            "[compare.adaptive]\nsimilarity = 2.0",
            "compare",
            "adaptive.similarity",
        ),
        (
            "[compare.adaptive]\nmax_normal_angle = -10.0",
            "compare",
            "adaptive.max_normal_angle",
        ),
        (
            "[compare.adaptive]\nmax_normal_angle = 1000.0",
            "compare",
            "adaptive.max_normal_angle",
        ),
        (
            "[compare.adaptive]\nrefine_above = nan",
            "compare",
            "adaptive.refine_above",
        ),
        (
            "[compare.adaptive.densify]\nmin_coverage = 2.0",
            "compare",
            "adaptive.densify.min_coverage",
        ),
        (
            "[compare.adaptive.fill]\nmin_share = -1.0",
            "compare",
            "adaptive.fill.min_share",
        ),
        (
            "[compare.adaptive.peak]\nmin_window = 0.0",
            "compare",
            "adaptive.peak.min_window",
        ),
        (
            "[compare]\nmethod = \"classic\"\nradius = 1e308",
            "compare",
            "radius",
        ),
        ("[compare]\nradius = -1.0", "compare", "radius"),
        ("[compare]\nmax_distance = inf", "compare", "max_distance"),
        (
            "[compare]\nregistration_error = nan",
            "compare",
            "registration_error",
        ),
        ("[compare]\nmin_points = 0", "compare", "min_points"),
        ("[regions]\ngap_factor = nan", "regions", "gap_factor"),
        ("[regions]\ngap_factor = 0.0", "regions", "gap_factor"),
        ("[regions]\nmin_points = 0", "regions", "min_points"),
        ("[regions]\nmin_coverage = 2.0", "regions", "min_coverage"),
        ("[core]\nuniform_ratio = nan", "core", "uniform_ratio"),
        ("[core]\nuniform_ratio = 2.0", "core", "uniform_ratio"),
        ("[core]\ncount = 0", "core", "count"),
        ("[suggest]\nstep_deg = 0.0", "suggest", "step_deg"),
        (
            "[suggest]\ntable_axis = [0.0, 0.0, 0.0]",
            "suggest",
            "table_axis",
        ),
    ];
    for (toml, table, key) in cases {
        // the setting is on the file's last line
        let line = toml.lines().count();
        assert_refused("inspect", toml, table, key, line);
    }
}

#[test]
fn edge_values_the_docs_call_valid_still_load() {
    let toml = "[compare]\nmax_distance = 0.0\nmin_points = 1\n\
                [compare.adaptive]\nsimilarity = 0.0\ngamma = 0.0\ndensify_above = inf\n\
                refine_above = inf\nmax_normal_angle = 180.0\nradii = [0.3, 0.6]\n\
                [register]\nmin_inliers = 0\nrank_candidates = 1000\nclique_time_budget = 3600.0\n\
                feature_max_nn = 10000\nicp_max_iterations = 10000\nmax_cliques = 10000000\n\
                top_k = 100000\nmax_keypoints = 100000000\nicp_max_points = 100000000\n\
                max_correspondences = 1000000\nmin_clique = 3\n\
                [regions]\nmin_coverage = 0.0\n[core]\nuniform_ratio = 1.0\ncount = 1\n";
    let tmp = tempdir();
    let (out, _) = common::run_with_config("inspect", tmp.path(), toml);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    // settings accepted: the first error is the missing input
    assert!(err.contains("missing.ply"), "{err}");
}

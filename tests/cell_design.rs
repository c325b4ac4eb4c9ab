//! Cell design (issue 51): the share of femoral_dm's articular surface a cell reaches, scored
//! through the planner's IK and collision model (`polishbot::design`).
mod common;

use polishbot::cloud::Units;
use polishbot::design::{self, Candidate, DesignConfig, Part, SourceCell};

use common::{calib, shared_data};

/// femoral_dm and its articular surface, sampled as the design samples them.
fn femoral_part(cfg: &DesignConfig) -> Part {
    let reference = design::load_mesh(&shared_data("femoral_dm.stl"), Some(Units::M)).unwrap();
    let surface =
        design::load_mesh(&shared_data("femoral_dm_contact.stl"), Some(Units::M)).unwrap();
    Part::new(&reference, &surface, cfg).unwrap()
}

/// Survey of hand-picked cells (numbers only; `--ignored --nocapture`).
#[test]
#[ignore]
fn survey_of_hand_picked_cells() {
    let cfg = DesignConfig {
        setups: 1,
        ..DesignConfig::default()
    };
    let part = femoral_part(&cfg);
    let source = SourceCell::load(&calib("turntable")).unwrap();
    let mut cases = Vec::new();
    let mounts = [
        [0.0, -1.0, 0.0],
        [0.0, -0.966, 0.259],
        [0.0, -0.966, -0.259],
    ];
    for (axis, mount) in mounts.iter().map(|m| ([0.0, -1.0, 0.0], *m)) {
        for centre in [
            [0.0, 0.20, 0.16],
            [0.0, 0.24, 0.21],
            [0.0, 0.22, 0.10],
            [0.0, 0.26, 0.26],
        ] {
            for shank_m in [0.0193, 0.035, 0.05] {
                cases.push(Candidate {
                    axis,
                    mount,
                    centre,
                    shank: 0,
                    shank_m,
                });
            }
        }
    }
    for c in cases {
        match design::assess(&part, &source, &cfg, &c) {
            Ok(d) => println!(
                "mount {:?} centre {:?} shank {:.1}: {:.1} % {:?}",
                c.mount,
                c.centre,
                c.shank_m * 1e3,
                100.0 * d.coverage,
                d.refused
            ),
            Err(e) => println!("mount {:?} centre {:?}: {e}", c.mount, c.centre),
        }
    }
}

/// The shipped cell for femoral components (calibration/femoral/, written by `cell design`)
/// scores again what its design.json says when assessed apart from the search (same samples,
/// same rules), and no less than the 85 % the design reached with the part mounted once (the
/// notch walls and the condyles' side faces stay out, docs/ALGORITHMS.md "Cell design"); with
/// the second setup design.json names, the two reach issue 51's 95 %; every sample it leaves
/// out names a rule and a table angle.
#[test]
fn the_shipped_femoral_cell_reaches_what_its_design_says() {
    let text = std::fs::read_to_string(calib("femoral/design.json")).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&text).unwrap();
    let c = &doc["candidate"];
    let v3 = |k: &str| -> [f64; 3] { std::array::from_fn(|i| c[k][i].as_f64().unwrap()) };
    let candidate = Candidate {
        axis: v3("axis"),
        mount: v3("mount"),
        centre: v3("centre"),
        shank: 0,
        shank_m: c["shank_m"].as_f64().unwrap(),
    };
    let cfg = DesignConfig::default();
    let part = femoral_part(&cfg);
    let source = SourceCell::load(&calib("turntable")).unwrap();
    let d = design::assess(&part, &source, &cfg, &candidate).unwrap();
    let said = doc["coverage"].as_f64().unwrap();
    println!(
        "shipped cell: {:.1} % ({:?})",
        100.0 * d.coverage,
        d.refused
    );
    assert!(
        (d.coverage - said).abs() < 1e-12,
        "{} vs {said}",
        d.coverage
    );
    assert!(d.coverage >= 0.85, "{}", d.coverage);
    // a second fixturing (the part turned on the table) brings the faces along the table
    // axis into reach: issue 51's 95 % over the two setups, as design.json says
    for (k, s) in d.setups.iter().enumerate() {
        println!(
            "setup {}: part direction {:?}: {:.1} % alone, {:.1} % together",
            k + 1,
            s.mount,
            100.0 * s.coverage,
            100.0 * s.union_coverage
        );
    }
    assert_eq!(d.setups.len(), 2);
    assert_eq!(d.setups[0].mount, candidate.mount);
    let union = design::union_coverage(&d);
    let said = doc["setups"][1]["union_coverage"].as_f64().unwrap();
    assert!((union - said).abs() < 1e-12, "{union} vs {said}");
    assert!(union >= 0.95, "{union}");
    for s in d.samples.iter().filter(|s| s.angle_deg.is_none()) {
        assert!(s.refused_by.is_some() && s.nearest_angle_deg.is_some());
    }
    // the workcell written beside it places the part as the candidate does
    let wc = polishbot::robot::Workcell::load(&calib("femoral/workcell.toml")).unwrap();
    for (r, row) in d.robot_from_reference.iter().enumerate() {
        for (k, v) in row.iter().enumerate() {
            assert!((wc.robot_from_reference[(r, k)] - v).abs() < 1e-6);
        }
    }
}

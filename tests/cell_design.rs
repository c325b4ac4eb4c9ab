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

/// The shipped femoral cell's candidate (calibration/femoral/design.json) and that file.
fn shipped_candidate() -> (Candidate, serde_json::Value) {
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
    (candidate, doc)
}

/// The share of the articular surface the shipped cell reaches on implant designs it was not
/// designed on (tests/common/variants.rs: femoral_dm scaled and mirrored about the fixture
/// point, synth's parametric part), scored as `cell design` scores femoral_dm: setup 1, setup 2
/// (design.json's second mounting) alone, and the two together; the left knee also on a
/// mirrored fixture (both mountings mirrored). Numbers only (`--ignored --nocapture`).
#[test]
#[ignore]
fn survey_of_unseen_designs_in_the_shipped_cell() {
    use common::variants::{self, Variant, VARIANTS};
    let cfg = DesignConfig {
        setups: 1,
        ..DesignConfig::default()
    };
    let source = SourceCell::load(&calib("turntable")).unwrap();
    let (first, doc) = shipped_candidate();
    let second: [f64; 3] = std::array::from_fn(|i| doc["setups"][1]["mount"][i].as_f64().unwrap());
    let mut parts = vec![(
        "femoral_dm".to_string(),
        variants::variant_meshes(&Variant {
            name: "femoral_dm",
            scale: 1.0,
            mirror: false,
        }),
        false,
    )];
    for v in VARIANTS {
        let meshes = variants::variant_meshes(&v);
        if v.mirror {
            parts.push((
                format!("{} (mirrored fixture)", v.name),
                meshes.clone(),
                true,
            ));
        }
        parts.push((v.name.to_string(), meshes, false));
    }
    parts.push((
        "parametric part".into(),
        variants::parametric_meshes(),
        false,
    ));
    for (name, (mesh, surface), mirror) in &parts {
        let part = Part::new(mesh, surface, &cfg).unwrap();
        let at = |mount: [f64; 3]| {
            let mount = if *mirror {
                variants::mirrored(mount)
            } else {
                mount
            };
            let c = Candidate {
                mount,
                ..first.clone()
            };
            design::assess(&part, &source, &cfg, &c).unwrap()
        };
        let (one, two) = (at(first.mount), at(second));
        let n = one.samples.len() as f64;
        let union = (one.samples.iter().zip(&two.samples))
            .filter(|(a, b)| a.angle_deg.is_some() || b.angle_deg.is_some())
            .count() as f64;
        let mut why: Vec<_> = one.refused.iter().collect();
        why.sort_by_key(|w| std::cmp::Reverse(*w.1));
        println!(
            "| {name} | {:.1} % | {:.1} % | {:.1} % | {:?} |",
            100.0 * one.coverage,
            100.0 * two.coverage,
            100.0 * union / n,
            &why[..why.len().min(3)]
        );
    }
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
    let (candidate, doc) = shipped_candidate();
    // design.json was written with table angles every 10 degrees in the final score and the
    // setups (`cell design` now scores them every 5, the planner's step)
    let cfg = DesignConfig {
        final_step_deg: 10.0,
        ..DesignConfig::default()
    };
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

/// The design's family members (`design::family`, printed by `cell design`) are the part scaled
/// about the point the cell mounts on the table centre: femoral_dm's samples scaled 0.85 and
/// 1.15 x by `family::member` are the samples of the meshes this suite scales itself about the
/// shipped cell's fixture point (tests/common/variants.rs, which the held-out plans use).
#[test]
fn the_designs_family_members_are_the_part_scaled_about_its_fixture_point() {
    use common::variants::{self, VARIANTS};
    let cfg = DesignConfig::default();
    let part = femoral_part(&cfg);
    let p0 = variants::femoral_fixture_point();
    assert!(
        (part.centroid - p0).norm() < 1e-3,
        "the cell mounts {p0:?}, the part's centroid is {:?}",
        part.centroid
    );
    for v in VARIANTS.iter().filter(|v| !v.mirror) {
        let member = design::family::member(&part, v.scale, false);
        let (mesh, surface) = variants::variant_meshes(v);
        let scaled = Part::new(&mesh, &surface, &cfg).unwrap();
        assert!((member.centroid - scaled.centroid).norm() < 1e-3);
        let worst = (member.surface.iter().zip(&scaled.surface))
            .map(|(a, b)| (a.0 - b.0).norm().max((a.1 - b.1).norm()))
            .fold(0.0, f64::max);
        println!("{}: samples agree within {worst:.2e}", v.name);
        assert!(worst < 1e-3, "{}: {worst}", v.name);
    }
}

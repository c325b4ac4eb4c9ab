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
    let cfg = DesignConfig::default();
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

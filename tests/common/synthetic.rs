//! A synth case's inspection folder made from its truth (no scan, no comparison): the planner
//! tests' input.
use std::path::Path;

use nalgebra::Vector3;
use polishbot::synth::{synth, SynthCase, SynthConfig, Truth};

/// Writes an inspection folder (deviations.csv, regions.json per DESIGN.md) for the synth case
/// of `config`: core points are the reference samples, distances the true
/// deviations, regions the points beyond `tolerance` grouped by the defect that dominates them.
pub fn inspection(dir: &Path, config: &SynthConfig) -> Truth {
    inspection_of(dir, synth(config).expect("synth"))
}

/// The demo's part (cli/demo.rs `demo_config`, seed 1) at 200,000 reference samples (the
/// planner's core points here; tests/common `case`'s density), its defects where the arm
/// reaches, as a perfect inspection.
pub fn demo_like(dir: &Path) -> polishbot::repair::Inspection {
    let config = SynthConfig {
        seed: 1,
        defects: 5,
        height_range: [0.12, 0.4],
        width_range: [2.0, 4.0],
        pit_share: 0.2,
        ridge_share: 0.2,
        reference_points: 200_000,
        scan_points: 1_000,
        ..SynthConfig::default()
    };
    let reachable = polishbot::cell::reachable_sites(
        &super::shipped_cell(),
        polishbot::cell::SITE_AXIS_MARGIN_DEG,
    )
    .unwrap();
    let case = polishbot::synth::synth_at(&config, &reachable).expect("synth");
    inspection_of(dir, case);
    polishbot::repair::Inspection::load(dir).expect("inspection")
}

/// As [`inspection`], for a case already made (`synth_at`: defects where the arm reaches).
pub fn inspection_of(dir: &Path, case: SynthCase) -> Truth {
    let tolerance = 0.05;
    let area: f64 = (0..case.mesh.faces.len())
        .map(|i| case.mesh.face_normal_area(i).1)
        .sum();
    let share = area / case.reference.len() as f64;
    let normals = case.reference.normals.as_ref().expect("normals");
    let truth = case.truth;
    let mut csv = String::from(
        "x,y,z,nx,ny,nz,distance,uncertainty,significant,radius,n_ref,n_scan,region\n",
    );
    let mut groups: Vec<Vec<(usize, f64)>> = vec![Vec::new(); truth.defects.len()];
    for (i, (p, n)) in case.reference.points.iter().zip(normals).enumerate() {
        let d = truth.deviation_at(p, n);
        let mut region = -1i64;
        if d.abs() > tolerance {
            let (k, _) = truth
                .defects
                .iter()
                .enumerate()
                .map(|(k, def)| (k, def.displacement(p, n).abs()))
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .expect("defects");
            groups[k].push((i, d));
            region = k as i64;
        }
        csv.push_str(&format!(
            "{},{},{},{},{},{},{},0.01,{},0.5,20,20,{}\n",
            p.x,
            p.y,
            p.z,
            n.x,
            n.y,
            n.z,
            d,
            u8::from(d.abs() > 0.02),
            region
        ));
    }
    let mut regions = Vec::new();
    for (k, g) in groups.iter().enumerate().filter(|(_, g)| !g.is_empty()) {
        let count = g.len() as f64;
        let c = g.iter().fold(Vector3::zeros(), |s, (i, _)| {
            s + case.reference.points[*i].coords
        }) / count;
        let n = g
            .iter()
            .fold(Vector3::zeros(), |s, (i, _)| s + normals[*i])
            .normalize();
        let peak = g
            .iter()
            .map(|x| x.1)
            .fold(0.0, |a: f64, b| if b.abs() > a.abs() { b } else { a });
        regions.push(serde_json::json!({
            "id": k, "centroid": [c.x, c.y, c.z], "normal": [n.x, n.y, n.z],
            "area": share * count, "peak": peak,
            "mean": g.iter().map(|x| x.1).sum::<f64>() / count,
            "volume": g.iter().map(|x| share * (x.1.abs() - tolerance)).sum::<f64>(),
            "points": g.len(), "repairable": peak > 0.0,
        }));
    }
    std::fs::create_dir_all(dir).expect("mkdir");
    std::fs::write(dir.join("deviations.csv"), csv).expect("write csv");
    let regions = serde_json::json!({
        "tolerance": tolerance, "spacing": 0.5, "gap": 1.25, "verdict": "repairable",
        "regions": regions,
    });
    std::fs::write(dir.join("regions.json"), regions.to_string()).expect("write regions");
    truth
}

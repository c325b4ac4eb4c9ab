//! Grinding planner: plans from inspections of synthetic cases (truth from `synth`) checked
//! through the robot model, unreachable regions reported, bad input refused, plan.json, CLI.
mod common;

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use polishbot::cloud::Units;
use polishbot::plan::{plan, Inspection, Plan, PlanConfig, PlanError, SegmentKind};
use polishbot::robot::{Robot, Workcell};
use polishbot::synth::{synth, SynthConfig};

fn calib(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration")
        .join(name)
}

fn dofbot() -> (Robot, Workcell) {
    let robot = Robot::load(
        &calib("dofbot.urdf"),
        &calib("tool.toml"),
        &calib("servos.toml"),
    )
    .expect("calibration");
    let wc = Workcell::load(&calib("workcell.toml")).expect("workcell");
    (robot, wc)
}

/// Writes an inspection folder (deviations.csv, regions.json per DESIGN.md) for a synth case
/// of the real femoral component: core points are the reference samples, distances the true
/// deviations, regions the points beyond `tolerance` grouped by the defect that dominates them.
fn synthetic_inspection(dir: &Path, seed: u64, defects: usize) -> polishbot::synth::Truth {
    let cfg = SynthConfig {
        seed,
        mesh: Some(common::shared_data("femoral_dm.stl")),
        surface: Some(common::shared_data("femoral_dm_contact.stl")),
        units: Some(Units::M),
        reference_points: 60_000,
        scan_points: 1_000,
        defects,
        ..SynthConfig::default()
    };
    let case = synth(&cfg).expect("synth");
    let tolerance = 0.05;
    let area: f64 = (0..case.mesh.faces.len())
        .map(|i| case.mesh.face_normal_area(i).1)
        .sum();
    let share = area / case.reference.len() as f64;
    let normals = case.reference.normals.as_ref().expect("normals");
    let truth = case.truth;
    let mut csv = String::from("x,y,z,nx,ny,nz,distance,uncertainty,significant,radius,n_ref,n_scan,region\n");
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
        let c = g
            .iter()
            .fold(Vector3::zeros(), |s, (i, _)| s + case.reference.points[*i].coords)
            / count;
        let n = g
            .iter()
            .fold(Vector3::zeros(), |s, (i, _)| s + normals[*i])
            .normalize();
        let peak = g.iter().map(|x| x.1).fold(0.0, |a: f64, b| if b.abs() > a.abs() { b } else { a });
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

/// Finite-difference velocity, acceleration and jerk of the samples against the joint limits.
fn worst_derivative_ratio(plan: &Plan, robot: &Robot) -> f64 {
    let h = plan.period;
    let mut worst: f64 = 0.0;
    for (j, spec) in robot.joints.iter().enumerate() {
        let q: Vec<f64> = plan.samples.iter().map(|s| s.q[j]).collect();
        for w in q.windows(4) {
            let v = (w[1] - w[0]) / h;
            let a = (w[2] - 2.0 * w[1] + w[0]) / (h * h);
            let jk = (w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]) / (h * h * h);
            worst = worst
                .max(v.abs() / spec.velocity)
                .max(a.abs() / spec.acceleration)
                .max(jk.abs() / spec.jerk);
        }
        for v in &q {
            assert!(*v >= spec.lower - 1e-9 && *v <= spec.upper + 1e-9, "{} out of limits", spec.name);
        }
    }
    worst
}

fn polyline_distance(p: &Vector3<f64>, line: &[Vector3<f64>]) -> f64 {
    polishbot::plan::check::polyline_distance(p, line)
}

#[test]
fn plan_from_a_synthetic_inspection_meets_every_acceptance_number() {
    let tmp = common::tempdir();
    let truth = synthetic_inspection(tmp.path(), 11, 6);
    let inspection = Inspection::load(tmp.path()).expect("load inspection");
    let (robot, wc) = dofbot();
    let cfg = PlanConfig::default();
    let p = plan(&inspection, &robot, &wc, &cfg).expect("plan");
    println!("defects: {:?}", truth.defects.iter().map(|d| (d.kind, d.height, d.width)).collect::<Vec<_>>());
    println!("metrics: {:#?}", p.metrics);
    for r in &p.reachability.regions {
        println!("region {r:?}");
    }
    println!("unreachable: {} (first: {:?})", p.reachability.unreachable.len(), p.reachability.unreachable.first());
    assert!(!p.passes.is_empty(), "something must be ground");

    // limits by finite differences, within 1 %
    let worst = worst_derivative_ratio(&p, &robot);
    println!("worst derivative / limit: {worst:.4}");
    assert!(worst <= 1.01, "finite differences reach {worst} of a limit");

    // modelled tool tip against every planned path point and vice versa
    let tips: Vec<Vector3<f64>> = p.samples.iter().map(|s| robot.fk(&s.q).position).collect();
    let mut worst_path: f64 = 0.0;
    let mut feeds = Vec::new();
    for seg in p.segments.iter().filter(|s| s.kind == SegmentKind::Grind) {
        let pass = &p.passes[seg.pass.expect("grind segments name a pass")];
        let sampled = &tips[seg.first_sample..=seg.last_sample];
        for pt in &pass.points {
            let tip = Vector3::from(pt.tip_m);
            assert!((robot.fk(&pt.q).position - tip).norm() < 1e-9, "IK of a path point");
            worst_path = worst_path.max(polyline_distance(&tip, sampled));
        }
        let planned: Vec<Vector3<f64>> = pass.points.iter().map(|x| Vector3::from(x.tip_m)).collect();
        for t in sampled {
            worst_path = worst_path.max(polyline_distance(t, &planned));
        }
        // feed: tip speed over the middle of strokes long enough to cruise
        let n = sampled.len();
        if n > 40 {
            for w in sampled[n / 4..3 * n / 4].windows(2) {
                feeds.push((w[1] - w[0]).norm() / p.period * 1e3);
            }
        }
    }
    println!("worst path error {:.4} mm", worst_path * 1e3);
    assert!(worst_path * 1e3 <= 0.1);
    assert!(!feeds.is_empty());
    for f in &feeds {
        assert!((f - cfg.feed_mm_s).abs() <= 0.1 * cfg.feed_mm_s, "feed {f} mm/s");
    }

    // coverage of the reachable part of every planned region
    for r in p.reachability.regions.iter().filter(|r| r.repairable && r.layers > 0) {
        if r.reachable_points > 0 {
            assert!(r.coverage_of_reachable >= 0.95, "region {} coverage {}", r.id, r.coverage_of_reachable);
        }
        assert!((r.unreachable_share - (1.0 - r.reachable_points as f64 / r.points as f64)).abs() < 1e-12);
    }
    // every left-out point says why
    assert!(p.reachability.unreachable.iter().all(|u| !u.reason.is_empty()));
}

//! Grinding planner speed: a whole rigid plan (raster, IK along every stroke with splits,
//! constant-feed strokes, transits, metrics, coverage, validation, frames) of about 5,000 path
//! points, and the removal plan of the demo case.
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use polishbot::motion::clearance::check_samples;
use polishbot::motion::collide::Scene;
use polishbot::motion::{plan_part, Inspection, PlanConfig, RegionInfo, SurfacePoint};
use polishbot::robot::{Robot, Workcell};

fn calib(n: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("calibration")
        .join(n)
}

/// A flat patch of the part (reference frame, facing -y like the distal surface the default
/// workcell presents to the arm) with one round bump of 0.95 mm, 24 mm across: 10 depth layers
/// of 11 raster lines.
fn inspection() -> Inspection {
    let centre = Point3::new(5.0, -35.0, -25.0);
    let mut points = Vec::new();
    for i in 0..=80 {
        for k in 0..=80 {
            let p = centre + Vector3::new(-20.0 + 0.5 * i as f64, 0.0, -20.0 + 0.5 * k as f64);
            let r = (p - centre).norm();
            let inside = r <= 12.0;
            points.push(SurfacePoint {
                position: p,
                normal: -Vector3::y(),
                distance: if inside {
                    0.95 * (1.0 - (r / 12.0).powi(2)) + 0.06
                } else {
                    0.0
                },
                uncertainty: 0.0,
                region: if inside { 0 } else { -1 },
            });
        }
    }
    let members: Vec<&SurfacePoint> = points.iter().filter(|p| p.region == 0).collect();
    let region = RegionInfo {
        id: 0,
        centroid: [centre.x, centre.y, centre.z],
        normal: [0.0, -1.0, 0.0],
        area: members.len() as f64 * 0.25,
        peak: 1.01,
        peak_lower_bound: false,
        mean: 0.5,
        volume: 100.0,
        points: members.len(),
        repairable: true,
        measured_share: 1.0,
        touches_unmeasured: false,
    };
    Inspection {
        dir: "bench".into(),
        tolerance: Some(0.05),
        regions: vec![region],
        points,
        fine: Vec::new(),
    }
}

/// The shipped arm and workcell.
fn cell() -> (Robot, Workcell) {
    let robot = Robot::load(
        &calib("dofbot.urdf"),
        &calib("tool.toml"),
        &calib("servos.toml"),
    )
    .expect("calibration");
    (
        robot,
        Workcell::load(&calib("workcell.toml")).expect("workcell"),
    )
}

/// Plans `insp` once (printing what it made), then measures `plan` on it as bench `name`.
fn measure(c: &mut Criterion, name: &str, insp: &Inspection, cfg: &PlanConfig) {
    let (robot, wc) = cell();
    let p = plan_part(insp, &robot, &wc, cfg).expect("plan");
    let r = &p.reachability.regions[0];
    println!(
        "{name}: {} path points ({} left out), {} passes, {} samples, {:.1} s predicted",
        r.path_points,
        r.unreachable_path_points,
        p.passes.len(),
        p.samples.len(),
        p.predicted_duration_s
    );
    let mut group = c.benchmark_group("plan");
    group.sample_size(10);
    group.bench_function(name, |b| {
        b.iter(|| plan_part(insp, &robot, &wc, cfg).expect("plan"))
    });
    // the collision check alone (issue 35's "10 us per checked sample"): every sample of the
    // plan under its segment's rule, a fresh scene per run (a scene remembers the samples it
    // found clear), the scene's k-d tree build included
    let samples = || p.samples.iter().map(|s| s.q.as_slice());
    // a removal plan's pressed samples are checked with its preload, as `run` re-checks them
    let mut collision = cfg.collision.clone();
    if let Some(r) = &p.removal {
        collision.press_mm = r.preload_mm;
    }
    let check = || {
        let scene = Scene::new(&insp.points, &robot, &wc, &collision);
        check_samples(samples(), &p.segments, &robot, &scene)
    };
    assert!(check().is_empty());
    group.bench_function(format!("check_{}_samples", p.samples.len()), |b| {
        b.iter(check)
    });
    group.finish();
}

fn bench(c: &mut Criterion) {
    measure(
        c,
        "plan_5000_path_points",
        &inspection(),
        &PlanConfig::rigid(),
    );
}

/// The demo case (issue 28's target: under 2 s): `polishbot demo`'s inspection planned in the
/// default (removal) mode. The demo runs once, before the measurement (about a minute).
fn bench_demo(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_polishbot"))
        .args(["demo", "--out"])
        .arg(dir.path())
        .stdout(std::process::Stdio::null())
        .status()
        .expect("polishbot demo");
    assert!(status.success(), "polishbot demo failed");
    let insp = Inspection::load(&dir.path().join("inspection")).expect("demo inspection");
    measure(c, "plan_demo_removal", &insp, &PlanConfig::default());
}

criterion_group!(benches, bench, bench_demo);
criterion_main!(benches);

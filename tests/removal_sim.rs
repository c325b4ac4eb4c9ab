//! The planner's removal prediction against the simulated cell's true law (issues 28/29): a
//! demo-like plan (the demo's defect settings placed where the arm reaches, a perfect
//! inspection) is ground along its exact joint trajectory by `sim::grind`'s own kinematics and
//! removal law (not the planner's) on the part as it is (nominal + deviation, normals by PCA
//! as `run --sim` gives them). With the linear law (exponents 1/1), the true k the planner's
//! (factor 1) and no k field, each planned region's removal must match the prediction within
//! [`WITHIN`], and each band of planned removal within [`BAND_WITHIN`]: the planner's model of
//! each contact (the spindle axis the arm holds there, the force and surface normal of the
//! part the ball really presses as the pass leaves it, its patch and dwell) is then the
//! simulator's physics. The same trajectory on the nominal surface is printed, not held:
//! there the ball presses only the preload, less than the plan expects on the excess.
//!
//! It can fail: with the contacts pressed at the preload on the nominal surface (the model
//! before `removal/press.rs`) the part took 1.08 / 1.23 / 1.27 / 1.36 / 1.09 x the plan
//! (`demo`, seed 1); with the force alone from the real penetration 1.16 / 1.19 / 1.29 / 1.01
//! (the bumps' slopes tilt the surface under the spindle, which near 10 degrees of tilt
//! changes the abrasive's speed by tens of percent); with every contact pressed on the part as
//! measured (the linear model, before `removal/sequence.rs`) 0.892-1.099 per region and
//! 1.42-2.19 per band where under 0.02 mm was planned. Measured now (exponents 1/1):
//! 1.008 / 0.996 / 0.940 / 0.969 on the part, per band 0.913-1.094, and 0.72-0.96 on the
//! nominal surface. With the simulator's default exponents 1.1/0.9 the law itself differs from
//! the planner's (`POLISHBOT_SIM_EXPONENTS=1.1,0.9 cargo test --release --test removal_sim --
//! --nocapture`). `POLISHBOT_SIM_DEMO=DIR` grinds a `demo --out DIR` instead (its plan.json
//! and inspection/, under the mount its plan was made with).
mod common;

use std::path::Path;

use nalgebra::Point3;
use polishbot::motion::dwell::{contact, reference_from_robot};
use polishbot::motion::{plan_part, Inspection, Plan, PlanConfig, SegmentKind};
use polishbot::preprocess::{estimate_normals, NormalConfig, Orientation};
use polishbot::robot::{Robot, Workcell};
use polishbot::sim::grind::{fk, GrindConfig, MountGive, ToolState, VirtualPart, SIM_STEP_S};
use polishbot::spatial::Neighbours;

/// Largest relative difference between the simulator's removal on the part and the plan's per
/// region (0.05): measured within 0.016 on the perfect inspection while every contact was
/// ground; with the tool lifting, 0.950-1.040 until each patch was centred where the ball
/// touches a sloped part (up-slope of its nominal contact), 0.961-1.001 since. Per point
/// (printed per band of planned removal) the simulator's removal over the plan's was
/// 0.46-0.61 / 0.79-0.96 / 1.07-1.17 under 0.02 / 0.02-0.1 / 0.1-0.2 mm before that, and
/// 1.02-1.24 / 1.00-1.03 / 0.93-0.98 after. The force at preload on the nominal surface was
/// 8-36 % off. Widened from 0.05 to 0.1 when the simulator's normals began to follow the
/// grind (`sim::grind::part`, re-estimated every 0.005 mm of removal) while the planner's stay
/// those measured before the pass: per region 0.910-1.059, per band 1.42-2.19 / 1.02-1.11 /
/// 0.78-0.97. A mid-pass normal in the planner (the surface with half the target gone, as its
/// force) gave 0.939-1.080 and was not kept; the planner's model of it is open (issue 28).
/// Widened from 0.1 to 0.12 when synth's site filter began to test a defect's rim with the
/// rim's own normals (`cell::reachable_sites`), which moved this part's defects: per region
/// 0.892-1.099 over its four regions; the mid-pass normal gave 0.892-1.247 on it. Narrowed to
/// 0.08 when the planner began to grind its pass in order (`removal::sequence`: each
/// contact pressed on the part as the contacts before it left it): 0.940-1.008 per region.
const WITHIN: f64 = 0.08;

/// Bands of planned removal for the per-point comparison, mm (upper ends).
const BANDS_MM: [f64; 3] = [0.02, 0.1, 0.2];

/// Largest relative difference between the simulator's removal and the plan's per band of
/// planned removal in a region (0.15): with the pass predicted in order 0.913-1.094 over the
/// bands of the four regions; with the linear model (every contact pressed on the part as
/// measured) 1.42-2.19 where under 0.02 mm was planned and 0.78-0.97 over 0.1 mm, the error
/// that left narrow peaks above the tolerance after the acceptance cases' grinds (issue 29).
const BAND_WITHIN: f64 = 0.15;

/// The simulated cell's truth for this test: the shipped tool, k as the planner's, no k
/// field, the exponents of `POLISHBOT_SIM_EXPONENTS` (pressure,speed; default 1,1).
fn truth(robot: &Robot) -> GrindConfig {
    let exponents: Vec<f64> = std::env::var("POLISHBOT_SIM_EXPONENTS")
        .unwrap_or_else(|_| "1,1".into())
        .split(',')
        .map(|v| v.trim().parse().expect("two numbers"))
        .collect();
    GrindConfig {
        k_factor: 1.0,
        k_noise: 0.0,
        pressure_exponent: exponents[0],
        speed_exponent: exponents[1],
        tip_offset_mm: robot.tool.tip_offset.map(|v| v * 1e3),
        ..GrindConfig::default()
    }
}

/// The mount's direction on both sides, the planner's tool.toml key and the simulator's:
/// `POLISHBOT_SIM_MOUNT` (`surface_normal` or `spindle_axis`, the shipped tool's); unset,
/// `recorded` (the plan's own in the demo mode: [`recorded_mount`]), else `surface_normal`.
/// Measured with `spindle_axis` (issue 50, the patch aimed `preload x tan` ahead,
/// `motion/aim.rs`): on the part 0.970 / 0.670 / 0.993 / 0.938 (regions 4 / 0 / 3 / 1), per
/// band 0.51-2.15: the planner measures the part's deviation and slope at the commanded point,
/// 0.7-0.9 mm from where the patch lands; measured where it lands, one contact presses 3.11 N
/// (the flank tilts the surface away from the axis, 1 / cos^2) and the force check refuses
/// the plan. Open: the spindle mount on a bumpy part is not held here yet (the flat plate's
/// closed form is, tests/mount_direction.rs).
fn mount(recorded: Option<String>) -> (&'static str, MountGive) {
    let named = std::env::var("POLISHBOT_SIM_MOUNT").ok().or(recorded);
    match named.as_deref().unwrap_or("surface_normal") {
        "spindle_axis" => ("spindle_axis", MountGive::SpindleAxis),
        _ => ("surface_normal", MountGive::SurfaceNormal),
    }
}

/// The mount a demo's plan was made with (`plan`, its plan.json's text): its provenance's
/// `removal_tool.compliance_direction`. Ground under the other mount the demo's first plan read
/// 0.46-0.63 of its prediction per region; under its own, 0.91-0.99 (2026-12-07). None for a
/// plan made before the key (the normal mount, [`mount`]'s fallback).
fn recorded_mount(plan: &str) -> Option<String> {
    let plan: serde_json::Value = serde_json::from_str(plan).unwrap();
    plan["provenance"]["config"]["removal_tool"]["compliance_direction"]
        .as_str()
        .map(str::to_string)
}

/// The part: every core point moved out by `lift` of its deviation, PCA normals turned
/// outward.
fn part(inspection: &Inspection, cfg: &GrindConfig, lift: impl Fn(f64) -> f64) -> VirtualPart {
    let points: Vec<Point3<f64>> = inspection
        .points
        .iter()
        .map(|p| p.position + p.normal * lift(p.distance))
        .collect();
    let mut cloud = polishbot::cloud::PointCloud::from_points(points);
    let normals = NormalConfig {
        orientation: Orientation::Unoriented,
        ..NormalConfig::default()
    };
    let mut n = estimate_normals(&cloud, &normals).unwrap().normals;
    for (v, p) in n.iter_mut().zip(&inspection.points) {
        if v.dot(&p.normal) < 0.0 {
            *v = -*v;
        }
    }
    cloud.normals = None;
    VirtualPart::new(cloud.points, n, cfg)
}

/// Grinds `part` along `plan`'s joint samples, linear between them, at the simulator's step.
fn grind(part: &mut VirtualPart, plan: &Plan, wc: &Workcell, cfg: &GrindConfig) {
    let back = wc.robot_from_reference.try_inverse().unwrap();
    let tip = cfg.tip_offset_mm.map(|v| v * 1e-3);
    let at = |q: &[f64]| {
        let (c, axis) = fk::tool(&std::array::from_fn(|k| q[k]), &tip);
        let c = back.transform_point(&c) * 1e3;
        (c, back.transform_vector(&axis).normalize())
    };
    let steps = (plan.period / SIM_STEP_S).round() as usize;
    let mut prev = at(&plan.samples[0].q).0;
    for w in plan.samples.windows(2) {
        for s in 1..=steps {
            let f = s as f64 / steps as f64;
            let q: Vec<f64> = w[0]
                .q
                .iter()
                .zip(&w[1].q)
                .map(|(a, b)| a + (b - a) * f)
                .collect();
            let (centre, axis) = at(&q);
            let velocity = (centre - prev) / SIM_STEP_S;
            prev = centre;
            let tool = ToolState {
                centre,
                axis,
                velocity,
            };
            part.grind_step(&tool, SIM_STEP_S, cfg);
        }
    }
}

/// Median and smallest spindle tilt from the normal over a region's contacts, degrees.
fn tilts(plan: &Plan, region: usize, robot: &Robot, wc: &Workcell) -> (f64, f64) {
    let back = reference_from_robot(wc);
    let ground: Vec<usize> = plan
        .segments
        .iter()
        .filter(|s| s.kind == SegmentKind::Grind && s.region == Some(region))
        .filter_map(|s| s.pass)
        .collect();
    let mut t: Vec<f64> = ground
        .iter()
        .map(|&i| {
            contact(&plan.passes[i], robot, &back)
                .tilt()
                .0
                .angle()
                .to_degrees()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0])
}

#[test]
fn the_simulator_removes_what_the_plan_predicts_per_region() {
    let mut robot = common::dofbot();
    // the demo mode's folder and its plan.json, read once
    let demo = std::env::var("POLISHBOT_SIM_DEMO").ok().map(|d| {
        let file = Path::new(&d).join("plan.json");
        let text = std::fs::read_to_string(&file).unwrap();
        (file, text)
    });
    let give = mount(demo.as_ref().and_then(|(_, text)| recorded_mount(text)));
    if let Some(toml::Value::Table(t)) = robot.tool.removal.as_mut() {
        t.insert("compliance_direction".into(), give.0.into());
    }
    let wc = Workcell::load(&common::calib("workcell.toml")).unwrap();
    let dir = common::tempdir();
    let (inspection, plan) = match demo {
        Some((file, text)) => {
            let d = file.parent().unwrap();
            let mut plan = Plan::parse(&file, &text).unwrap();
            let csv = std::fs::read_to_string(d.join("predicted.csv")).unwrap();
            let rows = polishbot::removal::fit::parse_predicted(&csv).unwrap();
            plan.removal.as_mut().expect("a removal plan").rows = rows;
            (Inspection::load(&d.join("inspection")).unwrap(), plan)
        }
        None => {
            let inspection = common::synthetic::demo_like(dir.path());
            let started = std::time::Instant::now();
            let plan = plan_part(&inspection, &robot, &wc, &PlanConfig::default()).expect("plan");
            println!("planned in {:.2} s", started.elapsed().as_secs_f64());
            (inspection, plan)
        }
    };
    let removal = plan.removal.as_ref().expect("a removal plan");
    let cfg = GrindConfig {
        compliance_direction: give.1,
        ..truth(&robot)
    };
    // the part as it is (the excess presses the ball deeper: force rate x (preload +
    // deviation), which the plan models), and the nominal surface the arm is commanded to
    let mut nominal = part(&inspection, &cfg, |_| 0.0);
    let mut real = part(&inspection, &cfg, |d| if d.is_finite() { d } else { 0.0 });
    grind(&mut nominal, &plan, &wc, &cfg);
    grind(&mut real, &plan, &wc, &cfg);
    let positions: Vec<Point3<f64>> = inspection.points.iter().map(|p| p.position).collect();
    let index = Neighbours::new(&positions);
    let mut rows = removal.rows.iter();
    let (mut ratios, mut band_ratios) = (Vec::new(), Vec::new());
    for r in &removal.regions {
        let (mut sim, mut deeper, mut predicted) = (0.0, 0.0, 0.0);
        let mut bands = [(0.0, 0.0); BANDS_MM.len() + 1];
        for row in rows.by_ref().take(r.core_points) {
            let i = index.nearest(&Point3::from(row.position)).unwrap().index;
            let planned = row.deviation - row.residual;
            sim += nominal.removal()[i];
            deeper += real.removal()[i];
            predicted += planned;
            let band = BANDS_MM.iter().take_while(|&&b| planned >= b).count();
            bands[band].0 += real.removal()[i];
            bands[band].1 += planned;
        }
        let per_band: Vec<f64> = bands.iter().map(|(s, p)| s / p).collect();
        band_ratios.extend(per_band.iter().copied().filter(|r| r.is_finite()));
        println!(
            "  sim/plan per point by planned removal (< {BANDS_MM:?} mm, above): {per_band:.3?}"
        );
        let (median, least) = tilts(&plan, r.region, &robot, &wc);
        let ratio = deeper / predicted;
        println!(
            "region {}: tilt median {median:.1} deg, min {least:.1} deg; removal sim/plan \
             {:.3} on the nominal surface, {ratio:.3} on the part ({} points)",
            r.region,
            sim / predicted,
            r.core_points
        );
        ratios.push(ratio);
    }
    assert!(!ratios.is_empty(), "no region planned");
    let unreachable = plan.reachability.unreachable.len();
    println!(
        "{} regions planned, {unreachable} unreachable contact points",
        ratios.len()
    );
    for ratio in ratios {
        assert!((ratio - 1.0).abs() <= WITHIN, "sim/plan {ratio}");
    }
    for ratio in band_ratios {
        assert!(
            (ratio - 1.0).abs() <= BAND_WITHIN,
            "sim/plan in a band of planned removal {ratio}"
        );
    }
}

//! Inspections of `synth` cases of the real femoral component, as `inspect` would write them
//! from a perfect measurement (tests/turntable.rs, tests/collision.rs), and the cases like
//! users' of issue 51 (defects uniform over the articular surface; tests/uniform.rs).
use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::Vector3;
use polishbot::motion::setups::SetupCell;
use polishbot::motion::{Inspection, Plan, PlanConfig, SurfacePoint};
use polishbot::regions::Region;
use polishbot::robot::{Robot, Turntable, Workcell};
use polishbot::synth::{synth, SynthConfig};

/// Deviation beyond which a core point belongs to a defect region, mm (regions' default).
const TOLERANCE: f64 = 0.05;

/// The cell of `calibration/DIR` (`""`: the default cell) and the planner's settings with
/// its fixed solids, as `plan` loads them.
pub fn cell(dir: &str) -> (Robot, Workcell, Option<Turntable>, PlanConfig) {
    let f = |name: &str| super::calib(&format!("{dir}{name}"));
    let robot = Robot::load(&f("dofbot.urdf"), &f("tool.toml"), &f("servos.toml")).unwrap();
    let wc = Workcell::load(&f("workcell.toml")).unwrap();
    let table = Turntable::load(&f("servos.toml"), &f("workcell.toml")).unwrap();
    let mut config = PlanConfig::rigid();
    let solids = polishbot::motion::collide::solids_beside(&f("workcell.toml")).unwrap();
    config.collision.solids.extend(solids);
    (robot, wc, table, config)
}

/// The setups of `calibration/DIR` (its workcell.toml, then `setup-N/` beside it, as `plan`
/// reads them), its robot and the planner's settings without the solids (each setup brings
/// its own).
pub fn setups(dir: &str) -> (Robot, Vec<SetupCell>, PlanConfig) {
    let f = |name: &str| super::calib(&format!("{dir}{name}"));
    let robot = Robot::load(&f("dofbot.urdf"), &f("tool.toml"), &f("servos.toml")).unwrap();
    let cells = polishbot::motion::setups::load(&f("workcell.toml"), &f("servos.toml")).unwrap();
    (robot, cells, PlanConfig::rigid())
}

/// The tool library of `calibration/DIR` as `plan` reads it (tool.toml and `tools/*.toml`,
/// largest ball first); with `alone`, the cell's tool.toml only (as before the library).
pub fn library(dir: &str, alone: bool) -> Vec<polishbot::motion::tools::ToolRobot> {
    let mut cfg = polishbot::robot::RobotConfig::default();
    cfg.use_cell(&super::calib(dir));
    let mut cell = cfg.read_cell().expect("read the cell");
    if alone {
        cell.tools.clear();
    }
    polishbot::motion::tools::ToolRobot::of_cell(&cell).expect("the tool library")
}

/// An inspection of a `synth` case of the real femoral component with `defects` random
/// defects on its articular surface (femoral_dm_contact.stl; placed by the seed, not for the
/// arm's reach): core points are the reference samples, distances the true deviations, a
/// region per defect of the points beyond the tolerance it dominates.
pub fn inspection(seed: u64, defects: usize) -> Inspection {
    of_case(&super::femoral_synth(seed, defects))
}

/// As [`inspection`], for any synth settings.
pub fn of_case(config: &SynthConfig) -> Inspection {
    let case = synth(config).expect("synth");
    let area: f64 = (0..case.mesh.faces.len())
        .map(|i| case.mesh.face_normal_area(i).1)
        .sum();
    let per_point = area / case.reference.len() as f64;
    let normals = case.reference.normals.clone().expect("normals");
    let defects = &case.truth.defects;
    let mut points = Vec::new();
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); defects.len()];
    for (p, n) in case.reference.points.iter().zip(&normals) {
        let d = case.truth.deviation_at(p, n);
        let owner = (d.abs() > TOLERANCE).then(|| {
            (0..defects.len())
                .max_by(|&a, &b| {
                    let da = defects[a].displacement(p, n).abs();
                    da.total_cmp(&defects[b].displacement(p, n).abs())
                })
                .expect("defects")
        });
        if let Some(k) = owner {
            members[k].push(points.len());
        }
        points.push(SurfacePoint {
            position: *p,
            normal: *n,
            distance: d,
            uncertainty: 0.0,
            region: owner.map_or(-1, |k| k as i64),
        });
    }
    let regions = members
        .iter()
        .enumerate()
        .filter(|(_, m)| !m.is_empty())
        .map(|(id, m)| region(id, m, &points, per_point))
        .collect();
    Inspection {
        dir: Path::new(".").to_path_buf(),
        tolerance: Some(TOLERANCE),
        regions,
        points,
        fine: Vec::new(),
    }
}

/// regions.json's entry for the core points `m` of region `id`.
fn region(id: usize, m: &[usize], points: &[SurfacePoint], per_point: f64) -> Region {
    let n = m.len() as f64;
    let c = m
        .iter()
        .fold(Vector3::zeros(), |s, &i| s + points[i].position.coords)
        / n;
    let nn = m
        .iter()
        .fold(Vector3::zeros(), |s, &i| s + points[i].normal)
        .normalize();
    let d: Vec<f64> = m.iter().map(|&i| points[i].distance).collect();
    let peak = d
        .iter()
        .copied()
        .fold(0.0, |a: f64, b| if b.abs() > a.abs() { b } else { a });
    Region {
        id,
        centroid: c.into(),
        normal: nn.into(),
        area: per_point * n,
        peak,
        peak_lower_bound: false,
        mean: d.iter().sum::<f64>() / n,
        volume: d.iter().map(|x| per_point * (x.abs() - TOLERANCE)).sum(),
        points: m.len(),
        repairable: peak > 0.0,
        measured_share: 1.0,
        touches_unmeasured: false,
    }
}

/// Defects per case: 60 over the articular surface, so every part of it gets some (the
/// default 6 leaves most of it without a defect; half of them are pits, not repairable).
const DEFECTS: usize = 60;

/// Reference points per case (a quarter of the turntable test's 60,000; 0.5 mm spacing stays
/// under the ball's 3 mm radius and keeps a plan to seconds).
const POINTS: usize = 15_000;

/// Seed `seed`'s case: `DEFECTS` defects uniform over the articular surface.
pub fn uniform_case(seed: u64) -> Inspection {
    of_case(&uniform_config(seed))
}

/// The synth settings of [`uniform_case`] (`synthetic::inspection` writes its folder).
pub fn uniform_config(seed: u64) -> SynthConfig {
    SynthConfig {
        reference_points: POINTS,
        ..super::femoral_synth(seed, DEFECTS)
    }
}

/// The same on synth's parametric femoral part (its own frame: medial-lateral along x).
pub fn parametric_case(seed: u64) -> Inspection {
    of_case(&SynthConfig {
        seed,
        reference_points: POINTS,
        scan_points: 1_000,
        defects: DEFECTS,
        ..SynthConfig::default()
    })
}

/// Seed of the uniform case whose removal-mode plan in the designed femoral cell
/// (calibration/femoral/) splits regions by table angle (tests/collision/uniform.rs): region
/// 11, ground at -20 degrees, its last 14 core points at -25 degrees (96.8 % of the repairable
/// area planned). It was seed 5100 (region 17's last 7 core points at 15 degrees) until the
/// rim guard (issue 50): its lifts left region 17 short at its first angle, so it was planned
/// alone at the next candidates and moved whole to 40 degrees, which covers 15 of its 16 core
/// points: one left, under `MIN_PIECE_POINTS`, nothing to split. Searched with the guard and
/// the softer contacts (motion::soften): seeds 5100 and 5102-5124, four split a region (5116,
/// 5118, 5119, 5123); this one splits off the largest piece.
pub const SPLIT_SEED: u64 = 5119;

/// The uniform case [`SPLIT_SEED`] and its removal-mode plan in the designed femoral cell, as
/// `plan` makes it: its robot, placement, table and settings too. (The turntable cell split a
/// region of this case until the spindle's press depth and the landed coverage of issue 50
/// left none of its regions under 95 % covered.)
pub fn split_plan() -> (Robot, Workcell, Turntable, PlanConfig, Inspection, Plan) {
    let insp = uniform_case(SPLIT_SEED);
    let (robot, wc, table, mut config) = cell("femoral/");
    config.mode = polishbot::motion::PlanMode::Removal;
    let table = table.expect("the designed cell has a turntable");
    let plan = polishbot::motion::plan(&insp, &robot, &wc, Some(&table), &config).expect("plan");
    (robot, wc, table, config, insp, plan)
}

/// The table angles (degrees, sorted, distinct) at which `plan` grinds region `id`: the
/// angle the table's moves leave it at when each of the region's grinding segments starts.
pub fn ground_at(plan: &Plan, id: usize) -> Vec<f64> {
    let tp = plan.turntable.as_ref().expect("a table part");
    let mut out: Vec<f64> = Vec::new();
    for s in &plan.segments {
        if s.region != Some(id) || s.kind != polishbot::motion::SegmentKind::Grind {
            continue;
        }
        let at = tp
            .moves
            .iter()
            .rev()
            .find(|m| m.at_sample <= s.first_sample)
            .map_or(tp.start, |m| *m.samples.last().expect("a move"));
        let deg = (at.to_degrees() * 1e6).round() / 1e6;
        if !out.contains(&deg) {
            out.push(deg);
        }
    }
    out.sort_by(f64::total_cmp);
    out
}

/// Planned and total repairable area of a plan, mm^2: per repairable region its area times
/// the share of its points within the footprint of a planned stroke (plan.json's
/// `coverage_of_all`).
pub fn planned_area(plan: &Plan) -> (f64, f64) {
    plan.reachability
        .regions
        .iter()
        .filter(|r| r.repairable)
        .fold((0.0, 0.0), |(c, t), r| {
            (c + r.coverage_of_all * r.area_mm2, t + r.area_mm2)
        })
}

/// plan.json's reasons for the contact points it left out, by rule (the reason's words
/// before its first number or colon).
pub fn reasons(plan: &Plan) -> BTreeMap<String, usize> {
    let mut out = BTreeMap::new();
    for u in &plan.reachability.unreachable {
        let rule: String = u
            .reason
            .split(|c: char| c.is_ascii_digit() || c == ':' || c == '(')
            .next()
            .unwrap_or("")
            .trim()
            .to_string();
        *out.entry(rule).or_insert(0) += 1;
    }
    out
}

/// The synth case (seed [`SYNC_SEED`], 4 defects) of the real femoral component planned in
/// rigid mode in the designed femoral cell with the tool held within [`SYNC_CONE_DEG`] of the
/// arm's plane (a stricter tool-axis rule than the IK's default 45 degrees): at that cone no
/// single table angle reaches most of region 0's contacts, and the planner grinds some of its
/// strokes with the table turning (`motion::table_sync`). Its robot, placement, table,
/// settings, the inspection and the plan.
pub fn synced_plan() -> (Robot, Workcell, Turntable, PlanConfig, Inspection, Plan) {
    let insp = inspection(SYNC_SEED, 4);
    let (robot, wc, table, mut config) = cell("femoral/");
    config.ik.max_axis_miss_deg = SYNC_CONE_DEG;
    let table = table.expect("the designed cell has a turntable");
    let plan = polishbot::motion::plan(&insp, &robot, &wc, Some(&table), &config).expect("plan");
    (robot, wc, table, config, insp, plan)
}

/// Seed of [`synced_plan`]'s case.
pub const SYNC_SEED: u64 = 2000;

/// Tool-axis cone of [`synced_plan`], degrees from the arm's plane.
pub const SYNC_CONE_DEG: f64 = 10.0;

/// The bus settings of `robot` (its servo map, the defaults otherwise) and the simulated
/// board's options with the turntable `table` on bus servo 7 at angle 0.
pub fn table_bus(
    robot: &Robot,
    table: &Turntable,
) -> (polishbot::bus::BusConfig, polishbot::sim::SimOptions) {
    let cfg = polishbot::bus::BusConfig {
        servo_map: polishbot::motion::frames::servo_map(robot).unwrap(),
        ..polishbot::bus::BusConfig::default()
    };
    let options = polishbot::sim::SimOptions {
        extra_servos: vec![polishbot::sim::ExtraServo {
            id: 7,
            start_raw: table.raw(0.0).unwrap(),
        }],
        ..polishbot::sim::SimOptions::default()
    };
    (cfg, options)
}

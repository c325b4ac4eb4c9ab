//! Motion planning: grinding passes over the repairable regions of the repair work, tool poses
//! in the robot frame, IK along every pass (split where the arm cannot reach or follow), in
//! removal mode the dwell of each contact from the `removal` room turned into the feed along
//! each stroke, one continuous time-optimal joint trajectory sampled at the bus period,
//! validated before any motion, and the reachability report. Method: docs/ALGORITHMS.md,
//! "Grinding planner".
//!
//! Front function: [`plan`] (the cell with its turntable, if any) with a [`PlanConfig`];
//! result: [`Plan`] (plan.json). [`plan_part`] plans the part where it sits, the step `plan`
//! makes once per table angle.
pub mod aim;
pub mod alternatives;
mod assemble;
mod by_region;
pub mod check;
pub mod clearance;
pub mod collide;
pub mod compensate;
mod config;
pub mod dwell;
pub mod error;
pub mod feed;
pub mod file;
pub mod finish;
pub mod frames;
mod free_motion;
mod landing;
pub mod order;
mod predict;
mod press_depth;
pub mod program;
pub mod raster;
pub mod report;
pub mod ros;
pub mod setups;
mod soften;
mod stroke;
pub mod surface;
pub mod table;
pub mod table_check;
pub mod table_file;
mod table_split;
mod table_sync;
mod tilt;
pub mod tools;
pub mod trajectory;
pub mod validate;

pub use crate::repair::{Inspection, RegionInfo, SurfacePoint};
pub use clearance::Collision;
pub use collide::{CollisionConfig, Solid};
pub use config::{PlanConfig, PlanMode, DEFAULT_TOLERANCE_MM, MAX_CONTACT_POINTS, MAX_LAYERS};
pub use error::PlanError;
pub use file::{Plan, Sample};
pub use program::{PlannedPass, PlannedPoint, Segment, SegmentKind};
pub use raster::{RasterGeometry, StrokeKind};
pub use report::{Metrics, Reachability, RegionReport, UnreachablePoint};
pub use table::plan;
pub use table_file::TablePlan;
pub use trajectory::{JointTrajectory, Limits, Move, TrajectoryConfig, TrajectoryError};
pub use validate::{validate, LimitKind, ValidationConfig, Violation};

use crate::removal;
use crate::robot::{Robot, Workcell};
use config::check_work;

/// Plans grinding for every repairable region of `inspection` with the part where the
/// workcell puts it (no table move) and validates the result.
pub fn plan_part(
    inspection: &Inspection,
    robot: &Robot,
    workcell: &Workcell,
    config: &PlanConfig,
) -> Result<Plan, PlanError> {
    config.check(robot)?;
    let tool = match config.mode {
        PlanMode::Rigid => None,
        // a finish presses with a share of the preload (`finish`): every model below follows
        PlanMode::Removal => Some(
            config
                .finish
                .tool(removal::ToolModel::of_robot(robot).map_err(PlanError::Config)?),
        ),
    };
    // the compliant ball is commanded `preload` inside the surface: the grinding rule of the
    // collision model (grinding, pressing in and out) accepts that much more penetration
    let mut adjusted = config.clone();
    if let Some(t) = &tool {
        adjusted.collision.press_mm = t.preload_mm;
    }
    let config = &adjusted;
    let radius_mm = robot.tool.radius_mm();
    let reach = radius_mm + config.contact_offset_mm;
    let geometry = match &tool {
        None => config.geometry(radius_mm),
        Some(t) => by_region::removal_geometry(t, radius_mm, config),
    };
    check_work(inspection, &geometry)?;
    let scene = collide::Scene::new(&inspection.points, robot, workcell, &config.collision);
    let fallback = removal::ToolModel::default();
    let positions: Vec<nalgebra::Point3<f64>> =
        inspection.points.iter().map(|p| p.position).collect();
    let index = crate::spatial::Neighbours::new(&positions);
    let ctx = dwell::Setup {
        tool: tool.as_ref().unwrap_or(&fallback),
        robot,
        workcell,
        config,
        index: &index,
    };
    let mut reachability = Reachability::default();
    let planned =
        by_region::plan_regions(inspection, &ctx, tool.as_ref(), &scene, &mut reachability)?;
    let counts = planned.counts.clone();
    let (mut prog, removal) = by_region::assemble_and_predict(
        planned,
        inspection,
        &ctx,
        tool.is_some(),
        &scene,
        &mut reachability.unreachable,
    )?;
    if tool
        .as_ref()
        .is_some_and(|t| t.compliance_direction == removal::ComplianceDirection::SpindleAxis)
    {
        press_depth::land(&mut prog.passes, workcell);
    }
    let cell = (robot, workcell, config);
    region_reports(
        inspection,
        &counts,
        &prog,
        cell,
        &mut reachability,
        reach,
        geometry.footprint,
    );
    if config.require_full_reach && !reachability.unreachable.is_empty() {
        return Err(PlanError::Unreachable(reachability.unreachable));
    }
    let metrics = check::measure(&prog, robot, config);
    check_program(&prog, &metrics, robot, &scene, config)?;
    let traj = std::mem::replace(
        &mut prog.trajectory,
        JointTrajectory::starting_at(&config.home, config.trajectory.period),
    );
    let force_n = tool.as_ref().map_or(0.0, |t| t.force_n());
    let (commanded, compensation) = compensate_plan(&traj, &prog, force_n, robot, workcell, config);
    let sampled = samples_and_frames(&traj, commanded.as_ref(), robot)?;
    let mut plan = plan_record(inspection, &traj, robot, &geometry, prog, sampled);
    plan.commands = commanded.map(|c| (0..c.len()).map(|i| c.sample(i).to_vec()).collect());
    plan.compensation = compensation;
    plan.reachability = reachability;
    plan.metrics = metrics;
    plan.strokes = tool.as_ref().map(|t| config.finish.record(t));
    plan.removal = removal;
    Ok(plan)
}

/// The plan of one placement of the part as every planner writes it: format, the part's
/// folder (absolute, so that `run` finds the part for its collision re-check from any
/// folder), the trajectory's period and duration, the arm's joints, the tool's and raster's
/// sizes, the program with its `samples` and frames; no commands, compensation, report,
/// strokes, removal, table, setups or tools (the caller sets those it has).
pub(super) fn plan_record(
    inspection: &Inspection,
    traj: &JointTrajectory,
    robot: &Robot,
    geometry: &RasterGeometry,
    prog: program::Program,
    (samples, stream): (Vec<Sample>, Vec<Vec<u8>>),
) -> Plan {
    Plan {
        format: "polishbot-plan".into(),
        version: 1,
        inspection: std::fs::canonicalize(&inspection.dir)
            .unwrap_or_else(|_| inspection.dir.clone())
            .display()
            .to_string(),
        period: traj.period,
        joint_names: robot.joints.iter().map(|j| j.name.clone()).collect(),
        tool_radius_mm: robot.tool.radius_mm(),
        stepover_mm: geometry.stepover,
        footprint_mm: geometry.footprint,
        predicted_duration_s: traj.duration(),
        passes: prog.passes,
        segments: prog.segments,
        samples,
        frames: stream.iter().map(|f| frames::to_hex(f)).collect(),
        commands: None,
        compensation: None,
        reachability: Reachability::default(),
        metrics: Metrics::default(),
        strokes: None,
        removal: None,
        turntable: None,
        setups: Vec::new(),
        tools: Vec::new(),
    }
}

/// Each region's coverage report (`check::region_report`) into `reachability.regions`: its
/// layers and path points from `counts`, the points left out from `reachability.unreachable`.
fn region_reports(
    inspection: &Inspection,
    counts: &std::collections::HashMap<usize, (usize, usize)>,
    prog: &program::Program,
    (robot, workcell, config): (&Robot, &Workcell, &PlanConfig),
    reachability: &mut Reachability,
    reach: f64,
    footprint: f64,
) {
    for region in &inspection.regions {
        let (layers, total) = counts.get(&region.id).copied().unwrap_or((0, 0));
        let left_out = reachability
            .unreachable
            .iter()
            .filter(|u| u.region == region.id)
            .count();
        reachability.regions.push(check::region_report(
            region,
            inspection,
            &prog.passes,
            layers,
            total,
            left_out,
            robot,
            workcell,
            config,
            reach,
            footprint,
        ));
    }
}

/// The servo commands and their report when `config.compensate_compliance` and the robot has
/// `[compliance]` (docs/ALGORITHMS.md, "Compliance compensation"); (None, None) otherwise.
/// A correction that no smoothing keeps within the limits is left out, said on stderr: the
/// plan then commands the loaded joints as before.
fn compensate_plan(
    traj: &JointTrajectory,
    prog: &program::Program,
    force_n: f64,
    robot: &Robot,
    workcell: &Workcell,
    config: &PlanConfig,
) -> (Option<JointTrajectory>, Option<file::CompensationReport>) {
    let loads = compensate::Loads {
        segments: &prog.segments,
        passes: &prog.passes,
        force_n,
    };
    // what `run` checks of the commands (file::Plan::check): each within the offset bound of
    // its sample, and the limits
    let keeps = |c: &JointTrajectory| {
        let far = (0..c.len()).find_map(|i| file::offset_refused(i, c.sample(i), traj.sample(i)));
        if let Some(why) = far {
            return Err(why);
        }
        let violations = validate(c, robot, &config.validation);
        match violations.first() {
            None => Ok(()),
            Some(v) => Err(format!("{} limit(s), first {v}", violations.len())),
        }
    };
    let compensated = config
        .compensate_compliance
        .then(|| compensate::commands(traj, &loads, robot, workcell, &keeps))
        .flatten();
    match compensated {
        Some(Err(why)) => {
            tracing::warn!("compliance compensation left out: the corrected commands break {why}");
            (None, None)
        }
        Some(Ok(c)) => {
            let report = file::CompensationReport {
                grinding_samples: c.grinding_samples,
                partial_samples: c.partial_samples,
                least_share: c.least_share,
            };
            (Some(c.traj), Some(report))
        }
        None => (None, None),
    }
}

/// The whole sampled program against the limits (validation), the scene (collisions) and the
/// planned path (`max_path_error_mm`); the first failing check is the error.
fn check_program(
    prog: &program::Program,
    metrics: &Metrics,
    robot: &Robot,
    scene: &collide::Scene,
    config: &PlanConfig,
) -> Result<(), PlanError> {
    let violations = validate(&prog.trajectory, robot, &config.validation);
    if !violations.is_empty() {
        return Err(PlanError::Invalid(violations));
    }
    let traj = &prog.trajectory;
    let collisions = clearance::check_samples(
        (0..traj.len()).map(|i| traj.sample(i)),
        &prog.segments,
        robot,
        scene,
    );
    if !collisions.is_empty() {
        return Err(PlanError::Collides(collisions));
    }
    let worst = metrics
        .sample_to_path_max_mm
        .max(metrics.path_to_samples_max_mm);
    if worst > config.max_path_error_mm {
        return Err(PlanError::Config(format!(
            "modelled tool tip strays {worst:.3} mm from the planned path (max_path_error_mm {})",
            config.max_path_error_mm
        )));
    }
    Ok(())
}

/// The trajectory's samples and the servo command stream they make (one frame per sample of
/// `commanded` when the plan compensates the arm's compliance, else of `traj`, through the
/// robot's servo map, the gripper held at its `hold_deg`).
pub(super) fn samples_and_frames(
    traj: &JointTrajectory,
    commanded: Option<&JointTrajectory>,
    robot: &Robot,
) -> Result<(Vec<Sample>, Vec<Vec<u8>>), PlanError> {
    let samples: Vec<Sample> = (0..traj.len())
        .map(|i| Sample {
            t: i as f64 * traj.period,
            q: traj.sample(i).to_vec(),
        })
        .collect();
    let map = frames::servo_map(robot)?;
    let hold = frames::gripper_hold_deg(robot)?;
    let sent = commanded.unwrap_or(traj);
    let qs: Vec<Vec<f64>> = (0..sent.len()).map(|i| sent.sample(i).to_vec()).collect();
    let stream = frames::encode(&qs, &map, hold, traj.period)?;
    Ok((samples, stream))
}

//! The table as a sixth axis within a stroke (issue 51, item 3): a region its pieces still
//! leave short (`table_split.rs`) gets strokes ground while the table turns. Each contact is
//! solved for the arm's joints and the table angle together: the first at the table angle
//! nearest where the table stands that the arm reaches it at, each next one at the previous
//! one's angle, or, when the arm cannot reach it there, at the nearest angle on a 1-D search
//! within what the table can turn in the time the tool takes between the two contacts at the
//! feed. A run of contacts solved that way, with the table angle changing along it, is ground
//! as one stroke: the arm's joints and the table angle as one six-axis joint path along the
//! ball's path on the part, time-parametrised within both the arm's and the table's limits
//! (`feed::path_limits` with the table as a sixth joint, so the slower one sets the speed), the
//! table angle sampled with the arm at the bus period. Each such stroke is its own trip from
//! home: the table turns (at rest, arm at home) to the stroke's first angle, the arm enters with
//! the part there, grinds with the table turning, and retracts and goes home with the part at
//! the stroke's last angle. Every sample is checked against the part turned to the table angle
//! of that sample. Rigid mode only (a removal stroke's dwell is not solved with the table
//! moving yet). Method: docs/ALGORITHMS.md, "Turntable".
//!
//! Front: `table::plan` calls [`synced`] for a region still short after its pieces.
use nalgebra::{Point3, Vector3};

use super::check::{self, Cover};
use super::clearance::check_samples;
use super::collide::{Allow, Scene};
use super::feed::{path_limits, sample_stroke, JointSpline, PathLimits};
use super::file::Plan;
use super::free_motion::Assembly;
use super::program::{max_step, misfit, tool_target, PlannedPass, PlannedPoint, Program, Segment};
use super::raster::{self, PathPoint};
use super::report::{Reachability, SegmentKind};
use super::surface::Surface;
use super::table_split::PieceCell;
use super::trajectory::JointTrajectory;
use super::validate::validate;
use crate::repair::{Inspection, RegionInfo};
use crate::robot::units::{metres, mm};
use crate::robot::{JointSpec, Workcell};

/// Grid of the table angles each contact is solved at, degrees: the table turns up to
/// `velocity x spacing / feed` between two contacts (about 5 degrees at 1 rad/s, 0.5 mm and
/// 5 mm/s), so a degree lets it turn in steps of a fifth of that; over a 270-degree table
/// that is 271 IK calls per contact.
const GRID_STEP_DEG: f64 = 1.0;
/// Least change of the table angle along a run for it to be ground synced, rad: a run at one
/// angle is what the pieces plan already (`table_split.rs`).
const LEAST_TURN: f64 = 1e-6;

/// One stroke ground with the table turning, as a plan of its own from home to home.
pub(super) struct SyncedPart {
    /// The stroke's plan (the arm's samples; the table at `start` until the stroke).
    pub plan: Plan,
    /// Table angle at the stroke's first contact, rad (where the table must be before it).
    pub start: f64,
    /// Arm sample where the stroke starts (the table at `angles[0]`).
    pub first_sample: usize,
    /// Table angle per arm sample from `first_sample` to the stroke's last, rad.
    pub angles: Vec<f64>,
}

/// A contact solved with the table: the path point, its table angle and the planned point.
struct Solved {
    angle: f64,
    point: PlannedPoint,
}

/// Strokes over region `region`'s core points in `part` (the region cut to what is left
/// uncovered, `table_split::piece_of`) ground with the table turning, at most
/// `config.table_sync`, the table starting from `from` (rad).
pub(super) fn synced(
    cell: &PieceCell,
    part: &Inspection,
    region: &RegionInfo,
    from: f64,
) -> Vec<SyncedPart> {
    let (robot, config) = (cell.robot, cell.config);
    let radius_mm = robot.tool.radius_mm();
    let geometry = config.geometry(radius_mm);
    let surface = Surface::new(&part.points);
    let members: Vec<_> = part
        .region_points(region.id)
        .into_iter()
        .map(|i| part.points[i])
        .collect();
    let strokes = raster::raster(region, &members, &surface, &geometry);
    let scene = Scene::new(
        &part.points,
        robot,
        &cell.table.workcell_at(cell.workcell, from),
        &config.collision,
    );
    let mut out = Vec::new();
    let mut at = from;
    for stroke in &strokes {
        for run in solve_runs(cell, &stroke.points, &scene, at) {
            if out.len() >= config.table_sync {
                return out;
            }
            let (lo, hi) = run.iter().fold((f64::MAX, f64::MIN), |(lo, hi), s| {
                (lo.min(s.angle), hi.max(s.angle))
            });
            if run.len() < 2 || hi - lo < LEAST_TURN {
                continue;
            }
            let pass = PlannedPass {
                region: stroke.region,
                layer: stroke.layer,
                kind: stroke.kind,
                feed_mm_s: config.feed_mm_s,
                dwell_s: None,
                contact_normal: None,
                points: Vec::new(),
            };
            if let Some(sub) = stroke_plan(cell, part, region, pass, &run) {
                at = *sub.angles.last().unwrap_or(&at);
                out.push(sub);
            }
        }
    }
    out
}

/// The contacts of one stroke solved with the table, starting near `from` (rad): runs of
/// consecutive contacts the arm and the table follow. Each contact's table angles the arm
/// reaches it at are found on a grid of [`GRID_STEP_DEG`] over the table's range; a forward
/// pass keeps, per contact, the angles reachable from the previous contact's within what the
/// table turns in the time between them at the feed (a 1-D search with look-ahead), and a
/// backward pass picks from the last contact the angles nearest `from` and then each nearest
/// the next one's (least turning). A contact with no such angle ends a run.
fn solve_runs(
    cell: &PieceCell,
    points: &[PathPoint],
    scene: &Scene,
    from: f64,
) -> Vec<Vec<Solved>> {
    let config = cell.config;
    let reach = cell.robot.tool.radius_mm() + config.contact_offset_mm;
    let [lo, hi] = cell.table.range();
    let step = GRID_STEP_DEG.to_radians();
    let grid: Vec<f64> = ((lo / step).ceil() as i64..=(hi / step).floor() as i64)
        .map(|k| k as f64 * step)
        .collect();
    let jump = config.max_joint_step;
    let mut runs = Vec::new();
    // per contact of the run being built: its solutions per grid cell, and which cells the
    // run can be at there
    let mut open: Vec<(Vec<Option<Solved>>, Vec<bool>)> = Vec::new();
    for (i, p) in points.iter().enumerate() {
        let fits = misfit(p, reach, scene, &config.aim).is_none();
        let prev = open.last();
        let sols: Vec<Option<Solved>> = grid
            .iter()
            .enumerate()
            .map(|(c, &a)| {
                let q = prev
                    .and_then(|(s, _)| s[c].as_ref())
                    .map_or(&config.home, |s| &s.point.q);
                fits.then(|| solve_at(cell, p, a, q)).flatten()
            })
            .collect();
        let turn = match prev {
            None => 0,
            Some(_) => turn_between(cell, &points[i - 1], p),
        };
        let can: Vec<bool> = (0..grid.len())
            .map(|c| {
                sols[c].is_some()
                    && prev.is_none_or(|(_, was)| {
                        let (a, b) = (c.saturating_sub(turn), (c + turn).min(grid.len() - 1));
                        was[a..=b].iter().any(|x| *x)
                    })
            })
            .collect();
        if can.iter().any(|x| *x) {
            open.push((sols, can));
            continue;
        }
        let turns = turn_cells(cell, points, i);
        runs.push(back(std::mem::take(&mut open), &grid, from, &turns, jump));
        // this contact starts the next run when the arm reaches it at some angle
        let can: Vec<bool> = sols.iter().map(Option::is_some).collect();
        if can.iter().any(|x| *x) {
            open.push((sols, can));
        }
    }
    let turns = turn_cells(cell, points, points.len());
    runs.push(back(open, &grid, from, &turns, jump));
    runs.retain(|r| !r.is_empty());
    runs
}

/// Grid cells the table may turn between contacts `a` and `b`: its velocity limit (with the
/// planner's joint margin) over the time the tool takes between them at the feed.
fn turn_between(cell: &PieceCell, a: &PathPoint, b: &PathPoint) -> usize {
    let config = cell.config;
    let [v, _, _] = cell.table.limits();
    let d = (b.surface - a.surface).norm();
    let most = config.joint_margin * v * d / config.feed_mm_s.max(1e-9);
    (most / GRID_STEP_DEG.to_radians()).floor() as usize
}

/// [`turn_between`] for each pair of consecutive contacts of `points` before `end` (index `k`
/// for the step into contact `k + 1`).
fn turn_cells(cell: &PieceCell, points: &[PathPoint], end: usize) -> Vec<usize> {
    (1..end)
        .map(|i| turn_between(cell, &points[i - 1], &points[i]))
        .collect()
}

/// The backward pass over a run's contacts `open` (their solutions and reachable cells; the
/// run's contacts are the last `open.len()` before the end of `turns`): the last contact at
/// its reachable cell nearest `from`, each earlier one at its reachable cell within the turn
/// of the next one's and nearest it. Cut where the arm's joints would jump more than `jump`
/// (the planner's joint step) plus the table's turn (a branch flip of the IK).
fn back(
    open: Vec<(Vec<Option<Solved>>, Vec<bool>)>,
    grid: &[f64],
    from: f64,
    turns: &[usize],
    jump: f64,
) -> Vec<Solved> {
    let n = open.len();
    if n == 0 {
        return Vec::new();
    }
    let near = |cands: &mut dyn Iterator<Item = usize>, to: f64| {
        cands.min_by(|&x, &y| (grid[x] - to).abs().total_cmp(&(grid[y] - to).abs()))
    };
    let mut cells = vec![0usize; n];
    let last = &open[n - 1].1;
    cells[n - 1] = near(&mut (0..grid.len()).filter(|&c| last[c]), from).unwrap_or(0);
    let offset = turns.len() + 1 - n;
    for k in (0..n - 1).rev() {
        let t = turns[offset + k];
        let next = cells[k + 1];
        let (a, b) = (next.saturating_sub(t), (next + t).min(grid.len() - 1));
        let was = &open[k].1;
        cells[k] = near(&mut (a..=b).filter(|&c| was[c]), grid[next]).unwrap_or(next);
    }
    let mut out: Vec<Solved> = Vec::with_capacity(n);
    for (k, (mut sols, _)) in open.into_iter().enumerate() {
        let Some(s) = sols[cells[k]].take() else {
            break;
        };
        let flips = out.last().is_some_and(|l: &Solved| {
            max_step(&l.point.q, &s.point.q) > jump + (s.angle - l.angle).abs()
        });
        if flips {
            break;
        }
        out.push(s);
    }
    out
}

/// Contact `p` solved with the table at `angle`: the arm's joints from `prev` (the IK's branch),
/// the tool axis within the accepted miss of the normal.
fn solve_at(cell: &PieceCell, p: &PathPoint, angle: f64, prev: &[f64]) -> Option<Solved> {
    let (robot, config) = (cell.robot, cell.config);
    let reach = robot.tool.radius_mm() + config.contact_offset_mm;
    let wc = cell.table.workcell_at(cell.workcell, angle);
    let target = tool_target(p, reach, 0.0, &wc, &config.aim);
    let sol = robot.ik(&target, prev, &config.ik).ok()?;
    let normal = wc.direction_from_reference(&p.normal);
    let axis = robot.fk(&sol.q).axis;
    let miss = crate::robot::angle_between(&axis, &-normal).to_degrees();
    if miss > config.ik.max_axis_miss_deg {
        return None;
    }
    Some(Solved {
        angle,
        point: PlannedPoint {
            surface_mm: p.surface.into(),
            normal: p.normal.into(),
            offset_mm: p.offset,
            tip_m: target.position.into(),
            axis: axis.into(),
            q: sol.q,
            landed_mm: None,
        },
    })
}

/// The table as a joint of the six-axis stroke: its range and limits.
fn table_joint(cell: &PieceCell) -> JointSpec {
    let [lower, upper] = cell.table.range();
    let [velocity, acceleration, jerk] = cell.table.limits();
    JointSpec {
        name: "turntable".into(),
        servo_id: cell.table.servo.id,
        lower,
        upper,
        velocity,
        acceleration,
        jerk,
    }
}

/// One run ground with the table turning as a plan from home to home (None when its way in or
/// out, a limit or a collision refuses it).
fn stroke_plan(
    cell: &PieceCell,
    part: &Inspection,
    region: &RegionInfo,
    mut pass: PlannedPass,
    run: &[Solved],
) -> Option<SyncedPart> {
    let (robot, config) = (cell.robot, cell.config);
    let (a, b) = (run[0].angle, run[run.len() - 1].angle);
    let (wc_a, wc_b) = (
        cell.table.workcell_at(cell.workcell, a),
        cell.table.workcell_at(cell.workcell, b),
    );
    let scene_a = Scene::new(&part.points, robot, &wc_a, &config.collision);
    let scene_b = Scene::new(&part.points, robot, &wc_b, &config.collision);
    let mut prog = Program {
        trajectory: JointTrajectory::starting_at(&config.home, config.trajectory.period),
        segments: Vec::new(),
        passes: Vec::new(),
        cruise: vec![false],
        slowed: 0,
    };
    let (first, last) = (&run[0].point, &run[run.len() - 1].point);
    let into = Assembly::new(robot, &wc_a, config, &scene_a);
    prog.enter(None, (first, 0.0), region.id, &into)
        .ok()?
        .ok()?;
    // the ball centre's path on the part (reference frame), and the six-axis joint path
    let reach = robot.tool.radius_mm() + config.contact_offset_mm;
    let centre = |s: &Solved| {
        let p = &s.point;
        Point3::from(p.surface_mm) + Vector3::from(p.normal) * (p.offset_mm + reach)
    };
    let mut s = vec![0.0];
    let mut q6 = vec![[run[0].point.q.clone(), vec![a]].concat()];
    for w in run.windows(2) {
        let d = metres((centre(&w[1]) - centre(&w[0])).norm());
        let joint = max_step(&w[0].point.q, &w[1].point.q) + (w[1].angle - w[0].angle).abs();
        if d > 1e-9 || joint > 1e-12 {
            s.push(s.last().copied().unwrap_or(0.0) + d.max(1e-9));
            q6.push([w[1].point.q.clone(), vec![w[1].angle]].concat());
        }
    }
    let spline = JointSpline::new(s, q6);
    let mut joints = robot.joints.clone();
    joints.push(table_joint(cell));
    let wanted = PathLimits {
        velocity: metres(config.feed_mm_s),
        acceleration: config.path_acceleration,
        jerk: config.path_jerk,
    };
    let lim = path_limits(&spline, &joints, wanted, config.joint_margin);
    let (samples, cruise) = sample_stroke(&spline, &lim, &config.trajectory).ok()?;
    let at = prog.trajectory.len() - 1;
    let mut angles = vec![a];
    let dof = robot.dof();
    for q in &samples {
        prog.trajectory.push(&q[..dof]);
        angles.push(q[dof]);
    }
    prog.cruise.extend(cruise);
    pass.feed_mm_s = mm(lim.velocity);
    pass.points = run.iter().map(|s| s.point.clone()).collect();
    prog.segments.push(Segment {
        kind: SegmentKind::Grind,
        region: Some(region.id),
        pass: Some(0),
        first_sample: at,
        last_sample: at + samples.len(),
    });
    prog.passes.push(pass);
    let out = Assembly::new(robot, &wc_b, config, &scene_b);
    prog.retract(last, region.id, &out).ok()?.ok()?;
    prog.home(Some(last), &out).ok()?.ok()?;
    if !validate(&prog.trajectory, robot, &config.validation).is_empty() {
        return None;
    }
    if collides(cell, part, &prog, (&scene_a, &scene_b), at, &angles) {
        return None;
    }
    let plan = to_plan(cell, part, region, prog, &wc_a)?;
    Some(SyncedPart {
        plan,
        start: a,
        first_sample: at,
        angles,
    })
}

/// Whether a sample of `prog` touches the part turned to its table angle: up to the stroke's
/// first sample `at` with the part at the first angle (`scenes.0`), the stroke's samples each
/// at its own angle of `angles`, and from its last on at the last angle (`scenes.1`).
fn collides(
    cell: &PieceCell,
    part: &Inspection,
    prog: &Program,
    scenes: (&Scene, &Scene),
    at: usize,
    angles: &[f64],
) -> bool {
    let traj = &prog.trajectory;
    let end = at + angles.len() - 1;
    let robot = cell.robot;
    let before = (0..at + 1).map(|i| traj.sample(i));
    if !check_samples(before, &prog.segments, robot, scenes.0).is_empty() {
        return true;
    }
    let all = (0..traj.len()).map(|i| traj.sample(i));
    let after = check_samples(all, &prog.segments, robot, scenes.1);
    if after.iter().any(|c| c.sample >= end) {
        return true;
    }
    let config = cell.config;
    let mut turned = Scene::new(&part.points, robot, cell.workcell, &config.collision);
    angles.iter().enumerate().skip(1).any(|(k, &angle)| {
        let wc = cell.table.workcell_at(cell.workcell, angle);
        turned.place(&wc, &config.collision.solids);
        turned
            .check(robot, traj.sample(at + k), Allow::Grind)
            .is_some()
    })
}

/// The plan of one synced stroke's program (its report made with the part at the stroke's
/// first angle `wc`; `table::plan` folds the region's reports over its pieces).
fn to_plan(
    cell: &PieceCell,
    part: &Inspection,
    region: &RegionInfo,
    mut prog: Program,
    wc: &Workcell,
) -> Option<Plan> {
    let (robot, config) = (cell.robot, cell.config);
    let radius_mm = robot.tool.radius_mm();
    let reach = radius_mm + config.contact_offset_mm;
    let geometry = config.geometry(radius_mm);
    let mut reachability = Reachability::default();
    let path_points: usize = prog.passes.iter().map(|p| p.points.len()).sum();
    reachability.regions.push(check::region_report(
        region,
        part,
        &prog.passes,
        1,
        path_points,
        0,
        robot,
        wc,
        config,
        reach,
        geometry.footprint,
    ));
    let metrics = check::measure(&prog, robot, config);
    let traj = std::mem::replace(
        &mut prog.trajectory,
        JointTrajectory::starting_at(&config.home, config.trajectory.period),
    );
    let sampled = super::samples_and_frames(&traj, None, robot).ok()?;
    let mut plan = super::plan_record(part, &traj, robot, &geometry, prog, sampled);
    plan.reachability = reachability;
    plan.metrics = metrics;
    Some(plan)
}

/// How many of the core points `left` of region `id` the strokes of `parts` cover together.
pub(super) fn gained(cell: &PieceCell, parts: &[SyncedPart], id: usize, left: &[usize]) -> usize {
    let passes: Vec<PlannedPass> = parts
        .iter()
        .flat_map(|p| p.plan.passes.iter().cloned())
        .collect();
    let footprint = parts.first().map_or(0.0, |p| p.plan.footprint_mm);
    let cover = Cover::new(&passes, id, footprint);
    let pts = &cell.inspection.points;
    left.iter()
        .filter(|&&i| cover.covers(&pts[i].position))
        .count()
}

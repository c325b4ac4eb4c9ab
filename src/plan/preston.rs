//! Removal mode of the planner: the compliant tool pressed at its preload along one raster per
//! region, the dwell of every contact solved (robust to the arm's error, `removal::
//! solve_robust`), each stroke ground without stopping at the feed its contacts' dwells ask
//! for (`stroke.rs`), the force checked at each contact's joint angles, and the predicted part from the
//! dwell the trajectory really spends. Method: docs/ALGORITHMS.md, "Removal planning".
use nalgebra::{DMatrix, Matrix3, Point3, Vector3};
use serde::{Deserialize, Serialize};

use super::config::PlanConfig;
use super::error::PlanError;
use super::feed::JointSpline;
use super::inspection::RegionInfo;
use super::inspection::{Inspection, SurfacePoint};
use super::program::{PlannedPass, Program, Run, SegmentKind};
use super::removal::montecarlo::{spread, JointError};
use super::removal::{self, force, Contact, Influence, Problem, Stats, ToolModel};
use super::stroke::{chain_knots, chain_limits};
use crate::robot::{Robot, Workcell};

/// One contact of the dwell map in plan.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DwellPoint {
    /// Contact point (middle of its piece of stroke), reference frame, mm.
    pub surface_mm: [f64; 3],
    /// Time the trajectory spends on the piece, s, plus the dwell-equivalent of a press into
    /// or out of it (`press_dwell`).
    pub dwell_s: f64,
    /// Mean speed over the piece, mm/s.
    pub feed_mm_s: f64,
}

/// The removal planned over one region and the part predicted after it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionPrediction {
    /// Region id.
    pub region: usize,
    /// Allowance the robust solve settled on, mm.
    pub allowance_mm: f64,
    /// The dwell map, one entry per contact in program order.
    pub dwell: Vec<DwellPoint>,
    /// Core points of the region and its neighbours in the tool's reach.
    pub core_points: usize,
    /// Deviation before grinding over those points.
    pub before: Stats,
    /// Predicted deviation after grinding (nominal model).
    pub after: Stats,
    /// Lowest 5th-percentile residual of the Monte Carlo, mm (below -tolerance: over-grind).
    pub after_low_p95_mm: f64,
}

/// The removal part of plan.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemovalReport {
    /// Contact force at the preload, N.
    pub force_n: f64,
    /// The preload: how far the ball is pressed inside the surface while it grinds, mm
    /// (`run` re-checks the grinding samples with it).
    pub preload_mm: f64,
    /// Tolerance, mm: over-grind is a residual below -tolerance.
    pub tolerance_mm: f64,
    /// Per planned region.
    pub regions: Vec<RegionPrediction>,
    /// One row per core point (predicted.csv; not in plan.json).
    #[serde(skip)]
    pub rows: Vec<PredictedRow>,
}

/// One row of predicted.csv.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PredictedRow {
    /// Core point, reference frame, mm.
    pub position: [f64; 3],
    /// Deviation before grinding, mm.
    pub deviation: f64,
    /// Predicted residual (nominal model), mm.
    pub residual: f64,
    /// Width of the Monte Carlo's residual between its median and its low quantile, mm.
    pub spread_p95: f64,
}

/// The compliant tool of `robot` (tool.toml `[removal]`, defaults when absent).
pub fn tool_model(robot: &Robot) -> Result<ToolModel, PlanError> {
    let model: ToolModel = match &robot.tool.removal {
        None => ToolModel::default(),
        Some(v) => v.clone().try_into().map_err(|e: toml::de::Error| {
            PlanError::Config(format!("tool.toml [removal]: {}", e.message()))
        })?,
    };
    model
        .check()
        .map_err(|(key, msg)| PlanError::Config(format!("tool.toml `{key}`: {msg}")))?;
    Ok(model)
}

/// Rotation from the robot frame to the reference frame.
fn reference_from_robot(wc: &Workcell) -> Matrix3<f64> {
    let r = Matrix3::from_columns(&[
        wc.direction_from_reference(&Vector3::x()),
        wc.direction_from_reference(&Vector3::y()),
        wc.direction_from_reference(&Vector3::z()),
    ]);
    r.transpose()
}

/// The contact of a two-point piece: its middle, mean normal, direction, length, and the
/// tangent toward which the spindle leans (the arm's vertical plane through its base axis).
fn contact(piece: &PlannedPass, back: &Matrix3<f64>) -> Contact {
    let (a, b) = (&piece.points[0], &piece.points[piece.points.len() - 1]);
    let (pa, pb) = (Point3::from(a.surface_mm), Point3::from(b.surface_mm));
    let normal = (Vector3::from(a.normal) + Vector3::from(b.normal)).normalize();
    let d = pb - pa;
    let along = d
        .try_normalize(1e-12)
        .unwrap_or_else(|| normal.cross(&Vector3::x()));
    let radial = back * Vector3::new(a.tip_m[0], a.tip_m[1], 0.0);
    let tilt = radial - normal * normal.dot(&radial);
    let tilt_dir = tilt
        .try_normalize(1e-12)
        .unwrap_or_else(|| along.cross(&normal));
    Contact {
        point: pa + d * 0.5,
        normal,
        along,
        tilt_dir,
        length: d.norm(),
    }
}

/// How the joints of a piece's first pose move the tip (mm/rad, reference frame) and each
/// servo's half raw count (rad), as `robot/resolution.rs` quantises them.
fn joint_error(robot: &Robot, q: &[f64], back: &Matrix3<f64>) -> JointError {
    let jac = robot.jacobian(q);
    let position = jac.rows(0, 3).into_owned() * 1e3;
    let sensitivity: DMatrix<f64> = DMatrix::from_fn(3, robot.dof(), |r, c| {
        (0..3).map(|k| back[(r, k)] * position[(k, c)]).sum()
    });
    let half_count = robot
        .joints
        .iter()
        .map(|joint| {
            robot
                .servos
                .servos
                .iter()
                .find(|s| s.id == joint.servo_id)
                .map_or(0.0, |s| 0.5 / s.counts_per_degree().to_degrees())
        })
        .collect();
    JointError {
        sensitivity,
        half_count,
    }
}

/// Splits every piece of `runs` into two-point pieces (one contact each).
fn split(runs: Vec<Run>) -> Vec<Run> {
    runs.into_iter()
        .map(|run| {
            run.into_iter()
                .flat_map(|piece| {
                    let pairs: Vec<PlannedPass> = piece
                        .points
                        .windows(2)
                        .map(|w| PlannedPass {
                            points: w.to_vec(),
                            ..piece.clone()
                        })
                        .collect();
                    pairs
                })
                .collect::<Run>()
        })
        .filter(|run: &Run| !run.is_empty())
        .collect()
}

/// Core points in reach of `contacts` (the region's and its neighbours'), with the inspection
/// indices they come from.
fn cores_near(inspection: &Inspection, contacts: &[Contact], reach: f64) -> Vec<usize> {
    let mut keep = vec![false; inspection.points.len()];
    for (i, p) in inspection.points.iter().enumerate() {
        keep[i] = contacts
            .iter()
            .any(|c| (p.position - c.point).norm() <= reach + 0.5 * c.length);
    }
    (0..keep.len()).filter(|&i| keep[i]).collect()
}

/// What the removal planner needs besides the runs.
pub struct Setup<'a> {
    /// The compliant tool.
    pub tool: &'a ToolModel,
    /// The arm.
    pub robot: &'a Robot,
    /// Robot base from the reference frame.
    pub workcell: &'a Workcell,
    /// The planner's settings.
    pub config: &'a PlanConfig,
}

/// A region's runs with their dwell and the allowance used, or why the region is left out
/// (the robust solve found no allowance without predicted over-grind).
pub type Dwelled = Result<(Vec<Run>, f64), String>;

/// Turns one region's runs into one-contact pieces carrying the dwell the robust solve gives
/// them, starting from `allowance` mm; refuses a contact whose force a servo cannot hold
/// (naming the point and the joint).
pub fn set_dwell(
    runs: Vec<Run>,
    region: &RegionInfo,
    inspection: &Inspection,
    setup: &Setup,
    allowance: f64,
) -> Result<Dwelled, PlanError> {
    let (tool, robot, workcell, config) = (setup.tool, setup.robot, setup.workcell, setup.config);
    let solve = solve_config(&runs, robot, config)?;
    let mut runs = split(runs);
    let back = reference_from_robot(workcell);
    let pieces: Vec<&PlannedPass> = runs.iter().flatten().collect();
    let contacts: Vec<Contact> = pieces.iter().map(|p| contact(p, &back)).collect();
    for (p, c) in pieces.iter().zip(&contacts) {
        let push = workcell.direction_from_reference(&c.normal) * tool.force_n();
        if let Some(o) = force::overload(robot, &p.points[0].q, &push, config.force_share) {
            let s = c.point;
            return Err(PlanError::Config(format!(
                "region {}: contact at ({:.2}, {:.2}, {:.2}) mm: joint {} needs {:.3} N m to \
                 hold {:.2} N, more than its {:.3} N m (`force_share` {})",
                region.id,
                s.x,
                s.y,
                s.z,
                o.name,
                o.torque_nm,
                tool.force_n(),
                o.limit_nm,
                config.force_share
            )));
        }
    }
    let joints: Vec<JointError> = pieces
        .iter()
        .map(|p| joint_error(robot, &p.points[0].q, &back))
        .collect();
    let ball_mm = robot.tool.radius * 1e3;
    let reach = Influence::new(tool, ball_mm).patch_radius();
    let cores: Vec<SurfacePoint> = cores_near(inspection, &contacts, reach)
        .into_iter()
        .map(|i| inspection.points[i])
        .collect();
    let problem = Problem {
        tool,
        ball_mm,
        contacts: &contacts,
        joints: &joints,
        cores: &cores,
        tolerance: inspection.tolerance.unwrap_or(config.tolerance_mm),
    };
    let robust = match removal::solve_robust(&problem, allowance, &solve, &config.monte_carlo) {
        Ok(r) => r,
        Err(m) => return Ok(Err(format!("region left out by the removal planner: {m}"))),
    };
    let planned = runs
        .iter_mut()
        .flatten()
        .zip(&robust.plan.dwell)
        .zip(&contacts);
    for ((piece, t), c) in planned {
        piece.dwell_s = Some(*t);
        piece.feed_mm_s = c.length / t.max(f64::MIN_POSITIVE);
    }
    Ok(Ok((runs, robust.allowance)))
}

/// The dwell solve's settings with the fastest feed lowered to what the joints allow along
/// the slowest of `runs`' strokes (`stroke::chain_limits`): a continuous stroke's shortest
/// dwell per contact is its length at that feed, `t_min = piece / feed`.
fn solve_config(
    runs: &[Run],
    robot: &Robot,
    config: &PlanConfig,
) -> Result<removal::RemovalConfig, PlanError> {
    let mut solve = config.removal.clone();
    for piece in runs.iter().flatten() {
        let (s, q, _) = chain_knots(&[piece]);
        let lim = chain_limits(&JointSpline::new(s, q), robot, config);
        solve.feed_max_mm_s = solve.feed_max_mm_s.min(lim.velocity * 1e3);
    }
    if solve.feed_min_mm_s >= solve.feed_max_mm_s {
        return Err(PlanError::Config(format!(
            "`removal.feed_min_mm_s` {} is not below the {:.3} mm/s the joints allow along \
             the strokes",
            solve.feed_min_mm_s, solve.feed_max_mm_s
        )));
    }
    Ok(solve)
}

/// Dwell-equivalent of the press segments per pass index, s: a press moves the ball between
/// touching the surface and the preload, and Preston's removal summed over the contact patch
/// is `k F v` (linear in the force, F = rate x depth), so each bus period of a press counts
/// as `period x depth / preload` of dwell (trapezoid over its samples) at the contact it
/// presses into (the next grinding piece) or out of (the previous one).
fn press_dwell(prog: &Program, robot: &Robot, wc: &Workcell, preload: f64) -> Vec<f64> {
    let mut out = vec![0.0; prog.passes.len()];
    let segs = &prog.segments;
    for (i, seg) in segs.iter().enumerate() {
        if seg.kind != SegmentKind::Press || preload <= 0.0 {
            continue;
        }
        let grind = |j: Option<usize>| {
            j.and_then(|j| segs.get(j))
                .filter(|s| s.kind == SegmentKind::Grind)
                .and_then(|s| s.pass)
        };
        let (pass, point) = match (grind(Some(i + 1)), grind(i.checked_sub(1))) {
            (Some(p), _) => (p, &prog.passes[p].points[0]),
            (None, Some(p)) => (p, &prog.passes[p].points[prog.passes[p].points.len() - 1]),
            (None, None) => continue,
        };
        let normal = wc.direction_from_reference(&Vector3::from(point.normal));
        let contact = Vector3::from(point.tip_m);
        let depth = |k: usize| {
            let tip = robot.fk(prog.trajectory.sample(k)).position;
            (preload - (tip - contact).dot(&normal) * 1e3).clamp(0.0, preload) / preload
        };
        let shares: Vec<f64> = (seg.first_sample..=seg.last_sample).map(depth).collect();
        let sum: f64 = shares.windows(2).map(|w| 0.5 * (w[0] + w[1])).sum();
        out[pass] += sum * prog.trajectory.period;
    }
    out
}

/// The part predicted after `prog`, and the regions whose Monte Carlo low quantile
/// over-grinds by more than the tolerance (with the reason; the caller leaves them out): per
/// region, the removal of the time the trajectory spends on each piece actually in the
/// program (its presses counted, `press_dwell`), before/after statistics and the spread.
pub fn predict(
    prog: &Program,
    inspection: &Inspection,
    allowances: &[(usize, f64)],
    setup: &Setup,
) -> Result<(RemovalReport, Vec<(usize, String)>), PlanError> {
    let (tool, robot, workcell, config) = (setup.tool, setup.robot, setup.workcell, setup.config);
    let back = reference_from_robot(workcell);
    let ball_mm = robot.tool.radius * 1e3;
    let influence = Influence::new(tool, ball_mm);
    let tolerance = inspection.tolerance.unwrap_or(config.tolerance_mm);
    let mut report = RemovalReport {
        force_n: tool.force_n(),
        preload_mm: tool.preload_mm,
        tolerance_mm: tolerance,
        regions: Vec::new(),
        rows: Vec::new(),
    };
    let press = press_dwell(prog, robot, workcell, tool.preload_mm);
    let mut failed = Vec::new();
    for &(id, allowance_mm) in allowances {
        let (index, pieces): (Vec<usize>, Vec<&PlannedPass>) = prog
            .passes
            .iter()
            .enumerate()
            .filter(|(_, p)| p.region == id)
            .unzip();
        let contacts: Vec<Contact> = pieces.iter().map(|p| contact(p, &back)).collect();
        let dwell: Vec<f64> = pieces
            .iter()
            .zip(&index)
            .map(|(p, &i)| p.dwell_s.unwrap_or(0.0) + press[i])
            .collect();
        let joints: Vec<JointError> = pieces
            .iter()
            .map(|p| joint_error(robot, &p.points[0].q, &back))
            .collect();
        let idx = cores_near(inspection, &contacts, influence.patch_radius());
        let cores: Vec<(Point3<f64>, Vector3<f64>, f64)> = idx
            .iter()
            .map(|&i| {
                let p = inspection.points[i];
                let d = if p.distance.is_finite() {
                    p.distance
                } else {
                    0.0
                };
                (p.position, p.normal, d)
            })
            .collect();
        let geometry: Vec<(Point3<f64>, Vector3<f64>)> = cores.iter().map(|c| (c.0, c.1)).collect();
        let a = removal::influence::matrix(&influence, &contacts, &geometry);
        let removed = removal::influence::apply(&a, &dwell, cores.len());
        let before: Vec<f64> = cores.iter().map(|c| c.2).collect();
        let after: Vec<f64> = before.iter().zip(&removed).map(|(d, r)| d - r).collect();
        let mc = spread(
            tool,
            ball_mm,
            &contacts,
            &joints,
            &dwell,
            &cores,
            &config.monte_carlo,
        );
        let low = mc.low(config.monte_carlo.quantile);
        let median = mc.low(0.5);
        let lowest = low.iter().copied().fold(f64::INFINITY, f64::min);
        if lowest < -tolerance {
            failed.push((
                id,
                format!(
                    "region left out by the removal planner: the trajectory's dwell \
                     over-grinds to {lowest:.3} mm at the {} quantile, beyond the tolerance \
                     {tolerance} mm",
                    config.monte_carlo.quantile
                ),
            ));
            continue;
        }
        for (k, &i) in idx.iter().enumerate() {
            let p = inspection.points[i].position;
            report.rows.push(PredictedRow {
                position: [p.x, p.y, p.z],
                deviation: before[k],
                residual: after[k],
                spread_p95: median[k] - low[k],
            });
        }
        let area = inspection
            .regions
            .iter()
            .find(|r| r.id == id)
            .map_or(0.0, |r| {
                r.area / inspection.region_points(id).len().max(1) as f64
            });
        report.regions.push(RegionPrediction {
            region: id,
            allowance_mm,
            dwell: pieces
                .iter()
                .zip(&contacts)
                .zip(&dwell)
                .map(|((p, c), t)| DwellPoint {
                    surface_mm: [c.point.x, c.point.y, c.point.z],
                    dwell_s: *t,
                    feed_mm_s: p.feed_mm_s,
                })
                .collect(),
            core_points: idx.len(),
            before: Stats::of(&before, tolerance, area),
            after: Stats::of(&after, tolerance, area),
            after_low_p95_mm: if lowest.is_finite() { lowest } else { 0.0 },
        });
    }
    Ok((report, failed))
}

/// predicted.csv: a header and one row per core point, `spread_p95` empty when the Monte
/// Carlo drew nothing.
pub fn predicted_csv(
    report: &RemovalReport,
    mc: &super::removal::montecarlo::MonteCarloConfig,
) -> String {
    let mut out = String::from("x,y,z,deviation,predicted_residual,spread_p95\n");
    for r in &report.rows {
        let spread = if mc.draws > 0 {
            format!("{:.6}", r.spread_p95)
        } else {
            String::new()
        };
        out.push_str(&format!(
            "{:.6},{:.6},{:.6},{:.6},{:.6},{spread}\n",
            r.position[0], r.position[1], r.position[2], r.deviation, r.residual
        ));
    }
    out
}

/// Records every contact of `strokes` as left out for `reason` (`tip_m`: the contact itself in
/// the robot frame, m).
pub fn leave_out(
    strokes: &[super::raster::Stroke],
    reason: &str,
    wc: &Workcell,
    unreachable: &mut Vec<super::report::UnreachablePoint>,
) {
    for (si, stroke) in strokes.iter().enumerate() {
        for (pi, p) in stroke.points.iter().enumerate() {
            unreachable.push(super::report::UnreachablePoint {
                region: stroke.region,
                layer: stroke.layer,
                stroke: si,
                point: pi,
                surface_mm: [p.surface.x, p.surface.y, p.surface.z],
                tip_m: wc.point_from_reference_mm(&p.surface).coords.into(),
                reason: reason.to_string(),
            });
        }
    }
}

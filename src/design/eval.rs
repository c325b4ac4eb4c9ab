//! One candidate cell: the part's placement, the table's fixture as solids, and its score (the
//! share of articular-surface samples some table angle reaches), all through the planner's IK
//! and collision model.
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use serde::Serialize;

use super::part::{Part, SampleVerdict};
use crate::motion::collide::{Allow, Hit, Obstacle, Scene};
use crate::motion::{PlanConfig, Solid};
use crate::robot::{IkTarget, Robot, Servo, Turntable, Unreachable, Workcell};

/// Half width of the table's spindle (a square bar along the axis from the part's centroid
/// out past the part on the fixture side), m: 6 mm, a 12 mm mandrel that holds a femoral
/// component by its box cuts.
const SPINDLE_HALF_M: f64 = 0.006;
/// Step between the cubes that stand for the spindle (solids are axis-aligned boxes), m: under
/// twice their half width, so the chain has no gaps.
const SPINDLE_STEP_M: f64 = 0.008;
/// Free length of the spindle between the part and the housing, m (20 mm: room for the
/// ball and shank at the part's fixture-side rim).
const SPINDLE_FREE_M: f64 = 0.02;
/// Half size of the table's servo housing, m (a 40 mm cube: the 270 degree bus servo with
/// its bearing).
const HOUSING_HALF_M: f64 = 0.02;
/// Half width of the post carrying the housing from the base plane, m (a 24 mm bar).
const POST_HALF_M: f64 = 0.012;
/// Lowest point of the part above the base plane at every table angle, m (5 mm).
const FLOOR_CLEARANCE_M: f64 = 0.005;
/// Every this many part points are tried for the floor clearance (the check is a bound on a
/// 1.7 mm sampling; every 4th is within 4 mm of every point and the clearance's margin is the
/// solids' collision margin anyway).
const FLOOR_STRIDE: usize = 4;

/// A candidate cell.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    /// The table axis, robot frame (unit; positive angles turn right-handed about it).
    pub axis: [f64; 3],
    /// The part's direction that lies along the table axis (reference frame, unit): the
    /// fixture holds the part from the other side.
    pub mount: [f64; 3],
    /// Where the part's centroid sits on the axis, robot frame, m.
    pub centre: [f64; 3],
    /// Index of the shank length in the design's list.
    pub shank: usize,
    /// The shank length, m.
    pub shank_m: f64,
}

/// What the scoring needs.
pub struct Context<'a> {
    /// The part.
    pub part: &'a Part,
    /// One robot per shank length.
    pub robots: &'a [Robot],
    /// The shank lengths, m.
    pub shanks: &'a [f64],
    /// The planner's settings (IK, collision model, home, contact offset).
    pub plan: &'a PlanConfig,
    /// The table's servo (range, limits).
    pub servo: Servo,
}

/// A candidate's score.
pub struct Score {
    /// Share of the samples reached.
    pub coverage: f64,
    /// Each sample's verdict (when asked for).
    pub verdicts: Vec<SampleVerdict>,
}

/// The rotation taking `from` onto `to` (a half turn about a perpendicular when opposite).
fn rotation_between(from: &Vector3<f64>, to: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(from, to).unwrap_or_else(|| {
        let side = if from.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        UnitQuaternion::from_axis_angle(
            &Unit::new_normalize(from.cross(&side)),
            std::f64::consts::PI,
        )
    })
}

/// The part's placement at table angle 0: `mount` along the axis, the centroid on the centre.
pub fn placement(c: &Candidate, centroid_mm: &Point3<f64>) -> Workcell {
    let r = rotation_between(&Vector3::from(c.mount), &Vector3::from(c.axis));
    let t = Vector3::from(c.centre) - r * (centroid_mm.coords * 1e-3);
    Workcell {
        robot_from_reference: Isometry3::from_parts(Translation3::from(t), r).to_homogeneous(),
    }
}

/// The candidate's turntable.
pub fn table(c: &Candidate, servo: &Servo) -> Turntable {
    Turntable {
        servo: servo.clone(),
        axis: Unit::new_normalize(Vector3::from(c.axis)),
        centre: Point3::from(c.centre),
    }
}

/// An axis-aligned cube of half size `h` about `p`.
fn cube(name: &str, p: &Vector3<f64>, h: f64) -> Solid {
    Solid {
        name: name.into(),
        min: [p.x - h, p.y - h, p.z - h],
        max: [p.x + h, p.y + h, p.z + h],
    }
}

/// The cell's solids: the base plane, and the table's spindle (from the part's centroid along
/// the axis out past the part's fixture side), housing and post down to the base plane. None
/// when the housing would sit below the base plane.
pub fn solids(c: &Candidate, part: &Part) -> Option<Vec<Solid>> {
    let (a, centre) = (Vector3::from(c.axis), Vector3::from(c.centre));
    let d = Vector3::from(c.mount);
    let back = part
        .points
        .iter()
        .map(|p| (part.centroid - p.position).dot(&d))
        .fold(0.0, f64::max)
        * 1e-3;
    let reach = back + SPINDLE_FREE_M;
    let mut out = vec![Solid {
        name: "table".into(),
        min: [-0.6, -0.6, -0.05],
        max: [0.6, 0.6, 0.0],
    }];
    let steps = (reach / SPINDLE_STEP_M).ceil() as usize;
    for k in 0..=steps {
        let p = centre - a * (k as f64 * SPINDLE_STEP_M).min(reach);
        out.push(cube("table spindle", &p, SPINDLE_HALF_M));
    }
    let e = centre - a * (reach + HOUSING_HALF_M);
    if e.z - HOUSING_HALF_M < 0.0 {
        return None;
    }
    out.push(cube("table housing", &e, HOUSING_HALF_M));
    if e.z - HOUSING_HALF_M > 1e-6 {
        out.push(Solid {
            name: "table post".into(),
            min: [e.x - POST_HALF_M, e.y - POST_HALF_M, 0.0],
            max: [e.x + POST_HALF_M, e.y + POST_HALF_M, e.z - HOUSING_HALF_M],
        });
    }
    Some(out)
}

/// Table angles every `step_deg` over the servo's range, 0 first.
fn angles(range: [f64; 2], step_deg: f64) -> Vec<f64> {
    let step = step_deg.to_radians();
    let mut out = vec![0.0];
    let (lo, hi) = (
        (range[0] / step).ceil() as i64,
        (range[1] / step).floor() as i64,
    );
    out.extend((lo..=hi).filter(|&k| k != 0).map(|k| k as f64 * step));
    out
}

/// The nearness of a refusal (higher: the pose got further) and its rule's name. The IK tests
/// the axis against the arm plane first, then the wrist's reach, then the joint limits: a
/// table angle that fails a later test came nearer.
fn ik_rule(e: &Unreachable) -> (u8, String) {
    match e {
        Unreachable::OutOfReach { .. } => (2, "wrist centre out of reach".into()),
        Unreachable::AxisOffPlane { .. } => {
            (1, "tool axis off the arm plane beyond the cone".into())
        }
        Unreachable::JointLimit { joint, .. } => (3, format!("joint limit of {joint}")),
        other => (1, format!("IK: {other}")),
    }
}

fn hit_rule(h: &Hit) -> (u8, String) {
    let what = match &h.obstacle {
        Obstacle::Part { .. } => format!("{} against the part", h.body),
        Obstacle::SecondFace { .. } => "ball on a second face (tool does not fit)".into(),
        Obstacle::Solid(name) => format!("{} against the {name}", h.body),
    };
    (4, what)
}

/// Scores `c` on the first `n` surface samples with table angles every `step_deg`; None when
/// the cell is not buildable (housing below the base plane, the part into the base plane, or
/// the arm's home pose against the part at every angle).
pub fn score(
    ctx: &Context,
    c: &Candidate,
    n: usize,
    step_deg: f64,
    verdicts: bool,
) -> Option<Score> {
    let part = ctx.part;
    let robot = &ctx.robots[c.shank];
    let solids = solids(c, part)?;
    let wc0 = placement(c, &part.centroid);
    let table = table(c, &ctx.servo);
    let cells: Vec<(f64, Workcell)> = angles(table.range(), step_deg)
        .into_iter()
        .map(|a| (a, table.workcell_at(&wc0, a)))
        .collect();
    let floor = |wc: &Workcell| {
        part.points
            .iter()
            .step_by(FLOOR_STRIDE)
            .map(|p| wc.point_from_reference_mm(&p.position).z)
            .fold(f64::INFINITY, f64::min)
    };
    if cells.iter().any(|(_, wc)| floor(wc) < FLOOR_CLEARANCE_M) {
        return None;
    }
    let mut cc = ctx.plan.collision.clone();
    cc.solids = solids.clone();
    let mut scene = Scene::new(&part.points, robot, &wc0, &cc);
    let home = &ctx.plan.home;
    let reach = robot.tool.radius_mm() + ctx.plan.contact_offset_mm + ctx.plan.allowance_mm;
    let samples = &part.surface[..n.min(part.surface.len())];
    let mut reached: Vec<Option<f64>> = vec![None; samples.len()];
    let mut nearest: Vec<(u8, String, f64)> = vec![(0, String::new(), 0.0); samples.len()];
    let mut usable = false;
    for (a, wc) in &cells {
        scene.place(wc, &solids);
        if scene.check(robot, home, Allow::Free).is_some() {
            continue;
        }
        usable = true;
        for (k, (p, nrm)) in samples.iter().enumerate() {
            if reached[k].is_some() {
                continue;
            }
            let tip = p + nrm * reach;
            let target = IkTarget {
                position: wc.point_from_reference_mm(&tip).coords,
                axis: -wc.direction_from_reference(nrm),
                roll: None,
            };
            let (rank, rule) = match robot.ik(&target, home, &ctx.plan.ik) {
                Err(e) => ik_rule(&e),
                Ok(sol) => match scene.check(robot, &sol.q, Allow::Grind) {
                    None => {
                        reached[k] = Some(*a);
                        continue;
                    }
                    Some(h) => hit_rule(&h),
                },
            };
            if rank > nearest[k].0 {
                nearest[k] = (rank, rule, *a);
            }
        }
    }
    if !usable {
        return None;
    }
    let coverage =
        reached.iter().filter(|r| r.is_some()).count() as f64 / samples.len().max(1) as f64;
    let verdicts = if verdicts {
        samples
            .iter()
            .zip(reached.iter().zip(&nearest))
            .map(|((p, nrm), (r, (_, rule, at)))| SampleVerdict {
                position_mm: [p.x, p.y, p.z],
                normal: [nrm.x, nrm.y, nrm.z],
                angle_deg: r.map(f64::to_degrees),
                refused_by: r.is_none().then(|| {
                    if rule.is_empty() {
                        "the arm's home pose against the part".into()
                    } else {
                        rule.clone()
                    }
                }),
                nearest_angle_deg: r.is_none().then(|| at.to_degrees()),
            })
            .collect()
    } else {
        Vec::new()
    };
    Some(Score { coverage, verdicts })
}

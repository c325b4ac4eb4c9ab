//! The collision model of a plan: the part (the inspection's reference points with normals, in
//! the reference frame, through the project's k-d tree), fixed solids of the cell (boxes in the
//! robot frame), and the moving bodies at a joint sample: the tool's ball, its shank and the
//! arm's links as capsules between the URDF joint origins. Method: docs/ALGORITHMS.md,
//! "Collision model".
use std::collections::HashSet;
use std::sync::Mutex;

use nalgebra::{Matrix4, Point3, Vector3};
use serde::{Deserialize, Serialize};

pub use super::contact::{Body, Hit, Obstacle};
use super::inspection::SurfacePoint;
use crate::robot::{angle_between, Robot, Workcell};
use crate::spatial::Neighbours;

/// Settings of the collision model. Lengths in millimetres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CollisionConfig {
    /// Clearance every body keeps from the part and the solids during free motion, and the
    /// shank and links during grinding, mm (1.0: above the 0.1 mm path error and the tool
    /// tip's servo-resolution error, below the approach height).
    pub margin_mm: f64,
    /// How far the ball may be inside the nominal surface at and next to a contact (grinding,
    /// approach, retract, re-orientation), mm (0.1: the planner's `max_path_error_mm`).
    pub contact_tolerance_mm: f64,
    /// Two reference points inside the ball whose normals are more than this apart mean the
    /// ball touches a second face: the tool does not fit there, degrees (45).
    pub second_face_deg: f64,
    /// Capsule radius of the link after each actuated joint, base to wrist, mm ([30, 20, 20,
    /// 12]): the base turret, the two 40 mm wide servo brackets, the wrist with the tool motor
    /// (24 mm across). The link after the last joint is the tool (tool.toml). Estimates from
    /// the kit's parts: measure the real arm.
    pub link_radius_mm: Vec<f64>,
    /// Height along the surface normal a transit climbs to before it travels, when the
    /// direct move is not clear, mm (30: half the part's smallest extent in the default cell).
    pub safe_lift_mm: f64,
    /// Largest ball-centre move between two pieces of a run made as a straight line at the
    /// contact (a layer step, a turn about the ball centre), mm (0.5: one contact-point
    /// spacing); longer moves lift off, travel and come down again.
    pub glide_mm: f64,
    /// Angle step of the tool axis between the IK waypoints of a turn about the ball centre,
    /// degrees (1: the tip strays under 0.01 mm between waypoints).
    pub turn_step_deg: f64,
    /// Fixed solids of the cell (table, fixture), robot frame; `solids.toml` beside the
    /// workcell file adds its `[[solid]]` entries.
    pub solids: Vec<Solid>,
    /// How much deeper than `contact_tolerance_mm` the ball may be while grinding (and
    /// pressing in or out), mm: the compliant tool's preload in removal mode, set by the
    /// planner from tool.toml and by `run` from plan.json; 0 in rigid mode. Not a user key.
    #[serde(skip)]
    pub press_mm: f64,
}

impl Default for CollisionConfig {
    fn default() -> Self {
        CollisionConfig {
            margin_mm: 1.0,
            contact_tolerance_mm: 0.1,
            second_face_deg: 45.0,
            link_radius_mm: vec![30.0, 20.0, 20.0, 12.0],
            safe_lift_mm: 30.0,
            glide_mm: 0.5,
            turn_step_deg: 1.0,
            press_mm: 0.0,
            solids: Vec::new(),
        }
    }
}

impl CollisionConfig {
    /// Checks the values; names the key at fault.
    pub fn check(&self, dof: usize) -> Result<(), String> {
        let positive = [
            ("margin_mm", self.margin_mm),
            ("second_face_deg", self.second_face_deg),
            ("safe_lift_mm", self.safe_lift_mm),
            ("glide_mm", self.glide_mm),
            ("turn_step_deg", self.turn_step_deg),
        ];
        for (name, v) in positive {
            if !(v > 0.0 && v.is_finite()) {
                return Err(format!("collision.{name} must be > 0 (got {v})"));
            }
        }
        if !(self.contact_tolerance_mm >= 0.0 && self.contact_tolerance_mm.is_finite()) {
            return Err("collision.contact_tolerance_mm must be >= 0".into());
        }
        if self.link_radius_mm.len() + 1 != dof {
            return Err(format!(
                "collision.link_radius_mm has {} radii, the arm {} links before the tool",
                self.link_radius_mm.len(),
                dof.saturating_sub(1)
            ));
        }
        if self
            .link_radius_mm
            .iter()
            .any(|r| !(*r >= 0.0 && r.is_finite()))
        {
            return Err("collision.link_radius_mm must be >= 0".into());
        }
        for (i, s) in self.solids.iter().enumerate() {
            if !(0..3).all(|k| s.min[k] < s.max[k] && s.min[k].is_finite() && s.max[k].is_finite())
            {
                return Err(format!(
                    "collision.solids[{i}] ({}): min must be below max",
                    s.name
                ));
            }
        }
        Ok(())
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SolidsFile {
    #[serde(default)]
    solid: Vec<Solid>,
}

/// The `[[solid]]` entries of `solids.toml` beside `workcell` (none when there is no such
/// file).
pub fn solids_beside(workcell: &std::path::Path) -> Result<Vec<Solid>, crate::robot::RobotError> {
    let file = workcell.with_file_name("solids.toml");
    if !file.exists() {
        return Ok(Vec::new());
    }
    let parsed: SolidsFile = crate::robot::error::read_toml(&file)?;
    for (i, s) in parsed.solid.iter().enumerate() {
        let ok =
            (0..3).all(|k| s.min[k].is_finite() && s.max[k].is_finite() && s.min[k] < s.max[k]);
        if !ok {
            let msg = "min must be finite and below max on every axis";
            return Err(crate::robot::RobotError::bad(
                &file,
                format!("solid[{i}] ({})", s.name),
                msg,
            ));
        }
    }
    Ok(parsed.solid)
}

/// A fixed solid: an axis-aligned box in the robot base frame, metres.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Solid {
    /// Name in messages ("table", "fixture post").
    pub name: String,
    /// Lowest corner, m.
    pub min: [f64; 3],
    /// Highest corner, m.
    pub max: [f64; 3],
}

/// What a sample may touch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Allow {
    /// Nothing: every body keeps the margin (transits, home).
    Free,
    /// The ball may touch the part down to the contact tolerance; the rest keeps the margin
    /// (approach, retract, re-orientation).
    Contact,
    /// As `Contact`, and the ball must not touch a second face (grinding).
    Grind,
}

/// Points closer to the ball's centre than its radius less this count as inside it, mm.
const INSIDE_MM: f64 = 1e-3;

/// The reference points inside the ball (index, distance from the centre) and the nearest.
#[derive(Default)]
struct Inside {
    points: Vec<(usize, f64)>,
    nearest: Option<usize>,
}

/// A capsule: the segment `a`-`b` swept by `radius` (reference frame, mm).
#[derive(Debug, Clone, Copy)]
struct Capsule {
    body: Body,
    a: Point3<f64>,
    b: Point3<f64>,
    radius: f64,
}

/// Capsule `shank` from where it leaves a ball of radius `ball` at its end `a` (the shank's
/// axis meets the sphere `sqrt(ball^2 - r^2)` up; its end cap stays inside shank and ball).
fn outside_ball(shank: Capsule, ball: f64) -> Capsule {
    let d = shank.b - shank.a;
    let len = d.norm();
    if len <= 0.0 {
        return shank;
    }
    let h = (ball * ball - shank.radius * shank.radius)
        .max(0.0)
        .sqrt()
        .min(len);
    Capsule {
        a: shank.a + d * (h / len),
        ..shank
    }
}

/// The scene a plan moves in.
pub struct Scene<'a> {
    points: &'a [SurfacePoint],
    index: Neighbours,
    /// Reference-point spacing, mm: within it of a point its tangent plane stands for the part.
    patch: f64,
    lo: Point3<f64>,
    hi: Point3<f64>,
    ref_from_robot: Matrix4<f64>,
    robot_from_ref: Matrix4<f64>,
    ball: f64,
    shank: (f64, f64),
    cfg: CollisionConfig,
    /// Samples already found clear (joint values bit for bit, and the rule): `plan` checks
    /// every free-motion sample while it builds the program and all samples again at the end;
    /// the answer is a function of the two, so the second check of these is a look-up.
    clear: Mutex<HashSet<(Vec<u64>, Allow)>>,
}

impl<'a> Scene<'a> {
    /// The scene of `points` (reference frame, mm) placed by `wc`, for `robot`'s tool.
    pub fn new(
        points: &'a [SurfacePoint],
        robot: &Robot,
        wc: &Workcell,
        cfg: &CollisionConfig,
    ) -> Self {
        let pos: Vec<Point3<f64>> = points.iter().map(|p| p.position).collect();
        let index = Neighbours::new(&pos);
        let (mut lo, mut hi) = (Point3::origin(), Point3::origin());
        if let Some(first) = pos.first() {
            (lo, hi) = (*first, *first);
            for p in &pos {
                lo = lo.inf(p);
                hi = hi.sup(p);
            }
        }
        let scale = Matrix4::new_scaling(1e3);
        let robot_from_ref = wc.robot_from_reference * Matrix4::new_scaling(1e-3);
        let ref_from_robot = robot_from_ref.try_inverse().unwrap_or(scale);
        Scene {
            points,
            patch: spacing(&pos, &index),
            index,
            lo,
            hi,
            ref_from_robot,
            robot_from_ref,
            ball: robot.tool.radius * 1e3,
            shank: (
                robot.tool.shank_radius() * 1e3,
                robot.tool.shank_length() * 1e3,
            ),
            cfg: cfg.clone(),
            clear: Mutex::new(HashSet::new()),
        }
    }

    /// The settings.
    pub fn config(&self) -> &CollisionConfig {
        &self.cfg
    }

    /// The moving bodies at joint sample `q`, reference frame, mm.
    fn bodies(&self, robot: &Robot, q: &[f64]) -> Vec<Capsule> {
        let (frames, _) = robot.joint_frames(q);
        let tool = robot.fk(q);
        let to_ref = |v: &Vector3<f64>| self.ref_from_robot.transform_point(&Point3::from(*v));
        let tip = to_ref(&tool.position);
        let axis = (self.ref_from_robot.fixed_slice::<3, 3>(0, 0) * tool.axis).normalize();
        let mut out = vec![
            Capsule {
                body: Body::Ball,
                a: tip,
                b: tip,
                radius: self.ball,
            },
            Capsule {
                body: Body::Shank,
                a: tip,
                b: tip - axis * self.shank.1,
                radius: self.shank.0,
            },
        ];
        for (i, r) in self.cfg.link_radius_mm.iter().enumerate() {
            if let (Some(f0), Some(f1)) = (frames.get(i), frames.get(i + 1)) {
                let (a, b) = (
                    to_ref(&f0.translation.vector),
                    to_ref(&f1.translation.vector),
                );
                out.push(Capsule {
                    body: Body::Link(i),
                    a,
                    b,
                    radius: *r,
                });
            }
        }
        out
    }

    /// The first body at `q` nearer the part or a solid than `allow` permits. A sample found
    /// clear before under the same rule is clear again without a new search; so is one found
    /// clear under `Free` when `Contact` is asked (`Free` asks every body for the margin and
    /// searches at least the points `Contact` does, so its smallest clearance is no larger).
    pub fn check(&self, robot: &Robot, q: &[f64], allow: Allow) -> Option<Hit> {
        let key: Vec<u64> = q.iter().map(|v| v.to_bits()).collect();
        let mut known = self.clear.lock().unwrap_or_else(|e| e.into_inner());
        let mut key = (key, allow);
        if known.contains(&key) {
            return None;
        }
        if allow == Allow::Contact {
            key.1 = Allow::Free;
            let found = known.contains(&key);
            key.1 = Allow::Contact;
            if found {
                return None;
            }
        }
        let hit = self.search(robot, q, allow);
        if hit.is_none() {
            known.insert(key);
        }
        hit
    }

    /// `check` without the look-up.
    fn search(&self, robot: &Robot, q: &[f64], allow: Allow) -> Option<Hit> {
        let m = self.cfg.margin_mm;
        for c in self.bodies(robot, q) {
            // grinding: the stretch of the shank inside the ball is the ball, which may touch
            let c = match (c.body, allow) {
                (Body::Shank, Allow::Grind) => outside_ball(c, self.ball),
                _ => c,
            };
            let need = match (c.body, allow) {
                (Body::Ball, Allow::Contact) => -self.cfg.contact_tolerance_mm,
                (Body::Ball, Allow::Grind) => -(self.cfg.contact_tolerance_mm + self.cfg.press_mm),
                _ => m,
            };
            let grind_ball = c.body == Body::Ball && allow == Allow::Grind;
            let mut inside = Inside::default();
            let found = self.part_clearance(&c, need, grind_ball.then_some(&mut inside));
            if let Some((clear, point)) = found {
                if clear < need {
                    let at = self.points[point].position;
                    return Some(Hit {
                        body: c.body,
                        obstacle: Obstacle::Part {
                            point,
                            at_mm: [at.x, at.y, at.z],
                        },
                        clearance_mm: clear,
                    });
                }
            }
            if let Some(hit) = self.solid_hit(&c, m) {
                return Some(hit);
            }
            if let Some(n0) = inside.nearest.map(|i| self.points[i].normal) {
                if let Some(hit) = self.second_face_among(&inside.points, &n0) {
                    return Some(hit);
                }
            }
        }
        None
    }

    /// The ball at `centre` (reference frame, mm) touching a face whose normal lies more than
    /// `second_face_deg` from `normal` (default: the nearest reference point's normal).
    pub fn second_face(&self, centre: &Point3<f64>, normal: Option<&Vector3<f64>>) -> Option<Hit> {
        let inside: Vec<(usize, f64)> = self
            .index
            .within_unsorted(centre, self.ball - INSIDE_MM)
            .iter()
            .map(|nb| (nb.index, nb.dist2.sqrt()))
            .collect();
        let n0 = match normal {
            Some(n) => *n,
            None => self.points[self.index.nearest(centre)?.index].normal,
        };
        self.second_face_among(&inside, &n0)
    }

    /// The first of `inside` (points in the ball with their distances from its centre) whose
    /// normal lies more than `second_face_deg` from `n0`.
    fn second_face_among(&self, inside: &[(usize, f64)], n0: &Vector3<f64>) -> Option<Hit> {
        inside.iter().find_map(|&(i, dist)| {
            let p = &self.points[i];
            let angle = angle_between(&p.normal, n0).to_degrees();
            (angle > self.cfg.second_face_deg).then(|| Hit {
                body: Body::Ball,
                obstacle: Obstacle::SecondFace {
                    point: i,
                    at_mm: [p.position.x, p.position.y, p.position.z],
                    angle_deg: angle,
                },
                clearance_mm: dist - self.ball,
            })
        })
    }

    /// The ball's clearance from the part at `centre` (reference frame, mm), down to `need`.
    pub fn ball_clearance(&self, centre: &Point3<f64>, need: f64) -> f64 {
        let c = Capsule {
            body: Body::Ball,
            a: *centre,
            b: *centre,
            radius: self.ball,
        };
        self.part_clearance(&c, need, None)
            .map_or(f64::INFINITY, |(d, _)| d)
    }

    /// Smallest clearance of `c` from the part and the point it is measured at, over the
    /// reference points within `need` (plus one spacing) of the capsule; None when none is
    /// near. Within the patch of a point (its foot on the tangent plane within the spacing)
    /// the distance is to the plane (signed: negative inside), else to the point. Marches
    /// along the axis: where the nearest point is farther than the reach, the stretch that
    /// distance clears is skipped (sphere tracing); near the part, one radius query per step.
    fn part_clearance(
        &self,
        c: &Capsule,
        need: f64,
        mut inside: Option<&mut Inside>,
    ) -> Option<(f64, usize)> {
        let reach = c.radius + need.max(0.0) + self.patch;
        let (slo, shi) = (c.a.inf(&c.b), c.a.sup(&c.b));
        if c.body != Body::Ball
            && (0..3).any(|k| slo[k] - reach > self.hi[k] || shi[k] + reach < self.lo[k])
        {
            return None;
        }
        let d = c.b - c.a;
        let len = d.norm();
        let dir = if len > 0.0 { d / len } else { Vector3::zeros() };
        let step = c.radius.max(1.0);
        let mut best: Option<(f64, usize)> = None;
        let mut t = 0.0;
        while t <= len {
            let centre = c.a + dir * t;
            let nearest = self.index.nearest(&centre)?;
            let gap = nearest.dist2.sqrt();
            if let Some(found) = inside.as_deref_mut() {
                found.nearest = Some(nearest.index);
            }
            if c.body == Body::Ball {
                // a centre deep in the part has no point within reach: the nearest says so
                let p = &self.points[nearest.index];
                let dn = (centre - p.position).dot(&p.normal);
                if dn < 0.0 {
                    best = Some((dn - c.radius, nearest.index));
                }
            }
            if gap > reach {
                t += gap - reach + 1e-9;
                continue;
            }
            let half = (step / 2.0).min((len - t) / 2.0);
            let query = reach + half;
            for nb in self.index.within_unsorted(&(centre + dir * half), query) {
                let p = &self.points[nb.index];
                if let Some(found) = inside.as_deref_mut() {
                    let d = nb.dist2.sqrt();
                    if d < c.radius - INSIDE_MM {
                        found.points.push((nb.index, d));
                    }
                }
                let along = if len > 0.0 {
                    (p.position - c.a).dot(&dir).clamp(0.0, len)
                } else {
                    0.0
                };
                let v = c.a + dir * along - p.position;
                let dn = v.dot(&p.normal);
                let lateral = (v - p.normal * dn).norm();
                let dist = if lateral <= self.patch { dn } else { v.norm() };
                if best.is_none_or(|(b, _)| dist - c.radius < b) {
                    best = Some((dist - c.radius, nb.index));
                }
            }
            if len == 0.0 {
                break;
            }
            t += step;
        }
        best
    }

    /// The first solid `c` comes within `margin` of.
    fn solid_hit(&self, c: &Capsule, margin: f64) -> Option<Hit> {
        let to_robot_mm = |p: &Point3<f64>| self.robot_from_ref.transform_point(p) * 1e3;
        let (a, b) = (to_robot_mm(&c.a), to_robot_mm(&c.b));
        self.cfg.solids.iter().find_map(|s| {
            let lo = Point3::from(Vector3::from(s.min) * 1e3);
            let hi = Point3::from(Vector3::from(s.max) * 1e3);
            let clear = segment_box_distance(&a, &b, &lo, &hi) - c.radius;
            (clear < margin).then(|| Hit {
                body: c.body,
                obstacle: Obstacle::Solid(s.name.clone()),
                clearance_mm: clear,
            })
        })
    }

    /// A robot-frame point (m) in the reference frame (mm).
    pub fn to_reference(&self, p: &Vector3<f64>) -> Point3<f64> {
        self.ref_from_robot.transform_point(&Point3::from(*p))
    }
}

/// Distance from `p` to the box `lo`..`hi`.
fn point_box_distance(p: &Point3<f64>, lo: &Point3<f64>, hi: &Point3<f64>) -> f64 {
    let d = Vector3::from_fn(|k, _| (lo[k] - p[k]).max(0.0).max(p[k] - hi[k]));
    d.norm()
}

/// Distance from the segment `a`-`b` to a box: the distance to a convex set is convex along
/// the segment, so a golden-section search finds its minimum.
fn segment_box_distance(
    a: &Point3<f64>,
    b: &Point3<f64>,
    lo: &Point3<f64>,
    hi: &Point3<f64>,
) -> f64 {
    const ITERATIONS: usize = 60; // 0.618^60: 3e-13 of the segment
    let f = |t: f64| point_box_distance(&(a + (b - a) * t), lo, hi);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut x0, mut x1) = (0.0, 1.0);
    for _ in 0..ITERATIONS {
        let (l, r) = (x1 - g * (x1 - x0), x0 + g * (x1 - x0));
        if f(l) <= f(r) {
            x1 = r;
        } else {
            x0 = l;
        }
    }
    f(0.5 * (x0 + x1)).min(f(0.0)).min(f(1.0))
}

/// Median distance from a reference point to its nearest other point, mm, over up to
/// `SAMPLES` points spread over the set.
fn spacing(pos: &[Point3<f64>], index: &Neighbours) -> f64 {
    const SAMPLES: usize = 2000;
    let step = (pos.len() / SAMPLES).max(1);
    let mut d: Vec<f64> = pos
        .iter()
        .step_by(step)
        .filter_map(|p| index.knn(p, 2).get(1).map(|n| n.dist2.sqrt()))
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

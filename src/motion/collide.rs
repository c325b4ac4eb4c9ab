//! The collision model of a plan: the part (the inspection's reference points with normals, in
//! the reference frame, through the project's k-d tree), fixed solids of the cell (boxes in the
//! robot frame), and the moving bodies at a joint sample: the tool's ball, its shank and the
//! arm's links as capsules between the URDF joint origins. Method: docs/ALGORITHMS.md,
//! "Collision model".
mod solids;
mod sweep;

use std::collections::HashSet;
use std::sync::Mutex;

use nalgebra::{Matrix4, Point3, Vector3};

pub use super::report::{Body, Hit, Obstacle};
use crate::repair::SurfacePoint;
use crate::robot::units::{mm, MM_PER_M, M_PER_MM};
use crate::robot::{angle_between, Robot, Workcell};
use crate::spatial::{Neighbour, Neighbours};
use solids::{segment_box_distance, spacing};
pub use solids::{solids_beside, solids_of, CollisionConfig, Solid};
use sweep::Carry;
pub use sweep::Sweep;

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

/// Margin on a cosine that stands in for an angle test (1e-9: the cosine of unit normals is
/// off by about 1e-16; a normal this close to the limit gets its angle computed).
const COS_SLACK: f64 = 1e-9;

/// Allowance for rounding in a bound that stands in for a search, mm (coordinates of hundreds of mm
/// carry rounding errors near 1e-13 mm; 1e-6 mm is far above them and far below any clearance).
const ROUNDING_MM: f64 = 1e-6;

/// The last nearest query of a search and its answer (a query repeated at the same point
/// answers the same).
type Seen = Option<(Point3<f64>, Neighbour)>;

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
        let scale = Matrix4::new_scaling(MM_PER_M);
        let robot_from_ref = wc.robot_from_reference * Matrix4::new_scaling(M_PER_MM);
        let ref_from_robot = robot_from_ref.try_inverse().unwrap_or(scale);
        Scene {
            points,
            patch: spacing(&pos, &index),
            index,
            lo,
            hi,
            ref_from_robot,
            robot_from_ref,
            ball: robot.tool.radius_mm(),
            shank: (mm(robot.tool.shank_radius()), mm(robot.tool.shank_length())),
            cfg: cfg.clone(),
            clear: Mutex::new(HashSet::new()),
        }
    }

    /// Moves the part to the placement `wc` and sets the fixed solids (the part's index is
    /// kept: it lies in the reference frame): the cell design tries many placements of one
    /// part. Forgets the samples found clear.
    pub fn place(&mut self, wc: &Workcell, solids: &[Solid]) {
        self.robot_from_ref = wc.robot_from_reference * Matrix4::new_scaling(M_PER_MM);
        self.ref_from_robot = self
            .robot_from_ref
            .try_inverse()
            .unwrap_or(Matrix4::new_scaling(MM_PER_M));
        self.cfg.solids = solids.to_vec();
        if let Ok(c) = self.clear.get_mut() {
            c.clear();
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
    /// Grinding samples are not remembered (`plan` checks most of them once, at the end).
    pub fn check(&self, robot: &Robot, q: &[f64], allow: Allow) -> Option<Hit> {
        self.check_carried(robot, q, allow, None)
    }

    /// `check`, with the bounds carried from earlier samples when there are any.
    fn check_carried(
        &self,
        robot: &Robot,
        q: &[f64],
        allow: Allow,
        carry: Option<&mut Vec<Carry>>,
    ) -> Option<Hit> {
        if allow == Allow::Grind {
            return self.search(robot, q, allow, carry);
        }
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
        let hit = self.search(robot, q, allow, carry);
        if hit.is_none() {
            known.insert(key);
        }
        hit
    }

    /// `check` without the look-up; `carry` holds each body's bound from earlier samples.
    fn search(
        &self,
        robot: &Robot,
        q: &[f64],
        allow: Allow,
        mut carry: Option<&mut Vec<Carry>>,
    ) -> Option<Hit> {
        let m = self.cfg.margin_mm;
        // the ball's first query is the shank's (both start at the ball centre)
        let mut seen = None;
        for (k, c) in self.bodies(robot, q).into_iter().enumerate() {
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
            let limit = match carry.as_deref_mut() {
                Some(all) if c.body != Body::Ball => {
                    if all.len() <= k {
                        all.resize(k + 1, Carry::default());
                    }
                    self.search_limit(&mut all[k], &c, self.reach(&c, need))
                }
                _ => Some(f64::INFINITY),
            };
            let found = limit.and_then(|limit| {
                let inside = grind_ball.then_some(&mut inside);
                self.part_clearance(&c, need, limit, inside, &mut seen)
            });
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
    /// A normal whose cosine with `n0` exceeds the limit's by `COS_SLACK` lies within the limit
    /// and its angle is not computed (the same answer, without an `atan2` per point).
    fn second_face_among(&self, inside: &[(usize, f64)], n0: &Vector3<f64>) -> Option<Hit> {
        let within = self.cfg.second_face_deg.to_radians().cos() + COS_SLACK;
        let n0_norm = n0.norm();
        inside.iter().find_map(|&(i, dist)| {
            let p = &self.points[i];
            if p.normal.dot(n0) >= within * p.normal.norm() * n0_norm {
                return None;
            }
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
        self.part_clearance(&c, need, f64::INFINITY, None, &mut None)
            .map_or(f64::INFINITY, |(d, _)| d)
    }

    /// Smallest clearance of `c` from the part and the point it is measured at, over the
    /// reference points within `need` (plus one spacing) of the capsule; None when none is
    /// near. Within the patch of a point (its foot on the tangent plane within the spacing)
    /// the distance is to the plane (signed: negative inside), else to the point. Marches
    /// along the axis: where the nearest point is farther than the reach, the stretch that
    /// distance clears is skipped (sphere tracing); near the part, one radius query per step.
    /// `seen` holds the last nearest query (kept across the bodies of one sample); the march
    /// stops past `limit` mm along the axis (beyond it the axis is known to be clear).
    fn part_clearance(
        &self,
        c: &Capsule,
        need: f64,
        limit: f64,
        mut inside: Option<&mut Inside>,
        seen: &mut Seen,
    ) -> Option<(f64, usize)> {
        let reach = self.reach(c, need);
        if c.body != Body::Ball && self.outside_box(c, reach) {
            return None;
        }
        let d = c.b - c.a;
        let len = d.norm();
        let dir = if len > 0.0 { d / len } else { Vector3::zeros() };
        let step = c.radius.max(1.0);
        let mut best: Option<(f64, usize)> = None;
        let mut t = 0.0;
        while t <= len && t <= limit {
            let centre = c.a + dir * t;
            let nearest = match *seen {
                Some((at, found)) if at == centre => found,
                _ => {
                    let found = self.index.nearest(&centre)?;
                    *seen = Some((centre, found));
                    found
                }
            };
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
                let dist = if lateral > self.patch {
                    v.norm()
                } else if dn < 0.0
                    && best.is_none_or(|(b, _)| dn - c.radius < b)
                    && !self.behind_nearest(&(p.position + v), seen)
                {
                    // behind this point's plane but in front of the nearest face: the
                    // point is a far face of a wall thinner than the reach, the distance
                    // to its patch is unsigned
                    -dn
                } else {
                    dn
                };
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

    /// Whether `at` (reference frame, mm) lies behind the face of its nearest reference point
    /// (inside the part). A point's tangent plane says inside or outside only where its face
    /// is the nearest: beyond a wall thinner than the reach, the far face's plane has the
    /// outside behind it. `seen` caches the last query.
    fn behind_nearest(&self, at: &Point3<f64>, seen: &mut Seen) -> bool {
        let nearest = match *seen {
            Some((q, found)) if q == *at => found,
            _ => match self.index.nearest(at) {
                Some(found) => {
                    *seen = Some((*at, found));
                    found
                }
                None => return false,
            },
        };
        let p = &self.points[nearest.index];
        (at - p.position).dot(&p.normal) < 0.0
    }

    /// How far from `c`'s axis `part_clearance` looks for reference points when it needs
    /// `need` mm of clearance: a point farther than this from every point of the axis is never
    /// visited, mm.
    fn reach(&self, c: &Capsule, need: f64) -> f64 {
        c.radius + need.max(0.0) + self.patch
    }

    /// The box around `c`'s axis, widened by `reach`, misses the box of the reference points.
    fn outside_box(&self, c: &Capsule, reach: f64) -> bool {
        let (slo, shi) = (c.a.inf(&c.b), c.a.sup(&c.b));
        (0..3).any(|k| slo[k] - reach > self.hi[k] || shi[k] + reach < self.lo[k])
    }

    /// The first solid `c` comes within `margin` of (answers exactly as the search alone).
    fn solid_hit(&self, c: &Capsule, margin: f64) -> Option<Hit> {
        let to_robot_mm = |p: &Point3<f64>| mm(self.robot_from_ref.transform_point(p));
        let (a, b) = (to_robot_mm(&c.a), to_robot_mm(&c.b));
        self.cfg.solids.iter().find_map(|s| {
            let lo = Point3::from(mm(Vector3::from(s.min)));
            let hi = Point3::from(mm(Vector3::from(s.max)));
            // every point of the segment is in its bounding box, so the gap between the two
            // boxes bounds the distance from below: beyond the margin there, the search
            // (whose value is a distance to points of the segment) cannot find a hit either
            let (slo, shi) = (a.inf(&b), a.sup(&b));
            let gap = Vector3::from_fn(|k, _| (lo[k] - shi[k]).max(0.0).max(slo[k] - hi[k]));
            if gap.norm() - c.radius >= margin + ROUNDING_MM {
                return None;
            }
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

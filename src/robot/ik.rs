//! Inverse kinematics: closed form for the DOFBOT structure (base yaw about a vertical axis,
//! three parallel horizontal pitch axes in the vertical plane through the base axis, wrist roll
//! about the tool axis), k's Jacobian solver for any other chain. Every answer is checked by
//! forward kinematics through k. Method: docs/ALGORITHMS.md, section "Robot".
use std::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::model::Robot;
use super::planar::Planar;

/// Settings of the inverse kinematics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IkConfig {
    /// Largest accepted angle between a requested tool axis and the arm plane, degrees (45).
    /// A 5-DOF arm cannot tilt its tool sideways; smaller misses are projected and reported.
    pub max_axis_miss_deg: f64,
    /// Largest tool-tip distance (m) and axis angle (rad) between FK(IK) and the target
    /// before an answer is rejected (1e-9).
    pub verify_tolerance: f64,
    /// When the requested axis is out of reach or joint limits, tilt the tool within the arm
    /// plane (up to `max_axis_miss_deg` in all) to the nearest reachable axis (true): a
    /// ball-nosed burr grinds the same spot at any axis within that cone.
    pub axis_search: bool,
    /// Keep every joint this far inside its limits, radians (0.0). The planner sets a small
    /// margin so that interpolation between IK solutions cannot overshoot a limit.
    pub limit_margin: f64,
}

impl Default for IkConfig {
    fn default() -> Self {
        IkConfig {
            max_axis_miss_deg: 45.0,
            verify_tolerance: 1e-9,
            axis_search: true,
            limit_margin: 0.0,
        }
    }
}

/// A requested tool pose in the robot base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkTarget {
    /// Tool tip, metres.
    pub position: Vector3<f64>,
    /// Tool axis (shank to tip); need not be unit length.
    pub axis: Vector3<f64>,
    /// Wrist roll angle (last joint), radians; `None` keeps the previous one (a burr is
    /// symmetric about its axis).
    pub roll: Option<f64>,
}

/// An IK answer.
#[derive(Debug, Clone, PartialEq)]
pub struct IkSolution {
    /// Joint angles, radians.
    pub q: Vec<f64>,
    /// Angle between the requested tool axis and the achieved one, radians (the projection
    /// onto the arm plane).
    pub axis_miss: f64,
    /// Tool-tip distance between FK(q) and the target, metres (the FK check).
    pub position_error: f64,
    /// Angle between FK(q)'s tool axis and the projected target axis, radians (the FK check).
    pub axis_error: f64,
}

/// Why a pose cannot be reached.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unreachable {
    /// The wrist centre is too far from (or too near to) the shoulder.
    #[error("out of reach: wrist centre {distance:.4} m from the shoulder, reachable {min:.4}..{max:.4} m")]
    OutOfReach {
        /// Shoulder to wrist-centre distance the pose needs, metres.
        distance: f64,
        /// Nearest reachable distance, metres.
        min: f64,
        /// Farthest reachable distance, metres.
        max: f64,
    },
    /// The requested tool axis leaves the arm plane by more than accepted.
    #[error("tool axis off the arm plane by {degrees:.2} deg (accepted up to {max:.2} deg)")]
    AxisOffPlane {
        /// The miss, degrees.
        degrees: f64,
        /// The accepted miss, degrees.
        max: f64,
    },
    /// Every branch that reaches the pose puts a joint outside its limits.
    #[error("joint limit: {joint} would be {value:.4} rad, limits {lower:.4}..{upper:.4}")]
    JointLimit {
        /// The joint.
        joint: String,
        /// Its angle in the branch nearest the previous pose, radians.
        value: f64,
        /// Lower limit, radians.
        lower: f64,
        /// Upper limit, radians.
        upper: f64,
    },
    /// The numerical solver (chains without a closed form) did not converge.
    #[error("numerical IK did not converge: {0}")]
    NoConvergence(String),
    /// The FK check disagrees with the target (a bug or a bad model).
    #[error("FK check failed: tip {position:.3e} m, axis {axis:.3e} rad from the target")]
    FkMismatch {
        /// Tip distance, metres.
        position: f64,
        /// Axis angle, radians.
        axis: f64,
    },
}

impl Planar {
    /// Every closed-form branch for `target` (joint 5 left at 0): joint angles and, for
    /// branches that miss, why. Also returns the axis miss in radians.
    fn branches(&self, target: &IkTarget) -> (Vec<Result<[f64; 4], Unreachable>>, f64) {
        let t = target.position;
        let a = target.axis.normalize();
        let d = t.xy() - self.base;
        let rho = d.norm();
        let dir = if rho > 1e-9 {
            d / rho
        } else if a.xy().norm() > 1e-9 {
            a.xy().normalize()
        } else {
            let phi = self.phi0;
            Vector2::new(phi.cos(), phi.sin())
        };
        let mut out = Vec::new();
        let mut miss = 0.0;
        for s in [1.0, -1.0] {
            let u = dir * s;
            let n = Vector2::new(u.y, -u.x);
            let in_plane = Vector2::new(a.xy().dot(&u), a.z);
            miss = a.xy().dot(&n).abs().atan2(in_plane.norm());
            let q1 = self.s1 * (u.y.atan2(u.x) - self.phi0);
            let psi4 = in_plane.y.atan2(in_plane.x) - self.alpha0;
            let w = Vector2::new(d.dot(&u), t.z) - rotate(self.tip4, psi4);
            let dv = w - self.p2;
            let dist = dv.norm();
            let (l2, l3) = (self.l23, self.l34);
            let c = (dist * dist - l2 * l2 - l3 * l3) / (2.0 * l2 * l3);
            if !(-1.0 - 1e-12..=1.0 + 1e-12).contains(&c) {
                let (min, max) = ((l2 - l3).abs(), l2 + l3);
                out.push(Err(Unreachable::OutOfReach {
                    distance: dist,
                    min,
                    max,
                }));
                continue;
            }
            let g = c.clamp(-1.0, 1.0).acos();
            let gammas: &[f64] = if g == 0.0 || g == PI { &[g] } else { &[g, -g] };
            for &gamma in gammas {
                let theta = dv.y.atan2(dv.x) - (l3 * gamma.sin()).atan2(l2 + l3 * gamma.cos());
                let psi2 = theta - self.beta23;
                let psi3 = theta + gamma - self.beta34;
                let [s2, s3, s4] = self.sigma;
                out.push(Ok([q1, s2 * psi2, s3 * (psi3 - psi2), s4 * (psi4 - psi3)]));
            }
        }
        (out, miss)
    }
}

fn rotate(v: Vector2<f64>, angle: f64) -> Vector2<f64> {
    let (s, c) = angle.sin_cos();
    Vector2::new(c * v.x - s * v.y, s * v.x + c * v.y)
}

/// The representative of `q` modulo 2 pi inside `[lower, upper]` (tolerance 1e-10, clamped)
/// nearest `near`, if any.
fn fit_limits(q: f64, near: f64, lower: f64, upper: f64) -> Option<f64> {
    let base = q - TAU * ((q - near) / TAU).round();
    [base, base - TAU, base + TAU]
        .into_iter()
        .filter(|v| *v >= lower - 1e-10 && *v <= upper + 1e-10)
        .min_by(|x, y| (x - near).abs().total_cmp(&(y - near).abs()))
        .map(|v| v.clamp(lower, upper))
}

impl Robot {
    /// Joint angles that put the tool tip at `target.position` with the tool axis as near
    /// `target.axis` as the arm allows, on the branch nearest `previous` within the joint
    /// limits; checked by FK through k.
    pub fn ik(
        &self,
        target: &IkTarget,
        previous: &[f64],
        config: &IkConfig,
    ) -> Result<IkSolution, Unreachable> {
        assert_eq!(
            previous.len(),
            self.dof(),
            "previous pose has the wrong number of joints"
        );
        let first = match &self.planar {
            Some(planar) => self
                .ik_closed(planar, target, previous, config)
                .and_then(|q| self.check(target, q, config)),
            None => self
                .ik_numeric(target, previous)
                .and_then(|q| self.check(target, q, config)),
        };
        match (&first, &self.planar) {
            (
                Err(Unreachable::OutOfReach { .. } | Unreachable::JointLimit { .. }),
                Some(planar),
            ) if config.axis_search => self
                .ik_axis_search(planar, target, previous, config)
                .unwrap_or(first),
            _ => first,
        }
    }

    /// When the requested axis cannot be reached, tilts the tool within the arm plane by
    /// growing angles (1 degree steps, then bisection to 0.01 degree) while the total miss
    /// stays within `max_axis_miss_deg`; the smallest feasible tilt wins.
    fn ik_axis_search(
        &self,
        planar: &Planar,
        target: &IkTarget,
        previous: &[f64],
        config: &IkConfig,
    ) -> Option<Result<IkSolution, Unreachable>> {
        let a = target.axis.normalize();
        let d = target.position.xy() - planar.base;
        let u2 = if d.norm() > 1e-9 {
            d.normalize()
        } else {
            return None;
        };
        let u = Vector3::new(u2.x, u2.y, 0.0);
        let n = Vector3::new(u2.y, -u2.x, 0.0);
        let off = a.dot(&n).abs().asin();
        let alpha = a.z.atan2(a.dot(&u));
        let max = config.max_axis_miss_deg.to_radians();
        let try_tilt = |delta: f64| {
            let tilted = IkTarget {
                axis: u * (alpha + delta).cos() + Vector3::z() * (alpha + delta).sin(),
                ..*target
            };
            self.ik_closed(planar, &tilted, previous, config)
                .and_then(|q| self.check(&tilted, q, config))
                .ok()
        };
        let total_miss = |delta: f64| (off.cos() * delta.cos()).clamp(-1.0, 1.0).acos();
        let step = 1f64.to_radians();
        let mut k = 1.0;
        while total_miss(k * step) <= max {
            for sign in [1.0, -1.0] {
                if try_tilt(sign * k * step).is_some() {
                    // bisect between the last infeasible and the first feasible tilt
                    let (mut bad, mut good) = ((k - 1.0) * step, k * step);
                    for _ in 0..7 {
                        let mid = 0.5 * (bad + good);
                        if try_tilt(sign * mid).is_some() {
                            good = mid;
                        } else {
                            bad = mid;
                        }
                    }
                    let mut sol = try_tilt(sign * good)?;
                    sol.axis_miss = angle_between(&a, &self.fk(&sol.q).axis);
                    return Some(Ok(sol));
                }
            }
            k += 1.0;
        }
        None
    }

    fn ik_closed(
        &self,
        planar: &Planar,
        target: &IkTarget,
        previous: &[f64],
        config: &IkConfig,
    ) -> Result<Vec<f64>, Unreachable> {
        let (branches, miss) = planar.branches(target);
        let max = config.max_axis_miss_deg;
        if miss.to_degrees() > max {
            return Err(Unreachable::AxisOffPlane {
                degrees: miss.to_degrees(),
                max,
            });
        }
        let j5 = &self.joints[4];
        let roll = target.roll.unwrap_or(previous[4]);
        let mut best: Option<(f64, Vec<f64>)> = None;
        let mut limit_fail: Option<(f64, Unreachable)> = None;
        let mut reach_fail = None;
        for branch in branches {
            let raw = match branch {
                Ok(raw) => raw,
                Err(e) => {
                    reach_fail = Some(e);
                    continue;
                }
            };
            let mut q = Vec::with_capacity(5);
            let mut failed = None;
            for (i, v) in raw.iter().chain(std::iter::once(&roll)).enumerate() {
                let j = if i < 4 { &self.joints[i] } else { j5 };
                let wrapped = if i < 4 {
                    v - TAU * ((v - previous[i]) / TAU).round()
                } else {
                    *v
                };
                let m = config.limit_margin;
                match fit_limits(wrapped, previous[i], j.lower + m, j.upper - m) {
                    Some(fit) => q.push(fit),
                    None => {
                        q.push(wrapped);
                        failed.get_or_insert(i);
                    }
                }
            }
            let dist: f64 = q.iter().zip(previous).map(|(a, b)| (a - b) * (a - b)).sum();
            match failed {
                None if best.as_ref().is_none_or(|(d, _)| dist < *d) => best = Some((dist, q)),
                None => {}
                Some(i) if limit_fail.as_ref().is_none_or(|(d, _)| dist < *d) => {
                    let j = &self.joints[i];
                    let e = Unreachable::JointLimit {
                        joint: j.name.clone(),
                        value: q[i],
                        lower: j.lower,
                        upper: j.upper,
                    };
                    limit_fail = Some((dist, e));
                }
                Some(_) => {}
            }
        }
        match (best, limit_fail, reach_fail) {
            (Some((_, q)), _, _) => Ok(q),
            (None, Some((_, e)), _) => Err(e),
            (None, None, Some(e)) => Err(e),
            (None, None, None) => Err(Unreachable::NoConvergence("no branch".into())),
        }
    }

    /// k's Jacobian solver from `previous`: full pose for 6+ joints; for fewer, the position
    /// and the two world rotation components least aligned with the requested axis.
    fn ik_numeric(&self, target: &IkTarget, previous: &[f64]) -> Result<Vec<f64>, Unreachable> {
        use k::InverseKinematicsSolver;
        let dof = self.dof();
        let tool_axis = Vector3::from(self.tool.axis);
        let axis = target.axis.normalize();
        self.with_chain(|chain| {
            chain.set_joint_positions_unchecked(previous);
            let current = chain.end_transform();
            let turn = UnitQuaternion::rotation_between(&(current.rotation * tool_axis), &axis)
                .unwrap_or_else(UnitQuaternion::identity);
            let goal =
                Isometry3::from_parts(Translation3::from(target.position), turn * current.rotation);
            let mut constraints = k::Constraints::default();
            if dof < 6 {
                let free = axis.iamax();
                constraints.rotation_x = free != 0 && dof >= 5;
                constraints.rotation_y = free != 1 && dof >= 5;
                constraints.rotation_z = free != 2 && dof >= 5;
            }
            let solver = k::JacobianIkSolver::new(1e-10, 1e-10, 0.5, 500);
            solver
                .solve_with_constraints(chain, &goal, &constraints)
                .map_err(|e| Unreachable::NoConvergence(e.to_string()))?;
            Ok(chain.joint_positions())
        })
    }

    /// The FK check through k, then the joint-limit and axis-miss checks.
    fn check(
        &self,
        target: &IkTarget,
        q: Vec<f64>,
        config: &IkConfig,
    ) -> Result<IkSolution, Unreachable> {
        let pose = self.fk(&q);
        let a = target.axis.normalize();
        let miss = angle_between(&a, &pose.axis);
        if miss.to_degrees() > config.max_axis_miss_deg {
            return Err(Unreachable::AxisOffPlane {
                degrees: miss.to_degrees(),
                max: config.max_axis_miss_deg,
            });
        }
        if let Some(i) = self.limit_violation(&q, -config.limit_margin) {
            let j = &self.joints[i];
            return Err(Unreachable::JointLimit {
                joint: j.name.clone(),
                value: q[i],
                lower: j.lower,
                upper: j.upper,
            });
        }
        let position_error = (pose.position - target.position).norm();
        let axis_error = match &self.planar {
            Some(p) => {
                // the achieved axis must be the target axis projected onto the arm plane
                let u = Vector2::new(pose.position.x - p.base.x, pose.position.y - p.base.y);
                let n = Vector3::new(u.y, -u.x, 0.0);
                let projected = if n.norm() > 1e-9 {
                    a - n.normalize() * a.dot(&n.normalize())
                } else {
                    a
                };
                angle_between(&projected, &pose.axis)
            }
            None => 0.0,
        };
        if position_error > config.verify_tolerance || axis_error > config.verify_tolerance {
            return Err(Unreachable::FkMismatch {
                position: position_error,
                axis: axis_error,
            });
        }
        Ok(IkSolution {
            q,
            axis_miss: miss,
            position_error,
            axis_error,
        })
    }
}

/// Angle between two vectors, radians, accurate for tiny angles too (atan2 of the cross and
/// dot products; nalgebra's `angle` uses acos, which loses half the digits near 0).
pub fn angle_between(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

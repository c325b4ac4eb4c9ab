//! Joint-space validation of a sampled trajectory before any motion: position limits, servo
//! degree ranges, and velocity / acceleration / jerk limits by finite differences.
use std::fmt;

use serde::{Deserialize, Serialize};

use super::trajectory::JointTrajectory;
use crate::robot::Robot;

/// Settings of the validation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValidationConfig {
    /// Relative tolerance on velocity, acceleration and jerk limits (0.01: finite differences
    /// may exceed a limit by 1 %).
    pub derivative_tolerance: f64,
    /// Absolute tolerance on position limits and servo ranges, radians (1e-9).
    pub position_tolerance: f64,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        ValidationConfig {
            derivative_tolerance: 0.01,
            position_tolerance: 1e-9,
        }
    }
}

/// Largest `derivative_tolerance` (0.1): finite differences of a sampled time-optimal
/// trajectory exceed a limit by about 1 % (the default); over a tenth the check no longer
/// holds the servos to their limits.
pub const MAX_DERIVATIVE_TOLERANCE: f64 = 0.1;
/// Largest `position_tolerance`, rad (1e-3, 0.06 degrees: a fifth of a servo count; the
/// default is 1e-9).
pub const MAX_POSITION_TOLERANCE: f64 = 1e-3;

impl ValidationConfig {
    /// The first setting outside its range, its key in backticks (0..=
    /// [`MAX_DERIVATIVE_TOLERANCE`], 0..=[`MAX_POSITION_TOLERANCE`] rad).
    pub fn check(&self) -> Result<(), String> {
        for (key, v, hi, unit) in [
            (
                "derivative_tolerance",
                self.derivative_tolerance,
                MAX_DERIVATIVE_TOLERANCE,
                "",
            ),
            (
                "position_tolerance",
                self.position_tolerance,
                MAX_POSITION_TOLERANCE,
                " rad",
            ),
        ] {
            if !(v.is_finite() && (0.0..=hi).contains(&v)) {
                return Err(format!("`{key}` = {v:?}{unit} is outside 0..={hi}{unit}"));
            }
        }
        Ok(())
    }
}

/// Which limit a sample breaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LimitKind {
    /// Joint position below the lower limit.
    BelowLower,
    /// Joint position above the upper limit.
    AboveUpper,
    /// Servo degrees outside the servo's degree range (and so its raw range).
    ServoRange,
    /// Finite-difference velocity.
    Velocity,
    /// Finite-difference acceleration.
    Acceleration,
    /// Finite-difference jerk.
    Jerk,
}

/// One offending sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Violation {
    /// Sample index (for differences: the first sample of the stencil).
    pub sample: usize,
    /// Time of that sample, seconds.
    pub time: f64,
    /// URDF joint name.
    pub joint: String,
    /// The limit broken.
    pub kind: LimitKind,
    /// The value found (rad, rad/s, rad/s^2, rad/s^3, or servo degrees).
    pub value: f64,
    /// The limit (same unit).
    pub limit: f64,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "t={:.3} s (sample {}): {} {:?} {:.6} beyond {:.6}",
            self.time, self.sample, self.joint, self.kind, self.value, self.limit
        )
    }
}

/// Every sample of `traj` against the robot's limits; empty when all is well.
pub fn validate(
    traj: &JointTrajectory,
    robot: &Robot,
    config: &ValidationConfig,
) -> Vec<Violation> {
    let mut out = Vec::new();
    let h = traj.period;
    let n = traj.len();
    let tol = 1.0 + config.derivative_tolerance;
    for (j, spec) in robot.joints.iter().enumerate() {
        let q: Vec<f64> = (0..n).map(|i| traj.sample(i)[j]).collect();
        let servo = robot.servos.servos.iter().find(|s| s.id == spec.servo_id);
        let mut push = |sample: usize, kind: LimitKind, value: f64, limit: f64| {
            out.push(Violation {
                sample,
                time: sample as f64 * h,
                joint: spec.name.clone(),
                kind,
                value,
                limit,
            });
        };
        for (i, &v) in q.iter().enumerate() {
            if v < spec.lower - config.position_tolerance {
                push(i, LimitKind::BelowLower, v, spec.lower);
            } else if v > spec.upper + config.position_tolerance {
                push(i, LimitKind::AboveUpper, v, spec.upper);
            }
            if let Some(s) = servo {
                let deg = s.servo_deg(v);
                let slack = config.position_tolerance.to_degrees();
                if deg < s.degree_range[0] - slack || deg > s.degree_range[1] + slack {
                    let limit = if deg < s.degree_range[0] {
                        s.degree_range[0]
                    } else {
                        s.degree_range[1]
                    };
                    push(i, LimitKind::ServoRange, deg, limit);
                }
            }
        }
        let checks = [
            (LimitKind::Velocity, spec.velocity, 1),
            (LimitKind::Acceleration, spec.acceleration, 2),
            (LimitKind::Jerk, spec.jerk, 3),
        ];
        for (kind, limit, order) in checks {
            for i in 0..n.saturating_sub(order) {
                let d = difference(&q[i..=i + order]) / h.powi(order as i32);
                if d.abs() > limit * tol {
                    push(i, kind, d, limit);
                }
            }
        }
    }
    out.sort_by_key(|v| v.sample);
    out
}

/// The forward difference of order `w.len() - 1` (binomial stencil).
fn difference(w: &[f64]) -> f64 {
    match w.len() {
        2 => w[1] - w[0],
        3 => w[2] - 2.0 * w[1] + w[0],
        4 => w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0],
        _ => unreachable!("orders 1..3 only"),
    }
}

//! `polishbot calibrate compliance (--port DEV | --i2c DEV | --sim)`: the compliance
//! calibration (crate::calibrate::compliance) with the jog terminal's operator, or with
//! `--sim` the simulated one, written into servos.toml's `[compliance]`.
//!
//! The touches on the simulated cell: [`SimTouch`] is the operator who
//! jogs the simulated arm until its true, loaded tool tip (the simulator's own kinematics,
//! backlash and sag, `[sim.grinding]`) sits on the touched point, and then records the touch
//! through the bus like any other touch source. The calibration itself sees only the
//! read-back joint angles.
use nalgebra::{Matrix4, Point3, Vector3, Vector4};

use super::common::say;
use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::calibrate::compliance::{self, ComplianceFit, LoadedPose, FITTED_JOINTS};
use crate::calibrate::jog::{record, Cell, JogTerminal, Touch, TouchSource};
use crate::calibrate::CalibError;
use crate::sim::grind::{fk, slack};
use crate::sim::model::{deg_at_raw, raw_at_deg, round_raw};
use crate::sim::GrindConfig;

/// Iterations of the simulated operator's jogging (converges in 3-5 where the tilt is
/// reachable; the damped steps towards a relaxed tilt take a few tens more).
const JOG_ITERATIONS: usize = 100;
/// Weight of the jog's tilt miss against its tip miss, m per rad: 0.01 (a degree of tilt off
/// counts as 0.17 mm of tip miss). Where the tilt is reachable both misses go to zero and the
/// weight does not matter; where the loaded arm cannot put its tip on the point at the listed
/// tilt (the pose's pitch sum: the loaded tool leans by the pitch joints' deflections, up to
/// 4 degrees with 10 mm of sag, which moves the wrist 13 mm from the rigid pose's, beyond a
/// stretched elbow's reach) the tip stays on the point within a few hundredths of a
/// millimetre and the tilt gives.
const JOG_TILT_WEIGHT_M_PER_RAD: f64 = 0.01;
/// Start damping of the jog's Levenberg-Marquardt steps (relative to the normal matrix's
/// diagonal): 1e-3, a Newton step where the jog converges.
const JOG_START_DAMPING: f64 = 1e-3;
/// Factor the damping falls by after a step that lowers the miss and rises by after one
/// that does not.
const JOG_DAMPING_FACTOR: f64 = 10.0;
/// Smallest damping (1e-12: the step is Newton's to double precision).
const JOG_MIN_DAMPING: f64 = 1e-12;
/// Damping over which the jog stops (1e6: the steps are then under a millionth of the
/// gradient's).
const JOG_MAX_DAMPING: f64 = 1e6;
/// Largest joint step of one jogging iteration, rad (keeps Newton on its elbow branch).
const JOG_MAX_STEP: f64 = 0.05;
/// Step of the numeric derivative of the jogging, rad.
const JOG_STEP: f64 = 1e-7;
/// Whole counts either side of the jogged pose the operator tries on each of the four
/// fitted joints before recording (2: 5^4 = 625 poses, the one whose loaded tip sits nearest
/// the point wins, as an operator jogs count by count until the tip touches; the misses
/// drop from 0.1-0.4 mm at the nearest counts to a few hundredths).
const SNAP_COUNTS: i32 = 2;

/// The simulated operator of `calibrate compliance`: for each pose, in order, the servo
/// angles that put the simulated arm's loaded tip on the pose's point (the rigid arm's tip at
/// the point's first pose) with the tool tilt of the pose. Where a joint's load torque is
/// near zero at the point its gear jumps across the band as the tip passes the point, and the
/// operator stops as near as the jump allows (the fit sets such touches aside).
pub struct SimTouch {
    arm: slack::Arm,
    poses: Vec<LoadedPose>,
    next: usize,
    points: Vec<Point3<f64>>,
}

impl SimTouch {
    /// The operator of the simulated arm of `grinding` touching `poses`.
    pub fn new(grinding: &GrindConfig, poses: &[LoadedPose]) -> SimTouch {
        let arm = slack::Arm::new(grinding);
        let tip = arm.tip_m();
        let n = poses.iter().map(|p| p.point + 1).max().unwrap_or(0);
        let points = (0..n)
            .map(|i| {
                poses
                    .iter()
                    .find(|p| p.point == i)
                    .map_or(Point3::origin(), |p| fk::tool(&p.q, &tip).0)
            })
            .collect();
        SimTouch {
            arm,
            poses: poses.to_vec(),
            next: 0,
            points,
        }
    }

    /// The simulator's joint angles (rad) that hold the loaded tip on `point` with the pitch
    /// sum (the tool's tilt in the arm plane) and roll of `q`, or, where the loaded arm cannot
    /// reach the point at that tilt, at the tilt nearest it that does (a damped least-squares
    /// jog that weighs the tilt by [`JOG_TILT_WEIGHT_M_PER_RAD`]: an operator tilts the tool a
    /// little rather than record a touch beside the mark).
    fn jog(&self, q: &[f64; 5], force: Vector3<f64>, point: &Point3<f64>) -> [f64; 5] {
        let tilt = q[1] + q[2] + q[3];
        let miss = |x: &[f64; 5]| {
            let tip = self.arm.held(*x, force).0;
            let d = tip - point;
            Vector4::new(
                d.x,
                d.y,
                d.z,
                JOG_TILT_WEIGHT_M_PER_RAD * (x[1] + x[2] + x[3] - tilt),
            )
        };
        let mut x = *q;
        let mut r = miss(&x);
        let mut damping = JOG_START_DAMPING;
        for _ in 0..JOG_ITERATIONS {
            let mut jac = Matrix4::zeros();
            for k in 0..4 {
                let mut y = x;
                y[k] += JOG_STEP;
                jac.set_column(k, &((miss(&y) - r) / JOG_STEP));
            }
            let jtj = jac.transpose() * jac;
            let lhs = jtj + Matrix4::from_diagonal(&jtj.diagonal()) * damping;
            let Some(step) = lhs.lu().solve(&(-(jac.transpose() * r))) else {
                break;
            };
            let scale = (JOG_MAX_STEP / step.norm()).min(1.0);
            let mut y = x;
            for k in 0..4 {
                y[k] += step[k] * scale;
            }
            let ry = miss(&y);
            if ry.norm() < r.norm() {
                (x, r) = (y, ry);
                damping = (damping / JOG_DAMPING_FACTOR).max(JOG_MIN_DAMPING);
                if step.norm() < 1e-12 {
                    break;
                }
            } else if damping > JOG_MAX_DAMPING {
                break;
            } else {
                damping *= JOG_DAMPING_FACTOR;
            }
        }
        x
    }

    /// The whole-count servo pose within [`SNAP_COUNTS`] of the jogged pose `x` whose loaded
    /// tip (under `force`) sits nearest `point`, as joint angles (rad).
    fn snap(&self, x: &[f64; 5], force: Vector3<f64>, point: &Point3<f64>) -> [f64; 5] {
        let near: [f64; 5] =
            std::array::from_fn(|k| f64::from(round_raw(raw_at_deg(k, x[k].to_degrees() + 90.0))));
        let at = |raw: &[f64; 5]| -> [f64; 5] {
            std::array::from_fn(|k| fk::joint_of_servo_deg(deg_at_raw(k, raw[k])))
        };
        let side = 2 * SNAP_COUNTS + 1;
        let mut best = (f64::INFINITY, at(&near));
        for code in 0..side.pow(4) {
            let mut raw = near;
            for (k, r) in raw.iter_mut().enumerate().take(4) {
                *r += f64::from(code / side.pow(k as u32) % side - SNAP_COUNTS);
            }
            let q = at(&raw);
            let miss = (self.arm.held(q, force).0 - point).norm();
            if miss < best.0 {
                best = (miss, q);
            }
        }
        best.1
    }
}

impl<T: Transport> TouchSource<T> for SimTouch {
    fn touch(
        &mut self,
        bus: &mut Bus<T>,
        cell: &Cell,
        label: &str,
    ) -> Result<Option<Touch>, CalibError> {
        let Some(p) = self.poses.get(self.next).cloned() else {
            return Ok(None);
        };
        self.next += 1;
        let force = Vector3::from(p.force_n);
        let point = self.points[p.point];
        let x = self.snap(&self.jog(&p.q, force, &point), force, &point);
        // the simulator's joint angle -> servo degrees -> the planner's joint angle
        let mut q = [0.0; JOINT_COUNT];
        for (k, spec) in cell.robot.joints.iter().enumerate().take(JOINT_COUNT) {
            let deg = x[k].to_degrees() + 90.0;
            q[k] = cell
                .robot
                .servos
                .servos
                .iter()
                .find(|s| s.id == spec.servo_id)
                .map_or(x[k], |s| s.joint_from_deg(deg));
        }
        bus.move_joints(&q, cell.gripper_deg, None)?;
        record(bus, cell, label).map(Some)
    }
}

/// Runs `calibrate compliance`: the built-in touch plan with the jog terminal (or with the
/// simulated operator of `sim`, the simulated arm's mechanics), the fit from `servos_in`'s
/// `[compliance]` (or the defaults), and `out` written as `servos_in` with the fitted table.
pub fn run<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    sim: Option<&GrindConfig>,
    servos_in: &std::path::Path,
    out: &std::path::Path,
) -> Result<(), CalibError> {
    let poses = compliance::default_poses(cell.robot);
    let start = cell
        .robot
        .servos
        .compliance
        .clone()
        .unwrap_or_else(compliance::start_model);
    let mut source: Box<dyn TouchSource<T>> = match sim {
        Some(g) => Box::new(SimTouch::new(g, &poses)),
        None => {
            say(&format!(
                "calibrate compliance: {} touches on {} points. For each, jog the tool tip onto \
                 the point (the first touch of a point fixes it: a hard mark the tip can rest \
                 on) while a spring scale pulls the tip with the listed load (N, robot frame), \
                 then record the touch",
                poses.len(),
                poses.iter().map(|p| p.point + 1).max().unwrap_or(0)
            ));
            Box::new(JogTerminal::new(
                std::io::stdin(),
                std::io::stdout(),
                cell.cfg.jog_step_deg,
            ))
        }
    };
    let fit = compliance::compliance(bus, cell, &poses, &start, source.as_mut())?;
    compliance::write_compliance(servos_in, out, &fit.compliance)?;
    for line in describe(&fit) {
        say(&format!("calibrate compliance: {line}"));
    }
    say(&format!("calibrate compliance: wrote {}", out.display()));
    Ok(())
}

/// The fit's report: per joint stiffness and backlash with their standard deviations, the
/// masses, the residuals.
pub fn describe(fit: &ComplianceFit) -> Vec<String> {
    let c = &fit.compliance;
    let mut out: Vec<String> = (0..FITTED_JOINTS)
        .map(|k| {
            format!(
                "joint {}: stiffness {:.1} +- {:.1} N m/rad, backlash {:.3} +- {:.3} deg",
                k + 1,
                c.stiffness_nm_rad[k],
                fit.stiffness_sd[k],
                c.backlash_deg[k],
                fit.backlash_sd[k]
            )
        })
        .collect();
    out.push(format!(
        "lumped masses [kg] {:.3?} (elbow, wrist pitch, wrist roll, tool tip)",
        c.masses_kg
    ));
    out.push(format!(
        "{} touches, {} set aside; residual per touch [mm]: {}; RMS {:.3} mm",
        fit.residuals_mm.len(),
        fit.set_aside,
        crate::calibrate::pivot::list_mm(&fit.residuals_mm),
        fit.rms_mm
    ));
    out
}

//! `calibrate compliance`'s touches on the simulated cell: [`SimTouch`] is the operator who
//! jogs the simulated arm until its true, loaded tool tip (the simulator's own kinematics,
//! backlash and sag, `[sim.grinding]`) sits on the touched point, and then records the touch
//! through the bus like any other touch source. The calibration itself sees only the
//! read-back joint angles.
use nalgebra::{Matrix4, Point3, Vector3, Vector4};

use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::calibrate::compliance::LoadedPose;
use crate::calibrate::jog::{record, Cell, Touch, TouchSource};
use crate::calibrate::CalibError;
use crate::sim::grind::{fk, slack};
use crate::sim::GrindConfig;

/// Newton iterations of the simulated operator's jogging (converges in 3-5).
const JOG_ITERATIONS: usize = 30;
/// Largest joint step of one jogging iteration, rad (keeps Newton on its elbow branch).
const JOG_MAX_STEP: f64 = 0.05;
/// Step of the numeric derivative of the jogging, rad.
const JOG_STEP: f64 = 1e-7;

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
    /// sum (the tool's tilt in the arm plane) and roll of `q`.
    fn jog(&self, q: &[f64; 5], force: Vector3<f64>, point: &Point3<f64>) -> [f64; 5] {
        let tilt = q[1] + q[2] + q[3];
        let miss = |x: &[f64; 5]| {
            let tip = self.arm.held(*x, force).0;
            let d = tip - point;
            Vector4::new(d.x, d.y, d.z, x[1] + x[2] + x[3] - tilt)
        };
        let mut x = *q;
        for _ in 0..JOG_ITERATIONS {
            let r = miss(&x);
            let mut jac = Matrix4::zeros();
            for k in 0..4 {
                let mut y = x;
                y[k] += JOG_STEP;
                jac.set_column(k, &((miss(&y) - r) / JOG_STEP));
            }
            let Some(step) = jac.lu().solve(&(-r)) else {
                break;
            };
            let scale = (JOG_MAX_STEP / step.norm()).min(1.0);
            for k in 0..4 {
                x[k] += step[k] * scale;
            }
            if step.norm() < 1e-12 {
                break;
            }
        }
        x
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
        let x = self.jog(&p.q, force, &point);
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

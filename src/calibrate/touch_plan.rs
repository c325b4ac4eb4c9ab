//! The touches of the compliance calibration (issue 50, `compliance`): fixed points spread
//! over the working volume, each touched from several tool tilts under loads of both signs
//! (up, down and along the arm both ways, and two directions between them, each with a push
//! across the arm one way or the other, of two sizes), so that every observed joint's load
//! torque takes both signs (its backlash) and two sizes of one sign (its stiffness), and the
//! pitch joints' signs differ at some touches (their bands apart).
use nalgebra::Vector3;

use crate::bus::JOINT_COUNT;
use crate::robot::{IkConfig, IkTarget, Robot};

/// Load of a touch, N: 4, enough to turn the shoulder's and the wrist's gravity torques
/// (0.2-0.6 N m at the DOFBOT's reach) round so that every pitch joint crosses its band, and
/// under half the 15 kg.cm servos' rating at 0.3 m.
pub const TOUCH_LOAD_N: f64 = 4.0;
/// Tool tilts (rad, in the arm plane, from the base pose's) each point is touched from.
const TILTS_DEG: [f64; 5] = [-12.0, -6.0, 0.0, 6.0, 12.0];
/// Directions of a touch's load in the arm plane (degrees from the outward radial towards
/// up): out, up, in, down (`calibrate verify`'s check touches these only).
pub const IN_PLANE_DEG: [f64; 4] = [0.0, 90.0, 180.0, 270.0];
/// The calibration's load directions: [`IN_PLANE_DEG`] and two between them, 37.5 degrees
/// (out and up) and 167.5 (in and a little up). Under the four the three pitch joints' load
/// torques always share their sign (the arm's weight and the 4 N load turn all three one way),
/// so their gears cross their bands together and the fit can tell the bands apart only by
/// the Jacobian's change over the few reachable tilts: with 1 degree of backlash and 7.5 mm of
/// sag the elbow and wrist pitch came out 0.909 and 1.108 degrees even from the true model
/// with the truly bad touches set aside. Under these two the load turns the shoulder one way
/// and the wrist pitch (37.5) or the elbow and wrist (167.5) the other at most touched poses
/// (found by sweeping the direction in 5 degree steps over the touched poses with the DOFBOT's
/// weight); the same fit then gave 0.996 / 1.005 / 0.999 degrees (a replica of the fit on
/// the simulated touches).
const CALIBRATION_IN_PLANE_DEG: [f64; 6] = [0.0, 37.5, 90.0, 167.5, 180.0, 270.0];
/// The push across the arm plane added to each in-plane load, relative to it: both ways, at
/// two sizes (the base yaw's torque then takes two sizes of each sign, which separates its
/// stiffness from its backlash; 0.35 and 1: torques of 0.1-0.3 and 0.3-0.6 N m at the
/// DOFBOT's reach).
const ACROSS: [f64; 4] = [1.0, -1.0, 0.35, -0.35];
/// How far inside its limits every joint of a touch pose stays, rad (0.15: the loads and the
/// jogging move the joints by a few hundredths).
const POSE_MARGIN: f64 = 0.15;
/// Base poses of the touched points (joint angles, rad): spread over the working volume
/// (left, middle and right; near and far; high and low). Six azimuths: the base yaw's whole
/// count (0.08 deg, 0.3 mm across the arm at its reach) leaves the same miss on every touch
/// of a point under one across push, so its stiffness and backlash average over the points
/// (with three, the documented arm's base yaw came out 8 % and 0.06 deg off).
const POINT_POSES: [[f64; JOINT_COUNT]; 6] = [
    [-0.5, 0.1, 0.8, 0.7, 0.0],
    [0.0, 0.35, 0.7, 0.5, 0.0],
    [0.45, -0.1, 0.9, 0.8, 0.0],
    [-0.25, 0.2, 0.75, 0.6, 0.0],
    [0.2, 0.0, 0.85, 0.75, 0.0],
    [0.7, 0.25, 0.65, 0.55, 0.0],
];
/// One touch to make: which point, the joint angles near it, and the load on the tip.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedPose {
    /// Index of the fixed point touched.
    pub point: usize,
    /// Joint angles (rad) that put the unloaded, rigid arm's tip on the point.
    pub q: [f64; JOINT_COUNT],
    /// Load on the tool tip while touching, N, robot frame.
    pub force_n: [f64; 3],
}

/// The built-in touch plan: each point of [`POINT_POSES`] from each tilt of [`TILTS_DEG`]
/// under loads of [`TOUCH_LOAD_N`] in each direction of [`CALIBRATION_IN_PLANE_DEG`] with each push
/// [`ACROSS`]; tilts the IK cannot reach [`POSE_MARGIN`] inside the limits are left out.
pub fn default_poses(robot: &Robot) -> Vec<LoadedPose> {
    touch_plan(
        robot,
        &POINT_POSES,
        &TILTS_DEG,
        &CALIBRATION_IN_PLANE_DEG,
        &ACROSS,
    )
}

/// Touches of the points the rigid arm's tip reaches at the base poses `points`, each from
/// every tilt of `tilts_deg` (in the arm plane) under loads of [`TOUCH_LOAD_N`] in each
/// direction of `in_plane_deg` (degrees from the outward radial towards up) with each push
/// of `across`; tilts the IK cannot reach
/// [`POSE_MARGIN`] inside the limits are left out.
pub fn touch_plan(
    robot: &Robot,
    points: &[[f64; JOINT_COUNT]],
    tilts_deg: &[f64],
    in_plane_deg: &[f64],
    across: &[f64],
) -> Vec<LoadedPose> {
    let mut out = Vec::new();
    let exact = IkConfig {
        axis_search: false,
        limit_margin: POSE_MARGIN,
        ..IkConfig::default()
    };
    for (point, base) in points.iter().enumerate() {
        let pose = robot.fk(base);
        let radial = Vector3::new(pose.position.x, pose.position.y, 0.0).normalize();
        let side_axis = Vector3::z().cross(&radial);
        for tilt in tilts_deg {
            let rot = nalgebra::Rotation3::new(side_axis * tilt.to_radians());
            let target = IkTarget {
                position: pose.position,
                axis: rot * pose.axis,
                roll: Some(0.0),
            };
            let Ok(sol) = robot.ik(&target, base, &exact) else {
                continue;
            };
            let q: [f64; JOINT_COUNT] = std::array::from_fn(|k| sol.q[k]);
            for a in in_plane_deg.iter().map(|d| d.to_radians()) {
                for side in across {
                    let dir = Vector3::z() * a.sin() + radial * a.cos() + side_axis * *side;
                    let f = dir.normalize() * TOUCH_LOAD_N;
                    out.push(LoadedPose {
                        point,
                        q,
                        force_n: [f.x, f.y, f.z],
                    });
                }
            }
        }
    }
    out
}

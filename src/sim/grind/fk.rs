//! The simulator's own forward kinematics, from the joint table of shared/DOFBOT.md (Yahboom's
//! URDF), independent of `robot/` and of the URDF file the planner loads: where the simulated
//! arm's physical joint angles put the tool ball.
use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

/// The joint table of DOFBOT.md (origin xyz m, origin rpy rad, axis), pi/2 in full precision.
pub const DOFBOT_JOINTS: [([f64; 3], [f64; 3], [f64; 3]); 5] = {
    const H: f64 = std::f64::consts::FRAC_PI_2;
    [
        ([0.0, 0.0, 0.07], [0.0, 0.0, H], [0.0, 0.0, -1.0]),
        ([0.0, 0.0, 0.0405], [-H, 0.0, 0.0], [0.0, 0.0, -1.0]),
        ([0.0, -0.0829, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]),
        ([0.0, -0.0829, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]),
        ([-0.00215, -0.17455, 0.0], [H, 0.0, 0.0], [0.0, 0.0, 1.0]),
    ]
};

/// The joint origins (robot frame, m) and the last link's pose at joint angles `q` (rad):
/// URDF composition, origin then rpy (Rz Ry Rx) then the joint's rotation about its axis.
pub fn chain(q: &[f64; 5]) -> ([Vector3<f64>; 5], Isometry3<f64>) {
    let (j, t) = joints(q);
    (j.map(|(o, _)| o), t)
}

/// Joint angle (rad) of a physical servo angle (degrees), DOFBOT.md's convention: servo 90
/// degrees is joint zero, `servo_deg = q * 180 / pi + 90`.
pub fn joint_of_servo_deg(deg: f64) -> f64 {
    (deg - 90.0).to_radians()
}

/// Ball centre (robot frame, m) and tool axis (unit, shank to tip) at joint angles `q`, for a
/// ball centre `tip_m` in the last link's frame and the tool axis along that frame's z.
pub fn tool(q: &[f64; 5], tip_m: &[f64; 3]) -> (Point3<f64>, Vector3<f64>) {
    let (_, t) = chain(q);
    (
        t * Point3::from(Vector3::from(*tip_m)),
        t.rotation * Vector3::z(),
    )
}

/// A joint's origin and unit axis in the robot frame (m).
pub type JointAxis = (Vector3<f64>, Vector3<f64>);

/// Each joint's origin and unit axis in the robot frame (m) at joint angles `q` (rad), and
/// the last link's pose: what the load torques about the joints are taken with.
pub fn joints(q: &[f64; 5]) -> ([JointAxis; 5], Isometry3<f64>) {
    let mut t = Isometry3::identity();
    let mut out = [(Vector3::zeros(), Vector3::z()); 5];
    for (k, (xyz, rpy, axis)) in DOFBOT_JOINTS.iter().enumerate() {
        t *= Isometry3::from_parts(
            Translation3::new(xyz[0], xyz[1], xyz[2]),
            UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
        );
        let a = Unit::new_normalize(Vector3::from(*axis));
        out[k] = (t.translation.vector, t.rotation * a.into_inner());
        t *= Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&a, q[k]),
        );
    }
    (out, t)
}

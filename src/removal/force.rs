//! The force the arm can hold: at a contact, the static joint torques `tau = J_p^T F` of the
//! contact force stay within a share of each servo's rated torque (servos.toml).
use nalgebra::Vector3;

use crate::robot::Robot;

/// Share of a servo's rated torque the contact force may take (0.5): the rest is left for
/// the arm's own weight, acceleration and the rating's being a stall figure.
pub const DEFAULT_FORCE_SHARE: f64 = 0.5;

/// A joint whose servo cannot hold the contact force.
#[derive(Debug, Clone, PartialEq)]
pub struct Overload {
    /// Index of the joint (URDF order).
    pub joint: usize,
    /// Its name.
    pub name: String,
    /// Static torque needed, N m (absolute value).
    pub torque_nm: f64,
    /// The allowed torque, N m (share x rated; 0 when servos.toml gives no rating).
    pub limit_nm: f64,
}

/// Static joint torques, N m, that hold the force `force` (N, robot frame, acting on the tool
/// tip) at joint angles `q`: `J_p^T F` with J_p the position rows of the tip Jacobian (m/rad).
pub fn joint_torques(robot: &Robot, q: &[f64], force: &Vector3<f64>) -> Vec<f64> {
    let jac = robot.jacobian(q);
    (0..robot.dof())
        .map(|i| jac.fixed_slice::<3, 1>(0, i).dot(force))
        .collect()
}

/// The first joint whose torque exceeds `share` of its servo's rated torque (a servo without
/// a rating counts as overloaded: no force goes unchecked).
pub fn overload(robot: &Robot, q: &[f64], force: &Vector3<f64>, share: f64) -> Option<Overload> {
    let torques = joint_torques(robot, q, force);
    robot
        .joints
        .iter()
        .zip(torques)
        .enumerate()
        .find_map(|(i, (joint, tau))| {
            let rated = robot
                .servos
                .servos
                .iter()
                .find(|s| s.id == joint.servo_id)
                .and_then(|s| s.rated_torque_nm)
                .unwrap_or(0.0);
            let limit = share * rated;
            (tau.abs() > limit).then(|| Overload {
                joint: i,
                name: joint.name.clone(),
                torque_nm: tau.abs(),
                limit_nm: limit,
            })
        })
}

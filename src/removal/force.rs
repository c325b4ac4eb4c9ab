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

/// The torque joint `joint` (URDF order) may give the contact force, N m: `share` of its
/// servo's rated torque (0 when servos.toml gives no rating: no force goes unchecked).
fn allowed(robot: &Robot, joint: usize, share: f64) -> f64 {
    let id = robot.joints[joint].servo_id;
    let rated = robot.servos.servos.iter().find(|s| s.id == id);
    share * rated.and_then(|s| s.rated_torque_nm).unwrap_or(0.0)
}

/// The largest force along the unit direction `direction` (robot frame, acting on the tool
/// tip) that every servo holds within `share` of its rated torque at joint angles `q`, N: the
/// torques are linear in the force, so joint i allows `share x rated / |(J_p^T u)_i|`
/// ([`joint_torques`] of the unit force u); 0 when a servo that feels the direction has no
/// rating (as [`overload`] counts it), infinite when no joint feels it.
pub fn largest_force(robot: &Robot, q: &[f64], direction: &Vector3<f64>, share: f64) -> f64 {
    let per_newton = joint_torques(robot, q, direction);
    per_newton
        .iter()
        .enumerate()
        .filter(|(_, tau)| tau.abs() > 1e-12)
        .map(|(i, tau)| allowed(robot, i, share) / tau.abs())
        .fold(f64::INFINITY, f64::min)
}

/// The first joint whose torque exceeds `share` of its servo's rated torque (a servo without
/// a rating counts as overloaded: no force goes unchecked).
pub fn overload(robot: &Robot, q: &[f64], force: &Vector3<f64>, share: f64) -> Option<Overload> {
    let torques = joint_torques(robot, q, force);
    torques.iter().enumerate().find_map(|(i, tau)| {
        let limit = allowed(robot, i, share);
        (tau.abs() > limit).then(|| Overload {
            joint: i,
            name: robot.joints[i].name.clone(),
            torque_nm: tau.abs(),
            limit_nm: limit,
        })
    })
}

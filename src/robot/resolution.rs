//! The tool-tip error that servo resolution alone causes.
use super::model::Robot;

/// Worst-case tool-tip displacement (metres) at joint angles `q` when every servo is off by
/// half a raw count: the sum over joints of |d tip / d q_i| * (0.5 count / counts per rad).
pub fn resolution_error(robot: &Robot, q: &[f64]) -> f64 {
    let jac = robot.jacobian(q);
    robot
        .joints
        .iter()
        .enumerate()
        .map(|(i, joint)| {
            let counts_per_rad = robot
                .servos
                .servos
                .iter()
                .find(|s| s.id == joint.servo_id)
                .map_or(f64::INFINITY, |s| {
                    s.counts_per_degree() * 180.0 / std::f64::consts::PI
                });
            jac.fixed_slice::<3, 1>(0, i).norm() * 0.5 / counts_per_rad
        })
        .sum()
}

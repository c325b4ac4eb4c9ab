//! Export of the joint trajectory as a ROS `trajectory_msgs/JointTrajectory` in YAML (the
//! form `rostopic pub` / `ros2 topic pub` take), with the URDF joint names.
use std::fmt::Write;

use super::file::Plan;

/// The YAML text: header, joint_names, and per sample positions, velocities (central
/// differences, zero at the ends) and time_from_start.
pub fn joint_trajectory_yaml(plan: &Plan, frame_id: &str) -> String {
    let mut y = String::new();
    let list = |v: &[f64]| {
        let items: Vec<String> = v.iter().map(|x| format!("{x:.9}")).collect();
        format!("[{}]", items.join(", "))
    };
    let _ = writeln!(
        y,
        "header:\n  seq: 0\n  stamp: {{secs: 0, nsecs: 0}}\n  frame_id: \"{frame_id}\""
    );
    let names: Vec<String> = plan
        .joint_names
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect();
    let _ = writeln!(y, "joint_names: [{}]", names.join(", "));
    let _ = writeln!(y, "points:");
    let n = plan.samples.len();
    for (i, s) in plan.samples.iter().enumerate() {
        let vel: Vec<f64> = if i == 0 || i + 1 == n {
            vec![0.0; s.q.len()]
        } else {
            let (a, b) = (&plan.samples[i - 1].q, &plan.samples[i + 1].q);
            a.iter()
                .zip(b)
                .map(|(x, z)| (z - x) / (2.0 * plan.period))
                .collect()
        };
        let secs = s.t.floor();
        let nsecs = ((s.t - secs) * 1e9).round() as u64;
        let (secs, nsecs) = if nsecs >= 1_000_000_000 {
            (secs + 1.0, 0)
        } else {
            (secs, nsecs)
        };
        let _ = writeln!(
            y,
            "  - positions: {}\n    velocities: {}\n    accelerations: []\n    effort: []\n    time_from_start: {{secs: {}, nsecs: {nsecs}}}",
            list(&s.q),
            list(&vel),
            secs as u64
        );
    }
    y
}

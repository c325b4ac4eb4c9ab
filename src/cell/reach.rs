//! Where on a part the cell can grind: a site filter for synthetic cases whose defects the
//! arm must reach (demo, tests/cycle.rs).
use anyhow::Result;
use nalgebra::{Point3, Vector3};

use crate::robot::{self as robot_model, IkConfig, IkTarget, RobotConfig};

/// Joint-limit margin of the reach test, rad: the sites keep 0.02 rad inside every limit so
/// the planner's own margin and the servo quantisation still leave the pose reachable.
const SITE_LIMIT_MARGIN: f64 = 0.02;

/// A site filter: the defect's centre and four points on its rim must be reachable with the
/// tool against the surface (the default cell calibration), so the demo can grind them.
pub fn reachable_sites() -> Result<impl Fn(&Point3<f64>, &Vector3<f64>, f64) -> bool + Sync> {
    let robot_cfg = RobotConfig::default();
    let (robot, workcell) = robot_model::load(&robot_cfg)?;
    let ik = IkConfig {
        limit_margin: SITE_LIMIT_MARGIN,
        ..robot_cfg.ik
    };
    let ball_mm = robot.tool.radius * 1000.0;
    let home = vec![0.0; robot.dof()];
    Ok(move |p: &Point3<f64>, n: &Vector3<f64>, radius: f64| {
        let t1 = n
            .cross(&Vector3::x())
            .try_normalize(1e-6)
            .unwrap_or_else(|| n.cross(&Vector3::y()).normalize());
        let t2 = n.cross(&t1);
        [Vector3::zeros(), t1, -t1, t2, -t2].iter().all(|t| {
            let contact = p + t * radius;
            let target = IkTarget {
                position: workcell
                    .point_from_reference_mm(&(contact + n * ball_mm))
                    .coords,
                axis: -workcell.direction_from_reference(n),
                roll: None,
            };
            robot.ik(&target, &home, &ik).is_ok()
        })
    })
}

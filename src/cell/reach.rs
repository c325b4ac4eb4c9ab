//! Where on a part the cell can grind: a site filter for synthetic cases whose defects the
//! arm must reach (demo, tests/cycle.rs).
use anyhow::Result;

use crate::robot::{CellFiles, IkConfig, IkTarget, RobotConfig};
use crate::synth::SiteProbe;

/// Joint-limit margin of the reach test, rad: the sites keep 0.02 rad inside every limit so
/// the planner's own margin and the servo quantisation still leave the pose reachable.
const SITE_LIMIT_MARGIN: f64 = 0.02;

/// Axis margin a chosen defect site keeps under the planner's axis limit, degrees: the planner
/// shares one tool axis along a stroke and holds the tool tilted off the normal where it can,
/// which moves a rim contact's axis up to about 3 degrees further off its normal than the
/// point's own best axis (issue 29's seeds 41 and 61: contacts refused at 45.2-47.8 degrees
/// beside contacts 45.0 degrees off the arm plane).
pub const SITE_AXIS_MARGIN_DEG: f64 = 5.0;

/// A filter of surface points: every probe (reference frame mm, outward normal) must be
/// reachable with the tool against the surface at its own normal, the tool axis within the
/// default IK settings' axis limit less `axis_margin_deg`, in the cell `cell` (its files held).
/// Synth's sites use [`SITE_AXIS_MARGIN_DEG`]; judging a point the planner could grind uses 0.
pub fn reachable_sites(
    cell: &CellFiles,
    axis_margin_deg: f64,
) -> Result<impl Fn(&[SiteProbe]) -> bool + Sync> {
    let robot_cfg = RobotConfig::default();
    let (robot, workcell) = cell.load()?;
    let ik = IkConfig {
        limit_margin: SITE_LIMIT_MARGIN,
        max_axis_miss_deg: robot_cfg.ik.max_axis_miss_deg - axis_margin_deg,
        ..robot_cfg.ik
    };
    let ball_mm = robot.tool.radius_mm();
    let home = vec![0.0; robot.dof()];
    Ok(move |probes: &[SiteProbe]| {
        probes.iter().all(|(contact, n)| {
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

//! The cell's `[compliance]` as `calibrate compliance` measures it on the simulated cell (issue
//! 50's compensation): the simulated operator touches the built-in poses on the simulator's
//! documented arm through the bus and the fit turns the read-back into the table, written
//! into a copy of the shipped servos.toml. The planner then sees only the fitted table.
use std::path::{Path, PathBuf};

use polishbot::bus::{Bus, BusConfig, Journal};
use polishbot::calibrate::compliance;
use polishbot::calibrate::jog::Cell;
use polishbot::calibrate::CalibrationConfig;
use polishbot::cli::calibrate_compliance::SimTouch;
use polishbot::motion::frames;
use polishbot::robot::{Compliance, Robot};
use polishbot::sim::{GrindConfig, SimArm, SimOptions};

/// `calibrate compliance`'s fit on the simulated arm of `grinding` (the shipped cell, the
/// built-in touch poses, a rigid start): the cell's robot and the fit.
pub fn run_fit(grinding: &GrindConfig) -> (Robot, compliance::ComplianceFit) {
    let robot = super::dofbot();
    let map = frames::servo_map(&robot).unwrap();
    let options = SimOptions {
        grinding: grinding.clone(),
        ..SimOptions::default()
    };
    let arm = SimArm::new(&options, &map).unwrap();
    let bus_cfg = BusConfig {
        servo_map: map.clone(),
        ..BusConfig::default()
    };
    let mut bus = Bus::connect(arm.transport(), bus_cfg, Journal::none()).unwrap();
    let cfg = CalibrationConfig::default();
    let cell = Cell {
        robot: &robot,
        map: &map,
        gripper_deg: 90.0,
        cfg: &cfg,
    };
    let poses = compliance::default_poses(&robot);
    let mut source = SimTouch::new(grinding, &poses);
    let start = Compliance {
        stiffness_nm_rad: [200.0; 5],
        backlash_deg: [0.0; 5],
        masses_kg: [0.1; 4],
    };
    let fit = compliance::compliance(&mut bus, &cell, &poses, &start, &mut source).unwrap();
    (robot, fit)
}

/// The `[compliance]` table of [`run_fit`].
pub fn fitted(grinding: &GrindConfig) -> Compliance {
    run_fit(grinding).1.compliance
}

/// The shipped servos.toml with `c` as its `[compliance]`, written to `dir/servos.toml`.
pub fn servos_with(c: &Compliance, dir: &Path) -> PathBuf {
    let out = dir.join("servos.toml");
    compliance::write_compliance(&super::calib("servos.toml"), &out, c).unwrap();
    out
}

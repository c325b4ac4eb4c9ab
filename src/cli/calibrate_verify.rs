//! `polishbot calibrate verify [--targets FILE [--fixture FILE]]`: on a cell with a turntable
//! the table is checked first: turned to each of `[calibrate] verify_table_angles_deg` (the
//! arm at its home pose during each turn), read back over 0x37 and its error reported per
//! angle in counts and degrees, then turned back to 0 (the placement workcell.toml gives).
//! Then the arm moves through the check poses (calibrate/verify.rs). Fails with one line
//! naming every check over its tolerance. Last, on a cell whose servos.toml has a
//! `[compliance]` table, the operator (with `--sim` the simulated one) makes the loaded
//! touch-offs of calibrate/compliance_check.rs, and a table they contradict is refused with
//! one line naming servos.toml and `[compliance]` ([`check_table`]).
use std::path::Path;

use super::common::say;
use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::calibrate::compliance_check::{check_compliance, check_poses};
use crate::calibrate::jog::Cell;
use crate::calibrate::verify::{verify_table, TableCheck};
use crate::calibrate::{self, CalibError, CalibrationConfig, Fixture, JogTerminal, TouchSource};
use crate::robot::{Turntable, Workcell};
use crate::sim::GrindConfig;

/// The config key of the table's check angles, named in its errors.
const ANGLES_KEY: &str = "[calibrate] verify_table_angles_deg";

/// The cell's turntable, if it has one, with the check angles tested against its range before
/// anything moves.
pub fn prepare(
    servos: &Path,
    workcell: &Path,
    cfg: &CalibrationConfig,
) -> anyhow::Result<Option<Turntable>> {
    let Some(table) = Turntable::load(servos, workcell)? else {
        return Ok(None);
    };
    anyhow::ensure!(
        !cfg.verify_table_angles_deg.is_empty(),
        "{ANGLES_KEY}: empty; the cell's turntable needs at least one check angle"
    );
    for a in cfg.verify_table_angles_deg.iter().chain(&[0.0]) {
        table
            .raw(a.to_radians())
            .map_err(|m| anyhow::anyhow!("{ANGLES_KEY}: {m}"))?;
    }
    Ok(Some(table))
}

/// Runs verify: the table (when the cell has one), then the check poses; prints every error
/// and returns the worst tool-tip error, mm (for the cell's record).
pub fn run<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    table: Option<&Turntable>,
    poses: &[[f64; JOINT_COUNT]],
    fixture: Option<&Fixture>,
    workcell_in: &Path,
) -> Result<f64, CalibError> {
    let mut failed = Vec::new();
    if let Some(table) = table {
        let angles = &cell.cfg.verify_table_angles_deg;
        let mut turn = |bus: &mut Bus<T>, deg: f64| {
            super::calibrate_table::turn_at_home(bus, cell, table, deg)
        };
        bus.torque(true)?;
        let checks = verify_table(bus, table, angles, cell.cfg.touch_reads, &mut turn)?;
        if angles.last() != Some(&0.0) {
            turn(bus, 0.0)?;
        }
        failed.extend(judge_table(&checks, cell.cfg.max_verify_table_error_counts));
    }
    let workcell = match fixture {
        Some(_) => Some(Workcell::load(workcell_in)?),
        None => None,
    };
    let r = calibrate::verify(bus, cell, poses, fixture.zip(workcell.as_ref()))?;
    for (k, p) in r.poses.iter().enumerate() {
        let e: Vec<String> = p
            .servo_error_deg
            .iter()
            .map(|v| format!("{v:+.3}"))
            .collect();
        let fid = match (&p.fiducial, p.fiducial_error_mm) {
            (Some(n), Some(e)) => format!(", fiducial {n} {e:.3} mm"),
            _ => String::new(),
        };
        say(&format!(
            "calibrate verify: pose {}: servo error [deg] {}; tool tip {:.3} mm{fid}",
            k + 1,
            e.join(" "),
            p.tip_error_mm
        ));
    }
    let fid = r
        .max_fiducial_error_mm
        .map(|e| format!(", fiducials {e:.3} mm"))
        .unwrap_or_default();
    let worst: Vec<String> = r
        .max_servo_error_deg
        .iter()
        .map(|v| format!("{v:.3}"))
        .collect();
    say(&format!(
        "calibrate verify: worst servo error [deg] {}; worst tool tip {:.3} mm{fid}",
        worst.join(" "),
        r.max_tip_error_mm
    ));
    if !r.ok {
        failed.insert(
            0,
            format!(
                "tool-tip error above {} mm (tip {:.3} mm{fid})",
                cell.cfg.max_verify_tip_error_mm, r.max_tip_error_mm
            ),
        );
    }
    match failed.is_empty() {
        true => Ok(r.max_tip_error_mm),
        false => Err(CalibError::Refused(failed.join("; "))),
    }
}

/// Prints the table's error per angle and the worst; the failure line when the worst exceeds
/// `tolerance` counts.
fn judge_table(checks: &[TableCheck], tolerance: u16) -> Option<String> {
    for c in checks {
        say(&format!(
            "calibrate verify: table {} deg (raw {}): read-back error {:+.2} counts ({:+.3} deg)",
            c.angle_deg, c.commanded_raw, c.error_counts, c.error_deg
        ));
    }
    let worst = checks
        .iter()
        .max_by(|a, b| a.error_counts.abs().total_cmp(&b.error_counts.abs()))?;
    say(&format!(
        "calibrate verify: worst table error {:.2} counts ({:.3} deg) at {} deg",
        worst.error_counts.abs(),
        worst.error_deg.abs(),
        worst.angle_deg
    ));
    (worst.error_counts.abs() > f64::from(tolerance)).then(|| {
        format!(
            "table read-back error {:.2} counts ({:.3} deg) at {} deg above {tolerance} counts",
            worst.error_counts.abs(),
            worst.error_deg.abs(),
            worst.angle_deg
        )
    })
}

/// The config key of the compliance check's bound, named in its refusal.
const CHECK_KEY: &str = "[calibrate] max_compliance_check_rms_mm";

/// The guard on servos.toml's `[compliance]` (calibrate/compliance_check.rs): nothing on a cell
/// without the table; else the loaded touch-offs (from the simulated operator of `sim`, else
/// the jog terminal) and the verdict printed after `who` (the command), and a table they
/// contradict refused naming `servos` and the key.
pub fn check_table<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    (sim, who): (Option<&GrindConfig>, &str),
    servos: &Path,
) -> Result<(), CalibError> {
    let Some(table) = cell.robot.servos.compliance.as_ref() else {
        return Ok(());
    };
    let mut source: Box<dyn TouchSource<T>> = match sim {
        Some(g) => Box::new(super::calibrate_compliance::SimTouch::new(
            g,
            &check_poses(cell.robot),
        )),
        None => {
            say(&format!(
                "{who}: {} carries a [compliance] table; check it with {} loaded \
                 touch-offs: for each, jog the tool tip onto the point (the first touch of a \
                 point fixes it) while a spring scale pulls the tip with the listed load (N, \
                 robot frame), then record the touch",
                servos.display(),
                check_poses(cell.robot).len()
            ));
            Box::new(JogTerminal::new(
                std::io::stdin(),
                std::io::stdout(),
                cell.cfg.jog_step_deg,
            ))
        }
    };
    let c = check_compliance(bus, cell, table, source.as_mut())?;
    let verdict = format!(
        "{}: [compliance]: loaded touch-offs scatter {:.3} mm with the table, {:.3} mm without \
         ({} touches; {CHECK_KEY} {})",
        servos.display(),
        c.rms_table_mm,
        c.rms_rigid_mm,
        c.touches,
        c.limit_mm
    );
    say(&format!("{who}: {verdict}"));
    match c.agrees() {
        true => Ok(()),
        false => Err(CalibError::Refused(format!(
            "{verdict}: this arm contradicts the table (it was learned on another arm); run \
             calibrate compliance on this one, or remove the table"
        ))),
    }
}

/// The loop's check of its simulated arm before the first grind (`cycle --sim`, `demo`): the
/// loaded touch-offs of [`check_table`] made by the simulated operator on a simulated arm of
/// `sim` (the run's `[sim]`, the arm the loop grinds with) against the cell's `[compliance]`
/// table, as `calibrate verify` makes them. Some(why) when the arm contradicts the table
/// (learned on another arm: the plans would bend every command by a deflection this arm does
/// not have, or miss one it has); None when it agrees or the cell has no table.
pub fn check_loop_arm(
    cell: &crate::robot::CellFiles,
    sim: &crate::sim::SimOptions,
    bus_cfg: &crate::bus::BusConfig,
) -> anyhow::Result<Option<String>> {
    let robot = cell.robot()?;
    if robot.servos.compliance.is_none() {
        return Ok(None);
    }
    let mut bus_cfg = bus_cfg.clone();
    bus_cfg.servo_map = crate::motion::frames::servo_map(&robot)?;
    let map = bus_cfg.servo_map.clone();
    let sim = super::arm::sim_with_table(sim, cell.turntable()?.as_ref())?;
    let link = Box::new(crate::sim::SimArm::new(&sim, &map)?.transport());
    let mut bus = Bus::connect(link, bus_cfg, crate::bus::Journal::none())?;
    let cfg = CalibrationConfig::default();
    let arm = Cell {
        robot: &robot,
        map: &map,
        gripper_deg: crate::motion::frames::gripper_hold_deg(&robot)?,
        cfg: &cfg,
    };
    let who = (Some(&sim.grinding), "cycle: the arm before the first grind");
    match check_table(&mut bus, &arm, who, &cell.servos.path) {
        Ok(()) => Ok(None),
        Err(CalibError::Refused(why)) => Ok(Some(why)),
        Err(e) => Err(anyhow::anyhow!(
            "cycle: checking the arm before the first grind: {e}"
        )),
    }
}

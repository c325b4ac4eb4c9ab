//! `polishbot calibrate turntable --angles a1,..,an [--targets FILE] [--cell DIR]`: turns the
//! table to each angle (the arm first moved to its home pose, the table in one rest-to-rest
//! move as `arm move --table`), touches the fiducial on the table there (jog terminal, or one
//! joint target per angle) and writes the fitted axis and centre into workcell.toml's
//! `[turntable]`, keeping every other line.
use std::path::Path;

use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::calibrate::jog::{Cell, TouchSource};
use crate::calibrate::{turntable, CalibError};
use crate::robot::units::mm;
use crate::robot::Turntable;

/// The joints the arm returns to before every table turn (the pose `arm move --table` asks
/// for), rad.
const HOME: [f64; JOINT_COUNT] = [0.0; JOINT_COUNT];

/// Runs the routine and prints its result (see the module doc).
pub fn run<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    table: Option<&Turntable>,
    angles: &[f64],
    source: &mut dyn TouchSource<T>,
    workcell_in: &Path,
    workcell_out: &Path,
) -> Result<(), CalibError> {
    let table = table.ok_or_else(|| CalibError::Refused("the cell has no turntable".into()))?;
    let mut turn = |bus: &mut Bus<T>, deg: f64| turn_at_home(bus, cell, table, deg);
    let fit = turntable::turntable(bus, cell, angles, &mut turn, source)?;
    bus.move_joints(&HOME, cell.gripper_deg, None)?;
    turntable::write_workcell(workcell_in, workcell_out, &fit)?;
    let per: Vec<String> = angles
        .iter()
        .zip(&fit.residuals_mm)
        .map(|(a, r)| format!("{a} deg {r:.3}"))
        .collect();
    println!(
        "calibrate turntable: {} angles over {:.1} deg; residual per angle [mm]: {}; RMS {:.3} mm",
        angles.len(),
        fit.span_deg,
        per.join(", "),
        fit.rms_mm
    );
    println!(
        "calibrate turntable: axis [{:.5}, {:.5}, {:.5}], centre [mm] {:.2} {:.2} {:.2}, fiducial radius {:.2} mm; wrote {}",
        fit.axis[0],
        fit.axis[1],
        fit.axis[2],
        mm(fit.centre[0]),
        mm(fit.centre[1]),
        mm(fit.centre[2]),
        fit.radius_mm,
        workcell_out.display()
    );
    Ok(())
}

/// Moves the arm to its home pose, then turns the table to `deg` degrees in one rest-to-rest
/// move (`arm move --table`, read back at the end); a refused or missed turn is one line.
pub fn turn_at_home<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    table: &Turntable,
    deg: f64,
) -> Result<(), CalibError> {
    bus.move_joints(&HOME, cell.gripper_deg, None)?;
    let settle = bus.config().settle_ms;
    super::table::turn(bus, table, deg, cell.robot.servos.period, settle)
        .map(|_| ())
        .map_err(|e| CalibError::Refused(super::common::one_line(&e)))
}

/// Checks that need no arm, before anything moves: the cell has a turntable, the angles can
/// give a fit, each lies in the table's range, and a targets file has one pose per angle.
pub fn prepare(
    servos: &Path,
    workcell: &Path,
    angles: &[f64],
    targets: Option<&Path>,
    cfg: &crate::calibrate::CalibrationConfig,
) -> anyhow::Result<Turntable> {
    let table = Turntable::load(servos, workcell)?.ok_or_else(|| {
        anyhow::anyhow!(
            "calibrate turntable: {} has no [turntable] (give --cell DIR of a cell with one)",
            servos.display()
        )
    })?;
    turntable::check_angles(angles, cfg).map_err(|e| anyhow::anyhow!("--angles: {e}"))?;
    for a in angles {
        table
            .raw(a.to_radians())
            .map_err(|m| anyhow::anyhow!("--angles: {m}"))?;
    }
    if let Some(t) = targets {
        let n = crate::calibrate::load_targets(t)?.len();
        anyhow::ensure!(
            n == angles.len(),
            "{}: {n} joint targets for {} table angles",
            t.display(),
            angles.len()
        );
    }
    Ok(table)
}

//! Verification: moves through check poses, reads each back several times, and reports the
//! per-servo error (read-back against commanded, counts and degrees) and the tool-tip error
//! it causes (forward kinematics of read-back against commanded joints). With a fixture and
//! the workcell, each pose touches a fiducial and its tip is also compared with where
//! workcell.toml puts that fiducial. [`verify_table`] checks a cell's turntable: turned to
//! each angle, read back over 0x37, the error in counts and degrees.
use dofbot_protocol::BusId;
use nalgebra::Point3;

use super::config::CalibError;
use super::files::Fixture;
use super::jog::{record, Cell};
use super::turntable::TurnTable;
use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::robot::units::mm;
use crate::robot::{Turntable, Workcell};

/// Check poses `verify` uses when none are given, rad: zero, then spread over the joint
/// ranges, ending at zero.
pub const DEFAULT_CHECK_POSES: [[f64; JOINT_COUNT]; 5] = [
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [0.5, 0.3, 0.4, 0.3, 0.8],
    [-0.5, -0.2, 0.6, 0.5, -0.8],
    [0.3, 0.6, -0.3, -0.4, 1.5],
    [0.0, 0.0, 0.0, 0.0, 0.0],
];

/// One check pose.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseCheck {
    /// Commanded joints, rad.
    pub commanded: [f64; JOINT_COUNT],
    /// Read-back joints (mean), rad.
    pub read: [f64; JOINT_COUNT],
    /// Read-back minus commanded, per joint servo, degrees.
    pub servo_error_deg: [f64; JOINT_COUNT],
    /// Tool-tip distance between read-back and commanded joints, mm.
    pub tip_error_mm: f64,
    /// The fiducial this pose touches, if checked against the workcell.
    pub fiducial: Option<String>,
    /// Tool tip to the fiducial as workcell.toml places it, mm.
    pub fiducial_error_mm: Option<f64>,
}

/// The result of [`verify`].
#[derive(Debug, Clone, PartialEq)]
pub struct VerifyReport {
    /// Every pose.
    pub poses: Vec<PoseCheck>,
    /// Largest absolute error per joint servo, degrees.
    pub max_servo_error_deg: [f64; JOINT_COUNT],
    /// Largest tool-tip error, mm.
    pub max_tip_error_mm: f64,
    /// Largest fiducial error, mm (when checked).
    pub max_fiducial_error_mm: Option<f64>,
    /// True when every tool-tip and fiducial error is within `max_verify_tip_error_mm`.
    pub ok: bool,
}

/// Moves through `poses` and reports the errors; `fiducials` pairs pose k with fiducial k.
pub fn verify<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    poses: &[[f64; JOINT_COUNT]],
    fiducials: Option<(&Fixture, &Workcell)>,
) -> Result<VerifyReport, CalibError> {
    if let Some((fixture, _)) = fiducials {
        if fixture.fiducials.len() != poses.len() {
            return Err(CalibError::Refused(format!(
                "verify: {} poses for {} fiducials; give one pose per fiducial",
                poses.len(),
                fixture.fiducials.len()
            )));
        }
    }
    bus.torque(true)?;
    let mut checks = Vec::new();
    for (k, q) in poses.iter().enumerate() {
        bus.move_joints(q, cell.gripper_deg, None)?;
        let touch = record(bus, cell, &format!("check pose {}", k + 1))?;
        let servo_error_deg: [f64; JOINT_COUNT] =
            std::array::from_fn(|i| (touch.joints[i] - q[i]).to_degrees());
        let tip_error_mm = mm((touch.tip() - cell.robot.fk(q).position).norm());
        let (fiducial, fiducial_error_mm) = match fiducials {
            Some((fixture, w)) => {
                let f = &fixture.fiducials[k];
                let at = w.point_from_reference_mm(&Point3::from(f.position));
                let e = mm((touch.tip() - at.coords).norm());
                (Some(f.name.clone()), Some(e))
            }
            None => (None, None),
        };
        checks.push(PoseCheck {
            commanded: *q,
            read: touch.joints,
            servo_error_deg,
            tip_error_mm,
            fiducial,
            fiducial_error_mm,
        });
    }
    let max_servo_error_deg = std::array::from_fn(|i| {
        checks
            .iter()
            .map(|c| c.servo_error_deg[i].abs())
            .fold(0.0, f64::max)
    });
    let max_tip_error_mm = checks.iter().map(|c| c.tip_error_mm).fold(0.0, f64::max);
    let max_fiducial_error_mm = fiducials.map(|_| {
        checks
            .iter()
            .filter_map(|c| c.fiducial_error_mm)
            .fold(0.0, f64::max)
    });
    let limit = cell.cfg.max_verify_tip_error_mm;
    let ok = max_tip_error_mm <= limit && max_fiducial_error_mm.is_none_or(|e| e <= limit);
    Ok(VerifyReport {
        poses: checks,
        max_servo_error_deg,
        max_tip_error_mm,
        max_fiducial_error_mm,
        ok,
    })
}

/// The turntable's read-back at one verify angle.
#[derive(Debug, Clone, PartialEq)]
pub struct TableCheck {
    /// Commanded table angle, degrees.
    pub angle_deg: f64,
    /// Raw count commanded for it.
    pub commanded_raw: u16,
    /// Mean read-back minus commanded raw, counts.
    pub error_counts: f64,
    /// Mean read-back table angle minus commanded, degrees.
    pub error_deg: f64,
}

/// Turns the table to each of `angles_deg` in turn (`turn`: the arm to its home pose, then one
/// rest-to-rest table move), reads it back `reads` times over 0x37 and reports the mean error
/// against the commanded raw count and angle. The caller judges the errors.
pub fn verify_table<T: Transport>(
    bus: &mut Bus<T>,
    table: &Turntable,
    angles_deg: &[f64],
    reads: usize,
    turn: &mut TurnTable<'_, T>,
) -> Result<Vec<TableCheck>, CalibError> {
    let refuse = |m: String| CalibError::Refused(format!("turntable: {m}"));
    let id = BusId::new(table.servo.id).map_err(|e| refuse(e.to_string()))?;
    let reads = reads.max(1);
    let mut out = Vec::with_capacity(angles_deg.len());
    for &a in angles_deg {
        let commanded_raw = table.raw(a.to_radians()).map_err(refuse)?;
        turn(bus, a)?;
        let (mut counts, mut deg) = (0.0, 0.0);
        for _ in 0..reads {
            let raw = bus.read_any_raw(id, table.servo.raw_range)?;
            counts += f64::from(raw) - f64::from(commanded_raw);
            deg += table.angle_from_raw(raw).map_err(refuse)?.to_degrees() - a;
        }
        out.push(TableCheck {
            angle_deg: a,
            commanded_raw,
            error_counts: counts / reads as f64,
            error_deg: deg / reads as f64,
        });
    }
    Ok(out)
}

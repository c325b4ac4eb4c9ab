//! Tool-tip calibration by the pivot method: the tool tip touches one fixed point from several
//! orientations. With flange poses `(R_i, p_i)`, tip offset `t` (flange frame) and pivot `c`
//! (base frame), `R_i t + p_i = c` for every touch: linear least squares over
//! `[R_i, -I] [t; c] = -p_i` (SVD). Refused with too few touches or orientations too alike
//! (then `t` and `c` cannot be told apart along the shared rotation axis).
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Vector3};

use super::config::{CalibError, CalibrationConfig};
use super::jog::{Cell, Touch, TouchSource};
use crate::bus::{Bus, Transport};
use crate::robot::units::mm;
use crate::robot::Robot;

/// Most touches a routine collects before it stops asking.
pub const MAX_TOUCHES: usize = 64;

/// The result of the pivot calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct PivotFit {
    /// Tool tip in the flange frame, metres (tool.toml's `tip_offset`).
    pub tip_offset: [f64; 3],
    /// The touched point in the robot base frame, metres.
    pub pivot: [f64; 3],
    /// Distance of each touch's tip from the pivot, mm.
    pub residuals_mm: Vec<f64>,
    /// RMS of the residuals, mm.
    pub rms_mm: f64,
    /// Orientation spread of the touches, degrees (see `min_pivot_spread_deg`).
    pub spread_deg: f64,
    /// The touches.
    pub touches: Vec<Touch>,
}

/// Collects pivot touches from `source` until it has no more, then fits the tool tip.
pub fn tool_tip<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    source: &mut dyn TouchSource<T>,
) -> Result<PivotFit, CalibError> {
    bus.torque(true)?;
    let mut touches = Vec::new();
    while touches.len() < MAX_TOUCHES {
        let label = format!("the pivot point (touch {})", touches.len() + 1);
        match source.touch(bus, cell, &label)? {
            Some(t) => touches.push(t),
            None => break,
        }
    }
    fit_pivot(cell.robot, touches, cell.cfg)
}

/// The flange pose (wrist-roll frame) at joints `q`: the tool link's pose with the current
/// tool.toml tip offset taken off (the tool joint carries no rotation).
pub fn flange(robot: &Robot, q: &[f64]) -> Isometry3<f64> {
    let mut iso = robot.fk_isometry(q);
    iso.translation.vector -= iso.rotation * Vector3::from(robot.tool.tip_offset);
    iso
}

/// Orientation spread of rotations, degrees: `acos(s1 / n)` with `s1` the largest singular
/// value of their sum (0 when all are equal).
pub fn orientation_spread_deg(rotations: &[Matrix3<f64>]) -> f64 {
    let n = rotations.len() as f64;
    let sum: Matrix3<f64> = rotations.iter().sum();
    let s1 = sum.singular_values().max();
    (s1 / n).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Fits the tool tip to pivot touches (joints read back at each).
pub fn fit_pivot(
    robot: &Robot,
    touches: Vec<Touch>,
    cfg: &CalibrationConfig,
) -> Result<PivotFit, CalibError> {
    let n = touches.len();
    if n < cfg.min_touches.max(3) {
        return Err(CalibError::Refused(format!(
            "pivot: {n} touches, need at least {} from different orientations",
            cfg.min_touches.max(3)
        )));
    }
    let poses: Vec<Isometry3<f64>> = touches.iter().map(|t| flange(robot, &t.joints)).collect();
    let rotations: Vec<Matrix3<f64>> = poses
        .iter()
        .map(|p| p.rotation.to_rotation_matrix().into_inner())
        .collect();
    let spread = orientation_spread_deg(&rotations);
    if spread < cfg.min_pivot_spread_deg {
        return Err(CalibError::Refused(format!(
            "pivot poses too similar: orientation spread {spread:.1} deg, need at least {} deg; \
             touch the point with the tool tilted and rolled further between touches",
            cfg.min_pivot_spread_deg
        )));
    }
    let mut a = DMatrix::zeros(3 * n, 6);
    let mut b = DVector::zeros(3 * n);
    for (i, (p, r)) in poses.iter().zip(&rotations).enumerate() {
        a.fixed_slice_mut::<3, 3>(3 * i, 0).copy_from(r);
        a.fixed_slice_mut::<3, 3>(3 * i, 3)
            .copy_from(&(-Matrix3::identity()));
        b.fixed_rows_mut::<3>(3 * i)
            .copy_from(&(-p.translation.vector));
    }
    let x = a
        .svd(true, true)
        .solve(&b, 1e-12)
        .map_err(|e| CalibError::Refused(format!("pivot: least squares failed: {e}")))?;
    let t = Vector3::new(x[0], x[1], x[2]);
    let c = Vector3::new(x[3], x[4], x[5]);
    let residuals_mm: Vec<f64> = poses
        .iter()
        .map(|p| mm((p.rotation * t + p.translation.vector - c).norm()))
        .collect();
    let rms_mm = rms(&residuals_mm);
    if rms_mm > cfg.max_pivot_rms_mm {
        return Err(CalibError::Refused(format!(
            "pivot: RMS residual {rms_mm:.2} mm exceeds {} mm (per touch: {}): the tip slid off \
             the point between touches",
            cfg.max_pivot_rms_mm,
            list_mm(&residuals_mm)
        )));
    }
    Ok(PivotFit {
        tip_offset: [t.x, t.y, t.z],
        pivot: [c.x, c.y, c.z],
        residuals_mm,
        rms_mm,
        spread_deg: spread,
        touches,
    })
}

/// Root mean square.
pub fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// `0.12, 0.30, ..` (mm, two decimals).
pub fn list_mm(v: &[f64]) -> String {
    let parts: Vec<String> = v.iter().map(|x| format!("{x:.2}")).collect();
    parts.join(", ")
}

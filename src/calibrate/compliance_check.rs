//! The guard on servos.toml's `[compliance]` (issue 50): the planner bends every grinding
//! command by the table's predicted deflection, so a table learned on another arm (or on this
//! arm before a servo was changed) moves the tool by that deflection where the arm does not
//! bend: the loop on an ideal arm with the documented arm's table cut to -0.393 mm. `calibrate
//! verify` therefore makes a few loaded touch-offs of its own ([`check_poses`]: two fixed
//! points, each pushed out, up, in and down with a push across the arm either way) and asks
//! the table to explain them: with the table, every touch of a point must put the modelled
//! loaded tip on one place ([`judge`]). A table whose touches scatter more than
//! `max_compliance_check_rms_mm` is contradicted by the cell's own measurements and refused.
//! The check needs only the read-back joints and the loads the operator applied, never the
//! simulator's parameters; the same touches without the table (the rigid arm) are reported
//! beside it, so the message says which model the arm follows.
use nalgebra::Vector3;

use super::compliance::{touch_all, touch_plan, LoadedPose};
use super::config::CalibError;
use super::jog::{Cell, Touch, TouchSource};
use super::touch_plan::IN_PLANE_DEG;
use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::robot::{Compliance, Robot};

/// Base poses of the check's two points (joint angles, rad): two of `calibrate compliance`'s
/// points, one straight ahead and high, one to the right and far, so every pitch joint and the
/// base yaw carry load torques of both signs across the eight loads.
const CHECK_POINTS: [[f64; JOINT_COUNT]; 2] =
    [[0.0, 0.35, 0.7, 0.5, 0.0], [0.45, -0.1, 0.9, 0.8, 0.0]];
/// The check touches each point from the base pose's tilt only (the tilts add nothing the loads
/// do not already show, and an operator makes 16 touches, not 80).
const CHECK_TILTS_DEG: [f64; 1] = [0.0];
/// The push across the arm plane with each in-plane load, relative to it: both ways, so the
/// base yaw's gear crosses its band.
const CHECK_ACROSS: [f64; 2] = [1.0, -1.0];

/// The verdict on a `[compliance]` table from the check's touches.
#[derive(Debug, Clone, PartialEq)]
pub struct ComplianceCheck {
    /// RMS distance of the touches' modelled loaded tips (with the table) from their point's
    /// mean, mm.
    pub rms_table_mm: f64,
    /// The same without the table (the rigid arm's tip at the read-back joints), mm.
    pub rms_rigid_mm: f64,
    /// Touches judged.
    pub touches: usize,
    /// The bound `rms_table_mm` was judged against, mm (`max_compliance_check_rms_mm`).
    pub limit_mm: f64,
}

impl ComplianceCheck {
    /// True when the table explains the touches within the bound.
    pub fn agrees(&self) -> bool {
        self.rms_table_mm <= self.limit_mm
    }
}

/// The check's touches: each point of [`CHECK_POINTS`] under the loads of `calibrate
/// compliance` (4 N out, up, in and down, each pushed across the arm either way).
pub fn check_poses(robot: &Robot) -> Vec<LoadedPose> {
    touch_plan(
        robot,
        &CHECK_POINTS,
        &CHECK_TILTS_DEG,
        &IN_PLANE_DEG,
        &CHECK_ACROSS,
    )
}

/// RMS over the touches of the distance of `tip(touch, pose)` from the mean of its point's
/// tips, mm.
fn scatter(
    poses: &[LoadedPose],
    touches: &[Touch],
    tip: impl Fn(&Touch, &LoadedPose) -> Vector3<f64>,
) -> f64 {
    let tips: Vec<(usize, Vector3<f64>)> = poses
        .iter()
        .zip(touches)
        .map(|(p, t)| (p.point, tip(t, p)))
        .collect();
    let n_points = poses.iter().map(|p| p.point + 1).max().unwrap_or(0);
    let mut sq = 0.0;
    for point in 0..n_points {
        let own: Vec<Vector3<f64>> = tips
            .iter()
            .filter(|(p, _)| *p == point)
            .map(|(_, v)| *v)
            .collect();
        let mean = own.iter().sum::<Vector3<f64>>() / own.len().max(1) as f64;
        sq += own.iter().map(|v| (v - mean).norm_squared()).sum::<f64>();
    }
    (sq / tips.len().max(1) as f64).sqrt() * 1e3
}

/// Judges `table` by the touches `touches` made at `poses` (one each): the scatter of the
/// modelled loaded tips with the table and without it, against `limit_mm`.
pub fn judge(
    robot: &Robot,
    poses: &[LoadedPose],
    touches: &[Touch],
    table: &Compliance,
    limit_mm: f64,
) -> ComplianceCheck {
    let loaded =
        |t: &Touch, p: &LoadedPose| table.loaded_tip(robot, &t.joints, &Vector3::from(p.force_n));
    ComplianceCheck {
        rms_table_mm: scatter(poses, touches, loaded),
        rms_rigid_mm: scatter(poses, touches, |t, _| t.tip()),
        touches: touches.len(),
        limit_mm,
    }
}

/// Makes the check's touches with `source` and judges `table` by them (the caller refuses a
/// table that does not [`ComplianceCheck::agrees`]).
pub fn check_compliance<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    table: &Compliance,
    source: &mut dyn TouchSource<T>,
) -> Result<ComplianceCheck, CalibError> {
    let poses = check_poses(cell.robot);
    let touches = touch_all(bus, cell, &poses, source, "compliance check")?;
    let limit = cell.cfg.max_compliance_check_rms_mm;
    Ok(judge(cell.robot, &poses, &touches, table, limit))
}

//! Workcell calibration: the tool tip touches the fixture's fiducials; a rigid fit without
//! scale (weighted SVD, Umeyama, shared with registration) of their reference-frame
//! coordinates onto the touched tips gives `robot_from_reference`. Refused before any motion
//! with fewer than four fiducials or (nearly) collinear ones, and after the touches when the
//! RMS residual exceeds the threshold.
use nalgebra::{Matrix3, Matrix4, Point3, Vector3};

use super::config::{CalibError, CalibrationConfig};
use super::files::Fixture;
use super::jog::{Cell, Touch, TouchSource};
use super::pivot::rms;
use crate::bus::{Bus, Transport};
use crate::register::mac::pose::weighted_svd;
use crate::robot::units::{metres, mm};

/// The result of the workcell calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct WorkcellFit {
    /// Robot base frame from the reference frame, metres (workcell.toml).
    pub robot_from_reference: Matrix4<f64>,
    /// Distance between each fiducial mapped by the fit and its touched tip, mm.
    pub residuals_mm: Vec<f64>,
    /// RMS of the residuals, mm.
    pub rms_mm: f64,
    /// The touches, one per fiducial.
    pub touches: Vec<Touch>,
}

/// Checks that the fixture can give a rigid fit: at least `min_touches` fiducials, not
/// (nearly) collinear.
pub fn check_fixture(fixture: &Fixture, cfg: &CalibrationConfig) -> Result<(), CalibError> {
    let n = fixture.fiducials.len();
    let need = cfg.min_touches.max(3);
    if n < need {
        return Err(CalibError::Refused(format!(
            "workcell: the fixture has {n} fiducials, need at least {need}"
        )));
    }
    let pts: Vec<Vector3<f64>> = fixture
        .fiducials
        .iter()
        .map(|f| Vector3::from(f.position))
        .collect();
    let centre = pts.iter().sum::<Vector3<f64>>() / n as f64;
    let cov: Matrix3<f64> = pts
        .iter()
        .map(|p| (p - centre) * (p - centre).transpose())
        .sum();
    let mut sv: Vec<f64> = cov
        .symmetric_eigenvalues()
        .iter()
        .map(|v| v.max(0.0).sqrt())
        .collect();
    sv.sort_by(|a, b| b.total_cmp(a));
    if sv[0] <= 0.0 || sv[1] < cfg.min_fiducial_spread * sv[0] {
        return Err(CalibError::Refused(format!(
            "workcell: the fiducials are (nearly) collinear (spread off their line {:.3} of the \
             spread along it, need {}): use fiducials that span a plane",
            if sv[0] > 0.0 { sv[1] / sv[0] } else { 0.0 },
            cfg.min_fiducial_spread
        )));
    }
    Ok(())
}

/// Touches every fiducial of `fixture` (in order) and fits `robot_from_reference`.
pub fn workcell<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    fixture: &Fixture,
    source: &mut dyn TouchSource<T>,
) -> Result<WorkcellFit, CalibError> {
    check_fixture(fixture, cell.cfg)?;
    bus.torque(true)?;
    let mut touches = Vec::new();
    for f in &fixture.fiducials {
        let label = format!("fiducial {}", f.name);
        match source.touch(bus, cell, &label)? {
            Some(t) => touches.push(t),
            None => {
                return Err(CalibError::Refused(format!(
                    "workcell: {} of {} fiducials touched; touch every fiducial",
                    touches.len(),
                    fixture.fiducials.len()
                )))
            }
        }
    }
    fit_workcell(fixture, touches, cell.cfg)
}

/// Fits `robot_from_reference` to one touch per fiducial.
pub fn fit_workcell(
    fixture: &Fixture,
    touches: Vec<Touch>,
    cfg: &CalibrationConfig,
) -> Result<WorkcellFit, CalibError> {
    check_fixture(fixture, cfg)?;
    if touches.len() != fixture.fiducials.len() {
        return Err(CalibError::Refused(format!(
            "workcell: {} touches for {} fiducials",
            touches.len(),
            fixture.fiducials.len()
        )));
    }
    let src: Vec<Point3<f64>> = fixture
        .fiducials
        .iter()
        .map(|f| Point3::from(metres(Vector3::from(f.position))))
        .collect();
    let dst: Vec<Point3<f64>> = touches.iter().map(|t| Point3::from(t.tip())).collect();
    let pose = weighted_svd(&src, &dst, &vec![1.0; src.len()]).ok_or_else(|| {
        CalibError::Refused("workcell: the touched tips are degenerate (collinear)".into())
    })?;
    let residuals_mm: Vec<f64> = src
        .iter()
        .zip(&dst)
        .map(|(s, d)| mm((pose * s - d).norm()))
        .collect();
    let rms_mm = rms(&residuals_mm);
    if rms_mm > cfg.max_workcell_rms_mm {
        let per: Vec<String> = fixture
            .fiducials
            .iter()
            .zip(&residuals_mm)
            .map(|(f, r)| format!("{} {r:.2}", f.name))
            .collect();
        return Err(CalibError::Refused(format!(
            "workcell: RMS residual {rms_mm:.2} mm exceeds {} mm (per fiducial, mm: {}): a touch \
             missed its fiducial or the fixture file does not match the fixture",
            cfg.max_workcell_rms_mm,
            per.join(", ")
        )));
    }
    Ok(WorkcellFit {
        robot_from_reference: pose.to_homogeneous(),
        residuals_mm,
        rms_mm,
        touches,
    })
}

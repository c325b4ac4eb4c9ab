//! Settings of the calibration routines and the error they stop with.
use serde::{Deserialize, Serialize};

use crate::bus::BusError;
use crate::robot::RobotError;

/// Default of `max_compliance_check_rms_mm`, mm: 0.3, six times the scatter the documented
/// arm's own table leaves on `verify`'s loaded touch-offs on the simulated cell (0.050 mm:
/// whole servo counts), and a twentieth of what the documented arm's table leaves on an ideal
/// arm (6.4 mm; the documented arm without its table: 6.3 mm). A tenth of the 4 N loads'
/// deflection then passes unexplained at most.
pub const MAX_COMPLIANCE_CHECK_RMS_MM: f64 = 0.3;

/// Settings of the calibration routines.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibrationConfig {
    /// Reads per servo at the zero pose. Default 8.
    pub reads_per_servo: usize,
    /// Largest spread (max - min) of one servo's reads, counts; more is refused (the arm
    /// moved, or the servo jitters). Default 2.
    pub max_spread_counts: u16,
    /// Largest change of a servo's zero against the current servos.toml, degrees; more means
    /// the arm is not in the zero pose and is refused. Default 20.
    pub max_zero_change_deg: f64,
    /// Reads averaged per touch (tool and workcell) and per verify pose. Default 5.
    pub touch_reads: usize,
    /// Fewest pivot touches and fewest fiducials. Default 4.
    pub min_touches: usize,
    /// Smallest orientation spread of the pivot touches, degrees: `acos(s1 / n)`, s1 the
    /// largest singular value of the sum of the n flange rotations (0 when all are alike, about
    /// the half-range of the tilt about the least-varied axis). Default 10.
    pub min_pivot_spread_deg: f64,
    /// Largest RMS pivot residual, mm. Default 1.
    pub max_pivot_rms_mm: f64,
    /// Largest RMS fiducial residual of the workcell fit, mm. Default 1.
    pub max_workcell_rms_mm: f64,
    /// Smallest spread of the fiducials off their best-fit line, as the ratio of the second
    /// to the first singular value of the centred coordinates; less is "collinear". Default 0.1.
    pub min_fiducial_spread: f64,
    /// Largest tool-tip error `verify` accepts, mm. Default 1.
    pub max_verify_tip_error_mm: f64,
    /// Fewest table angles `calibrate turntable` touches the fiducial at (5: a circle has three
    /// unknowns in its plane, the plane three; two spare touches show a bad one).
    pub min_table_angles: usize,
    /// Smallest span of those table angles, degrees (90: on a shorter arc the centre's error
    /// grows as the inverse square of the span; a quarter turn keeps 1-count read noise
    /// under 0.3 mm at a 40 mm fiducial radius).
    pub min_table_span_deg: f64,
    /// Largest RMS distance of the touched tips from the fitted circle, mm (1.0, as the
    /// workcell fit's).
    pub max_table_rms_mm: f64,
    /// Table angles `verify` turns a cell's turntable to (arm at home), degrees. Default -90,
    /// -30, 30, 90, 0: both directions over most of the shipped table's +-135 degrees (a servo
    /// that drags under load misses most at the far ends), ending at the calibrated placement.
    pub verify_table_angles_deg: Vec<f64>,
    /// Largest mean read-back error of the table `verify` accepts, counts. Default 2: the
    /// spread `max_spread_counts` accepts from a still servo; on the 270-degree table servo
    /// (0.081 degree a count) 2 counts move a point 40 mm off the axis by 0.11 mm, a tenth of
    /// `max_verify_tip_error_mm`.
    pub max_verify_table_error_counts: u16,
    /// Initial jog step, degrees. Default 1.
    pub jog_step_deg: f64,
    /// Largest RMS scatter of `verify`'s loaded touch-offs under servos.toml's `[compliance]`
    /// (calibrate/compliance_check.rs), mm; more refuses the table as not this arm's. Default
    /// [`MAX_COMPLIANCE_CHECK_RMS_MM`].
    pub max_compliance_check_rms_mm: f64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        CalibrationConfig {
            reads_per_servo: 8,
            max_spread_counts: 2,
            max_zero_change_deg: 20.0,
            touch_reads: 5,
            min_touches: 4,
            min_pivot_spread_deg: 10.0,
            max_pivot_rms_mm: 1.0,
            max_workcell_rms_mm: 1.0,
            min_fiducial_spread: 0.1,
            max_verify_tip_error_mm: 1.0,
            jog_step_deg: 1.0,
            min_table_angles: 5,
            min_table_span_deg: 90.0,
            max_table_rms_mm: 1.0,
            verify_table_angles_deg: vec![-90.0, -30.0, 30.0, 90.0, 0.0],
            max_verify_table_error_counts: 2,
            max_compliance_check_rms_mm: MAX_COMPLIANCE_CHECK_RMS_MM,
        }
    }
}

/// What can stop a calibration routine; each displays as one line.
#[derive(Debug, thiserror::Error)]
pub enum CalibError {
    /// The bus failed (a servo that does not answer, a lost port, a failed read).
    #[error(transparent)]
    Bus(#[from] BusError),
    /// A calibration file is bad.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// The input cannot give a sound calibration (too few or degenerate touches, residuals
    /// too large); nothing was written.
    #[error("{0}")]
    Refused(String),
    /// The operator aborted the routine.
    #[error("aborted by the operator; nothing written")]
    Aborted,
    /// A file could not be read or written.
    #[error("{file}: {message}")]
    File {
        /// The file.
        file: String,
        /// What failed, with the place (`line N`, a key).
        message: String,
    },
}

impl CalibError {
    /// A file error naming `file`.
    pub fn file(file: &std::path::Path, message: impl std::fmt::Display) -> CalibError {
        CalibError::File {
            file: file.display().to_string(),
            message: message.to_string(),
        }
    }
}

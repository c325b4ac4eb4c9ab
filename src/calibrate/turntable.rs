//! Turntable calibration: the tool tip touches one fiducial on the table at several table
//! angles; the touched tips lie on a circle about the table's axis. A plane fit (the smallest
//! principal direction of the tips) gives the axis, a circle fit in that plane (Kasa's
//! algebraic least squares) its centre, the sign of the axis comes from the order of the
//! commanded angles (positive angles turn right-handed). Refused before any motion with too
//! few angles or angles spanning too little, and after the touches when the residual of the
//! circle exceeds the threshold. Writes workcell.toml's `[turntable]` axis and centre.
use std::path::Path;

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use super::config::{CalibError, CalibrationConfig};
use super::jog::{Cell, Touch, TouchSource};
use super::pivot::rms;
use crate::bus::{Bus, Transport};
use crate::robot::units::mm;

/// The result of the turntable calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct TableFit {
    /// Rotation axis in the robot frame (unit; positive table angles turn right-handed).
    pub axis: [f64; 3],
    /// The circle's centre: a point of the axis, robot frame, metres.
    pub centre: [f64; 3],
    /// Radius of the fiducial's circle, mm.
    pub radius_mm: f64,
    /// Distance of each touched tip from the fitted circle, mm.
    pub residuals_mm: Vec<f64>,
    /// RMS of the residuals, mm.
    pub rms_mm: f64,
    /// Span of the table angles touched, degrees.
    pub span_deg: f64,
    /// The touches, one per table angle.
    pub touches: Vec<Touch>,
}

/// Checks the table angles before anything moves: at least `min_table_angles`, all distinct,
/// spanning at least `min_table_span_deg`.
pub fn check_angles(angles_deg: &[f64], cfg: &CalibrationConfig) -> Result<f64, CalibError> {
    let refuse = |m: String| Err(CalibError::Refused(format!("turntable: {m}")));
    if angles_deg.len() < cfg.min_table_angles {
        return refuse(format!(
            "{} table angles, need at least {}",
            angles_deg.len(),
            cfg.min_table_angles
        ));
    }
    if angles_deg.iter().any(|a| !a.is_finite()) {
        return refuse("a table angle is not a number".into());
    }
    let mut sorted = angles_deg.to_vec();
    sorted.sort_by(f64::total_cmp);
    if sorted.windows(2).any(|w| w[1] - w[0] < 1e-6) {
        return refuse("two table angles are equal: each touch needs its own angle".into());
    }
    let span = sorted[sorted.len() - 1] - sorted[0];
    if span < cfg.min_table_span_deg {
        return refuse(format!(
            "the table angles span {span:.1} deg, need at least {} deg (a short arc leaves the \
             axis and centre undetermined)",
            cfg.min_table_span_deg
        ));
    }
    Ok(span)
}

/// What turns the table to an angle (degrees) between two touches (`calibrate turntable`: the
/// arm to its home pose, then one rest-to-rest table move).
pub type TurnTable<'a, T> = dyn FnMut(&mut Bus<T>, f64) -> Result<(), CalibError> + 'a;

/// Turns the table to each of `angles_deg` in turn (`turn`, with the arm moved out of the way
/// by it), touches the fiducial there (`source`) and fits axis and centre.
pub fn turntable<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    angles_deg: &[f64],
    turn: &mut TurnTable<'_, T>,
    source: &mut dyn TouchSource<T>,
) -> Result<TableFit, CalibError> {
    check_angles(angles_deg, cell.cfg)?;
    bus.torque(true)?;
    let mut touches = Vec::with_capacity(angles_deg.len());
    for &a in angles_deg {
        turn(bus, a)?;
        let label = format!("fiducial at table {a} deg");
        match source.touch(bus, cell, &label)? {
            Some(t) => touches.push(t),
            None => {
                return Err(CalibError::Refused(format!(
                    "turntable: {} of {} table angles touched; touch the fiducial at every angle",
                    touches.len(),
                    angles_deg.len()
                )))
            }
        }
    }
    fit_turntable(angles_deg, touches, cell.cfg)
}

/// Plane and circle through the touched tips (see the module doc).
pub fn fit_turntable(
    angles_deg: &[f64],
    touches: Vec<Touch>,
    cfg: &CalibrationConfig,
) -> Result<TableFit, CalibError> {
    let span_deg = check_angles(angles_deg, cfg)?;
    if touches.len() != angles_deg.len() {
        return Err(CalibError::Refused(format!(
            "turntable: {} touches for {} table angles",
            touches.len(),
            angles_deg.len()
        )));
    }
    let pts: Vec<Vector3<f64>> = touches.iter().map(Touch::tip).collect();
    let n = pts.len() as f64;
    let mean = pts.iter().sum::<Vector3<f64>>() / n;
    let cov: Matrix3<f64> = pts
        .iter()
        .map(|p| (p - mean) * (p - mean).transpose())
        .sum();
    let eig = cov.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let mut axis: Vector3<f64> = eig.eigenvectors.column(order[0]).into();
    let u: Vector3<f64> = eig.eigenvectors.column(order[2]).into();
    let v = axis.cross(&u);
    // Kasa: x^2 + y^2 = 2 a x + 2 b y + c in the plane's coordinates
    let a = DMatrix::from_fn(pts.len(), 3, |i, j| {
        let d = pts[i] - mean;
        [2.0 * d.dot(&u), 2.0 * d.dot(&v), 1.0][j]
    });
    let rhs = DVector::from_fn(pts.len(), |i, _| {
        let d = pts[i] - mean;
        d.dot(&u).powi(2) + d.dot(&v).powi(2)
    });
    let sol = a
        .svd(true, true)
        .solve(&rhs, 1e-15)
        .map_err(|e| CalibError::Refused(format!("turntable: circle fit failed: {e}")))?;
    let centre = mean + u * sol[0] + v * sol[1];
    let radius = (sol[2] + sol[0] * sol[0] + sol[1] * sol[1]).max(0.0).sqrt();
    // positive angles turn right-handed: the tips advance counter-clockwise about the axis
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_by(|&i, &j| angles_deg[i].total_cmp(&angles_deg[j]));
    let turning: f64 = order
        .windows(2)
        .map(|w| (pts[w[0]] - centre).cross(&(pts[w[1]] - centre)).dot(&axis))
        .sum();
    if turning < 0.0 {
        axis = -axis;
    }
    let residuals_mm: Vec<f64> = pts
        .iter()
        .map(|p| {
            let d = p - centre;
            let off = d.dot(&axis);
            let radial = (d - axis * off).norm() - radius;
            mm((off * off + radial * radial).sqrt())
        })
        .collect();
    let rms_mm = rms(&residuals_mm);
    if rms_mm > cfg.max_table_rms_mm {
        return Err(CalibError::Refused(format!(
            "turntable: RMS residual {rms_mm:.2} mm of the circle exceeds {} mm (per angle, mm: \
             {}): a touch missed the fiducial, or the fiducial moved on the table",
            cfg.max_table_rms_mm,
            residuals_mm
                .iter()
                .zip(angles_deg)
                .map(|(r, a)| format!("{a} deg {r:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    check_arc(angles_deg, &pts, (&centre, &axis, &u), mm(radius))?;
    Ok(TableFit {
        axis: axis.into(),
        centre: centre.into(),
        radius_mm: mm(radius),
        residuals_mm,
        rms_mm,
        span_deg,
        touches,
    })
}

/// Smallest accepted radius of the fiducial's circle, mm: the axis direction comes from the
/// tips' circle, so its tilt error is about the touch error (0.1-0.3 mm with a hand-jogged
/// ball) over the radius; at 10 mm that is 1-2 degrees, the most a table plan can use. Five
/// touches at one point (radius 0) say nothing about the axis.
pub const MIN_TABLE_RADIUS_MM: f64 = 10.0;
/// Largest accepted difference between a step of the commanded table angles and the arc the
/// touched tips turn through about the fitted axis over that step, degrees: a touch error of
/// 0.3 mm at the 10 mm smallest radius is 1.7 degrees; a fiducial that did not turn with the
/// table, or angles listed in another order than the touches, misses by tens of degrees.
pub const MAX_ARC_MISMATCH_DEG: f64 = 5.0;

/// Refuses touches that do not follow the commanded angles: a circle smaller than
/// [`MIN_TABLE_RADIUS_MM`], or a step between two angles (in the order given) whose touched
/// arc about the fitted axis (`frame`: centre, axis, an in-plane direction) differs from the
/// commanded step by more than [`MAX_ARC_MISMATCH_DEG`].
fn check_arc(
    angles_deg: &[f64],
    pts: &[Vector3<f64>],
    frame: (&Vector3<f64>, &Vector3<f64>, &Vector3<f64>),
    radius_mm: f64,
) -> Result<(), CalibError> {
    if radius_mm.is_nan() || radius_mm < MIN_TABLE_RADIUS_MM {
        return Err(CalibError::Refused(format!(
            "turntable: the touched tips lie on a circle of radius {radius_mm:.3} mm, need at \
             least {MIN_TABLE_RADIUS_MM} mm (a fiducial near the axis, or every touch at one \
             point, leaves the axis undetermined)"
        )));
    }
    let (centre, axis, u) = frame;
    let v = axis.cross(u);
    let theta = |p: &Vector3<f64>| {
        let d = p - centre;
        d.dot(&v).atan2(d.dot(u)).to_degrees()
    };
    let wrap = |a: f64| (a + 180.0).rem_euclid(360.0) - 180.0;
    for i in 1..pts.len() {
        let touched = wrap(theta(&pts[i]) - theta(&pts[i - 1]));
        let commanded = angles_deg[i] - angles_deg[i - 1];
        if wrap(touched - commanded).abs() > MAX_ARC_MISMATCH_DEG {
            return Err(CalibError::Refused(format!(
                "turntable: touches {} and {}: the tip turned {touched:.1} deg about the fitted \
                 axis while the table turned {commanded:.1} deg (more than \
                 {MAX_ARC_MISMATCH_DEG} deg apart): the fiducial did not turn with the table, \
                 or the angles are not in the order of the touches",
                i - 1,
                i
            )));
        }
    }
    Ok(())
}

/// Shortest decimal that reads back as the same f64.
fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') {
        s
    } else {
        format!("{s}.0")
    }
}

/// The workcell.toml text `text` with `[turntable]`'s `axis` and `centre` set (lines
/// replaced in place, every other line and comment kept; the table added at the end when the
/// file has none).
pub fn patch_workcell(text: &str, fit: &TableFit) -> String {
    let vec3 = |v: [f64; 3]| format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]));
    let axis = format!("axis = {}", vec3(fit.axis));
    let centre = format!("centre = {}", vec3(fit.centre));
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let Some(start) = lines.iter().position(|l| l.trim() == "[turntable]") else {
        let mut out = text.trim_end().to_string();
        out.push_str(&format!(
            "\n\n# The part turntable (calibrate turntable).\n[turntable]\n{axis}\n{centre}\n"
        ));
        return out;
    };
    let end = (start + 1..lines.len())
        .find(|&i| lines[i].trim_start().starts_with('['))
        .unwrap_or(lines.len());
    let sets = |l: &str, key: &str| {
        l.trim_start()
            .strip_prefix(key)
            .is_some_and(|r| r.trim_start().starts_with('='))
    };
    for (key, new) in [("axis", axis), ("centre", centre)] {
        match (start + 1..end).find(|&i| sets(&lines[i], key)) {
            Some(i) => lines[i] = new,
            None => lines.insert(start + 1, new),
        }
    }
    lines.join("\n") + "\n"
}

/// Writes `out` from `input` (workcell.toml) with the fitted axis and centre.
pub fn write_workcell(input: &Path, out: &Path, fit: &TableFit) -> Result<(), CalibError> {
    let text = std::fs::read_to_string(input).map_err(|e| CalibError::file(input, e))?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| CalibError::file(dir, e))?;
    }
    std::fs::write(out, patch_workcell(&text, fit)).map_err(|e| CalibError::file(out, e))
}

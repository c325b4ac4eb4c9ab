//! Compliance calibration (issue 50): the tool tip touches a few fixed points, each from
//! several tool tilts and under loads of both signs (pushed up, down, sideways both ways and
//! along the arm both ways); the touches' read-back joint angles, the known loads and the
//! unknown points give the joints' stiffness, backlash and the arm's lumped masses by
//! nonlinear least squares (Levenberg-Marquardt on [`Compliance::loaded_tip`]), written to
//! servos.toml's `[compliance]` table. The wrist roll's stiffness and backlash are not
//! observable from the tip (the tip sits on its axis) and keep the file's values.
use nalgebra::{DMatrix, DVector, Vector3};

use super::config::{CalibError, CalibrationConfig};
use super::jog::{Cell, Touch, TouchSource};
use crate::bus::{Bus, Transport, JOINT_COUNT};
use crate::robot::compliance::LUMPED_MASSES;
use crate::robot::{Compliance, IkConfig, IkTarget, Robot};

/// Joints whose stiffness and backlash the touches observe: base yaw, shoulder, elbow and
/// wrist pitch (the tip lies on the wrist roll's axis).
pub const FITTED_JOINTS: usize = 4;
/// Load of a touch, N: 4, enough to turn the shoulder's and the wrist's gravity torques
/// (0.2-0.6 N m at the DOFBOT's reach) round so that every pitch joint crosses its band, and
/// under half the 15 kg.cm servos' rating at 0.3 m.
pub const TOUCH_LOAD_N: f64 = 4.0;
/// Tool tilts (rad, in the arm plane, from the base pose's) each point is touched from.
const TILTS_DEG: [f64; 5] = [-12.0, -6.0, 0.0, 6.0, 12.0];
/// How far inside its limits every joint of a touch pose stays, rad (0.15: the loads and the
/// jogging move the joints by a few hundredths).
const POSE_MARGIN: f64 = 0.15;
/// Base poses of the touched points (joint angles, rad): spread over the working volume
/// (left, middle and right; near and far; high and low).
const POINT_POSES: [[f64; JOINT_COUNT]; 3] = [
    [-0.5, 0.1, 0.8, 0.7, 0.0],
    [0.0, 0.35, 0.7, 0.5, 0.0],
    [0.45, -0.1, 0.9, 0.8, 0.0],
];
/// Levenberg-Marquardt iterations (the fit converges in under 10 from the start values).
const FIT_ITERATIONS: usize = 40;
/// Central-difference step of the fit's Jacobian (compliances in rad per N m around 1e-2,
/// half bands in rad around 1e-3, masses in kg around 0.1, points in m): 1e-6.
const JACOBIAN_STEP: f64 = 1e-6;
/// A touch whose residual after the first fit exceeds this many times the median is set
/// aside (3: a gear that jumped its band misses by the band, 5-10 times the read-back's
/// quantisation error).
pub const OUTLIER_FACTOR: f64 = 3.0;
/// ... and exceeds this, mm (0.2: the tip error of one raw count on two joints at full reach).
pub const OUTLIER_FLOOR_MM: f64 = 0.2;
/// Levenberg-Marquardt's first damping (1: small, gradient-like first steps, so that the
/// backlash flanks, which follow the masses, do not jump to a wrong basin).
const LM_START_DAMPING: f64 = 1.0;
/// Start value of every stiffness, N m/rad: 100, near the DOFBOT's (about 120 for 5 mm of
/// sag at full reach); from 200 the fit was seen to end in a wrong basin (one joint rigid,
/// another twice as soft).
const START_STIFFNESS: f64 = 100.0;
/// Start value of every lumped mass, kg.
const START_MASS: f64 = 0.1;

/// One touch to make: which point, the joint angles near it, and the load on the tip.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadedPose {
    /// Index of the fixed point touched.
    pub point: usize,
    /// Joint angles (rad) that put the unloaded, rigid arm's tip on the point.
    pub q: [f64; JOINT_COUNT],
    /// Load on the tool tip while touching, N, robot frame.
    pub force_n: [f64; 3],
}

/// The result of the compliance calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct ComplianceFit {
    /// The fitted model (the wrist roll's values from the input).
    pub compliance: Compliance,
    /// The touched points, robot frame, m.
    pub points: Vec<[f64; 3]>,
    /// Distance between each touch's modelled loaded tip and its point, mm.
    pub residuals_mm: Vec<f64>,
    /// RMS of the residuals of the touches kept, mm.
    pub rms_mm: f64,
    /// Touches set aside: residual over [`OUTLIER_FACTOR`] times the median (and over
    /// [`OUTLIER_FLOOR_MM`]) after a first fit (a joint whose load torque was near zero at the
    /// touch: its gear sat anywhere in the band).
    pub set_aside: usize,
}

/// The built-in touch plan: each point of [`POINT_POSES`] from each tilt of [`TILTS_DEG`]
/// under six loads of [`TOUCH_LOAD_N`] (up, down, both ways across the arm plane, both ways
/// along the arm); tilts the IK cannot reach [`POSE_MARGIN`] inside the limits are left out.
pub fn default_poses(robot: &Robot) -> Vec<LoadedPose> {
    let mut out = Vec::new();
    let exact = IkConfig {
        axis_search: false,
        limit_margin: POSE_MARGIN,
        ..IkConfig::default()
    };
    for (point, base) in POINT_POSES.iter().enumerate() {
        let pose = robot.fk(base);
        let radial = Vector3::new(pose.position.x, pose.position.y, 0.0).normalize();
        let across = Vector3::z().cross(&radial);
        for tilt in TILTS_DEG {
            let rot = nalgebra::Rotation3::new(across * tilt.to_radians());
            let target = IkTarget {
                position: pose.position,
                axis: rot * pose.axis,
                roll: Some(0.0),
            };
            let Ok(sol) = robot.ik(&target, base, &exact) else {
                continue;
            };
            let q: [f64; JOINT_COUNT] = std::array::from_fn(|k| sol.q[k]);
            for dir in [
                Vector3::z(),
                -Vector3::z(),
                across,
                -across,
                radial,
                -radial,
            ] {
                let f = dir * TOUCH_LOAD_N;
                out.push(LoadedPose {
                    point,
                    q,
                    force_n: [f.x, f.y, f.z],
                });
            }
        }
    }
    out
}

/// Touches every pose of `poses` (the operator loads the tip as each says) and fits the model,
/// starting from `start` (its wrist roll values are kept).
pub fn compliance<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    poses: &[LoadedPose],
    start: &Compliance,
    source: &mut dyn TouchSource<T>,
) -> Result<ComplianceFit, CalibError> {
    bus.torque(true)?;
    let mut touches = Vec::new();
    for (i, p) in poses.iter().enumerate() {
        let f = p.force_n;
        let label = format!(
            "compliance {i}: point {}, load [{:.1}, {:.1}, {:.1}] N",
            p.point, f[0], f[1], f[2]
        );
        match source.touch(bus, cell, &label)? {
            Some(t) => touches.push(t),
            None => {
                return Err(CalibError::Refused(format!(
                    "compliance: {} of {} touches made; make every touch",
                    touches.len(),
                    poses.len()
                )))
            }
        }
    }
    fit_compliance(cell.robot, poses, &touches, start, cell.cfg)
}

/// Parameters of the fit: compliance (rad per N m) and half band (rad) of the fitted joints,
/// the masses, then each point's coordinates.
fn unpack(theta: &DVector<f64>, start: &Compliance) -> (Compliance, Vec<Vector3<f64>>) {
    let mut c = start.clone();
    for k in 0..FITTED_JOINTS {
        c.stiffness_nm_rad[k] = 1.0 / theta[k].max(1e-9);
        c.backlash_deg[k] = 2.0 * theta[FITTED_JOINTS + k].to_degrees();
    }
    for i in 0..LUMPED_MASSES {
        c.masses_kg[i] = theta[2 * FITTED_JOINTS + i];
    }
    let first = 2 * FITTED_JOINTS + LUMPED_MASSES;
    let points = (first..theta.len())
        .step_by(3)
        .map(|i| Vector3::new(theta[i], theta[i + 1], theta[i + 2]))
        .collect();
    (c, points)
}

/// Each touch's modelled loaded tip minus its point, stacked (m).
fn residuals(
    robot: &Robot,
    poses: &[LoadedPose],
    touches: &[Touch],
    theta: &DVector<f64>,
    start: &Compliance,
    used: &[bool],
) -> DVector<f64> {
    let (c, points) = unpack(theta, start);
    let mut r = DVector::zeros(3 * touches.len());
    for (i, (p, t)) in poses.iter().zip(touches).enumerate() {
        if !used[i] {
            continue;
        }
        let tip = c.loaded_tip(robot, &t.joints, &Vector3::from(p.force_n));
        r.fixed_rows_mut::<3>(3 * i)
            .copy_from(&(tip - points[p.point]));
    }
    r
}

/// Fits the model to `touches` (one per pose of `poses`): a first fit over all, the touches
/// it leaves far off set aside, a second fit over the rest ([`solve`]).
pub fn fit_compliance(
    robot: &Robot,
    poses: &[LoadedPose],
    touches: &[Touch],
    start: &Compliance,
    cfg: &CalibrationConfig,
) -> Result<ComplianceFit, CalibError> {
    let n_points = poses.iter().map(|p| p.point + 1).max().unwrap_or(0);
    let n = 2 * FITTED_JOINTS + LUMPED_MASSES + 3 * n_points;
    if touches.len() != poses.len() || 3 * touches.len() < 2 * n {
        return Err(CalibError::Refused(format!(
            "compliance: {} touches for {} poses and {n} unknowns: need one touch per pose and \
             at least {} touches",
            touches.len(),
            poses.len(),
            (2 * n).div_ceil(3)
        )));
    }
    let mut theta: DVector<f64> = DVector::zeros(n);
    for k in 0..FITTED_JOINTS {
        theta[k] = 1.0 / START_STIFFNESS;
    }
    for i in 0..LUMPED_MASSES {
        theta[2 * FITTED_JOINTS + i] = START_MASS;
    }
    for pt in 0..n_points {
        let tips: Vec<Vector3<f64>> = poses
            .iter()
            .zip(touches)
            .filter(|(p, _)| p.point == pt)
            .map(|(_, t)| t.tip())
            .collect();
        let mean = tips.iter().sum::<Vector3<f64>>() / tips.len().max(1) as f64;
        let first = 2 * FITTED_JOINTS + LUMPED_MASSES + 3 * pt;
        theta.fixed_rows_mut::<3>(first).copy_from(&mean);
    }
    let all = vec![true; touches.len()];
    let theta = solve(robot, poses, touches, theta, start, &all);
    let per_touch = |th: &DVector<f64>, used: &[bool]| -> Vec<f64> {
        let r = residuals(robot, poses, touches, th, start, used);
        (0..touches.len())
            .map(|i| r.fixed_rows::<3>(3 * i).norm() * 1e3)
            .collect()
    };
    let first = per_touch(&theta, &all);
    let mut sorted = first.clone();
    sorted.sort_by(f64::total_cmp);
    let limit = (OUTLIER_FACTOR * sorted[sorted.len() / 2]).max(OUTLIER_FLOOR_MM);
    let used: Vec<bool> = first.iter().map(|r| *r <= limit).collect();
    let theta = solve(robot, poses, touches, theta, start, &used);
    let (compliance, points) = unpack(&theta, start);
    let residuals_mm = per_touch(&theta, &used);
    let kept: Vec<f64> = residuals_mm
        .iter()
        .zip(&used)
        .filter(|(_, u)| **u)
        .map(|(r, _)| *r)
        .collect();
    let rms_mm = super::pivot::rms(&kept);
    if rms_mm > cfg.max_pivot_rms_mm || 3 * kept.len() < 2 * n {
        return Err(CalibError::Refused(format!(
            "compliance: RMS residual {rms_mm:.3} mm (max_pivot_rms_mm {}) over {} of {} \
             touches: a touch missed its point or a load was not as listed",
            cfg.max_pivot_rms_mm,
            kept.len(),
            touches.len()
        )));
    }
    Ok(ComplianceFit {
        compliance,
        points: points.iter().map(|p| [p.x, p.y, p.z]).collect(),
        residuals_mm,
        rms_mm,
        set_aside: used.iter().filter(|u| !**u).count(),
    })
}

/// Levenberg-Marquardt from `theta` over the touches marked in `used`, with a
/// central-difference Jacobian; the compliances stay > 0, the half bands and masses >= 0.
fn solve(
    robot: &Robot,
    poses: &[LoadedPose],
    touches: &[Touch],
    mut theta: DVector<f64>,
    start: &Compliance,
    used: &[bool],
) -> DVector<f64> {
    let n = theta.len();
    let res = |th: &DVector<f64>| residuals(robot, poses, touches, th, start, used);
    let mut lambda = LM_START_DAMPING;
    for _ in 0..FIT_ITERATIONS {
        let r = res(&theta);
        let mut jac = DMatrix::zeros(r.len(), n);
        for j in 0..n {
            let (mut a, mut b) = (theta.clone(), theta.clone());
            a[j] += JACOBIAN_STEP;
            b[j] -= JACOBIAN_STEP;
            jac.set_column(j, &((res(&a) - res(&b)) / (2.0 * JACOBIAN_STEP)));
        }
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        let before = r.norm_squared();
        let mut improved = false;
        for _ in 0..10 {
            let mut m = jtj.clone();
            for j in 0..n {
                m[(j, j)] += lambda * jtj[(j, j)].max(1e-12);
            }
            let Some(step) = m.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let mut next = &theta + step;
            for j in 0..2 * FITTED_JOINTS + LUMPED_MASSES {
                next[j] = next[j].max(if j < FITTED_JOINTS { 1e-6 } else { 0.0 });
            }
            if res(&next).norm_squared() < before {
                theta = next;
                lambda = (lambda * 0.3).max(1e-9);
                improved = true;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    theta
}

/// The servos.toml text `text` with its `[compliance]` table replaced by (or appended as)
/// `c`'s; every other line kept.
pub fn patch_compliance(text: &str, c: &Compliance) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let header = |l: &str| l.trim_start().starts_with('[');
    let start = lines.iter().position(|l| l.trim() == "[compliance]");
    let mut kept: Vec<&str> = match start {
        Some(s) => {
            let end = (s + 1..lines.len())
                .find(|&i| header(lines[i]))
                .unwrap_or(lines.len());
            lines[..s].iter().chain(&lines[end..]).copied().collect()
        }
        None => lines,
    };
    while kept.last().is_some_and(|l| l.trim().is_empty()) {
        kept.pop();
    }
    let list = |v: &[f64]| {
        let s: Vec<String> = v.iter().map(|x| format!("{x:.6}")).collect();
        format!("[{}]", s.join(", "))
    };
    let table = format!(
        "\n[compliance]\n# written by `polishbot calibrate compliance` (docs/CALIBRATION.md)\n\
         stiffness_nm_rad = {}\nbacklash_deg = {}\nmasses_kg = {}\n",
        list(&c.stiffness_nm_rad),
        list(&c.backlash_deg),
        list(&c.masses_kg)
    );
    kept.join("\n") + "\n" + &table
}

/// Writes `out` from `input` (servos.toml) with the `[compliance]` table of `c` and reads it
/// back.
pub fn write_compliance(
    input: &std::path::Path,
    out: &std::path::Path,
    c: &Compliance,
) -> Result<(), CalibError> {
    let text = std::fs::read_to_string(input).map_err(|e| CalibError::file(input, e))?;
    super::files::write(out, &patch_compliance(&text, c))?;
    crate::robot::Servos::load(out)?;
    Ok(())
}

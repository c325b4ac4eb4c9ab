//! Compliance calibration (issue 50): the tool tip touches a few fixed points, each from
//! several tool tilts and under loads of both signs (pushed up, down and along the arm both
//! ways, each with a push across the arm one way or the other, of two sizes); the touches'
//! read-back joint angles, the known loads and the unknown points give the joints'
//! stiffness, backlash and the arm's lumped masses, written to servos.toml's `[compliance]`
//! table. The wrist roll's stiffness and backlash are not observable from the tip (the tip
//! sits on its axis) and keep the file's values.
//!
//! The fit ([`fit_compliance`]) alternates two linear least-squares solves, linearised at the
//! current loaded joint angles: with the masses fixed (so every touch's load torque and gear
//! flank are known) the compliances, half bands and points; with the compliances fixed the
//! masses, half bands and points. A joint's backlash shows as a step of its whole band
//! between touches whose load torque on it has opposite signs, its stiffness as the slope
//! over touches of one sign, so the loads are sized to give both on every joint. Touches
//! where a joint's load torque is under [`TRUST_TORQUE_NM`] (its gear may sit anywhere in the
//! band) do not enter the fit.
use nalgebra::{DMatrix, DVector, Matrix3xX, Vector3};

use super::config::{CalibError, CalibrationConfig};
use super::jog::{Cell, Touch, TouchSource};
pub use super::touch_plan::{default_poses, touch_plan, LoadedPose, TOUCH_LOAD_N};
use crate::bus::{Bus, Transport};
use crate::robot::compliance::{FLANK_TORQUE_NM, LUMPED_MASSES};
use crate::robot::{Compliance, Robot};

/// Joints whose stiffness and backlash the touches observe: base yaw, shoulder, elbow and
/// wrist pitch (the tip lies on the wrist roll's axis).
pub const FITTED_JOINTS: usize = 4;
/// Rounds of the alternating fit (it settles to 1e-3 deg and 0.1 N m/rad within 6 on the
/// simulated cell).
const FIT_ROUNDS: usize = 12;
/// Load torque, N m, under which a touch is left out of the fit: 0.05, ten times the torque
/// under which a gear was seen to leave its flank and five times the planner's
/// [`FLANK_TORQUE_NM`] (the fitted masses may be a few tens of grams off while they settle).
pub const TRUST_TORQUE_NM: f64 = 0.05;
/// A touch whose residual after the first fit exceeds this many times the median is set
/// aside (3: a gear that jumped its band misses by the band, 5-10 times the read-back's
/// quantisation error).
pub const OUTLIER_FACTOR: f64 = 3.0;
/// ... and exceeds this, mm (0.2: the tip error of one raw count on two joints at full reach).
pub const OUTLIER_FLOOR_MM: f64 = 0.2;
/// Start value of every stiffness, N m/rad: 100, near the DOFBOT's (about 120 for 5 mm of
/// sag at full reach).
const START_STIFFNESS: f64 = 100.0;
/// Start value of every lumped mass, kg, and the value the masses are weakly drawn to.
const START_MASS: f64 = 0.1;
/// Weight of the pull towards [`START_MASS`], m of tip per kg: 1e-4 (0.1 kg off costs as much
/// as one touch missing by 0.01 mm; it only holds masses the touches cannot tell apart).
const MASS_PRIOR_M_PER_KG: f64 = 1e-4;
/// Largest lumped mass, kg (a DOFBOT link with its servo weighs under 0.2 kg).
const MAX_MASS_KG: f64 = 2.0;

/// The result of the compliance calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct ComplianceFit {
    /// The fitted model (the wrist roll's values from the input).
    pub compliance: Compliance,
    /// One standard deviation of each fitted joint's stiffness, N m/rad.
    pub stiffness_sd: [f64; FITTED_JOINTS],
    /// One standard deviation of each fitted joint's backlash, degrees.
    pub backlash_sd: [f64; FITTED_JOINTS],
    /// The touched points, robot frame, m.
    pub points: Vec<[f64; 3]>,
    /// Distance between each touch's modelled loaded tip and its point, mm.
    pub residuals_mm: Vec<f64>,
    /// RMS of the residuals of the touches kept, mm.
    pub rms_mm: f64,
    /// Touches left out: a joint's load torque under [`TRUST_TORQUE_NM`], or a residual over
    /// [`OUTLIER_FACTOR`] times the median (and over [`OUTLIER_FLOOR_MM`]) after a first fit.
    pub set_aside: usize,
}

/// The model a cell without a `[compliance]` table starts from: every stiffness
/// [`START_STIFFNESS`], no backlash, every mass [`START_MASS`] (the wrist roll keeps these:
/// the touches do not observe it).
pub fn start_model() -> Compliance {
    Compliance {
        stiffness_nm_rad: [START_STIFFNESS; 5],
        backlash_deg: [0.0; 5],
        masses_kg: [START_MASS; LUMPED_MASSES],
    }
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
    let touches = touch_all(bus, cell, poses, source, "compliance")?;
    fit_compliance(cell.robot, poses, &touches, start, cell.cfg)
}

/// One touch of every pose of `poses`, in order, from `source` (the operator loads the tip as
/// each pose says; `routine` labels the prompts and the refusal when a touch is not made).
pub fn touch_all<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    poses: &[LoadedPose],
    source: &mut dyn TouchSource<T>,
    routine: &str,
) -> Result<Vec<Touch>, CalibError> {
    bus.torque(true)?;
    let mut touches = Vec::new();
    for (i, p) in poses.iter().enumerate() {
        let f = p.force_n;
        let label = format!(
            "{routine} {i}: point {}, load [{:.1}, {:.1}, {:.1}] N",
            p.point, f[0], f[1], f[2]
        );
        match source.touch(bus, cell, &label)? {
            Some(t) => touches.push(t),
            None => {
                return Err(CalibError::Refused(format!(
                    "{routine}: {} of {} touches made; make every touch",
                    touches.len(),
                    poses.len()
                )))
            }
        }
    }
    Ok(touches)
}

/// What the fit needs of one touch: read-back joints, the load's torques about each joint,
/// and each lumped mass's torques per kg.
struct Sample {
    point: usize,
    q: Vec<f64>,
    force: Vector3<f64>,
    contact: Vec<f64>,
    per_kg: [Vec<f64>; LUMPED_MASSES],
}

/// The current estimate: compliance (rad per N m) and half band (rad) of the fitted joints,
/// the masses (kg) and the points (m).
#[derive(Clone)]
struct Estimate {
    c: [f64; FITTED_JOINTS],
    h: [f64; FITTED_JOINTS],
    m: [f64; LUMPED_MASSES],
    points: Vec<Vector3<f64>>,
}

impl Estimate {
    fn torques(&self, s: &Sample) -> [f64; FITTED_JOINTS] {
        std::array::from_fn(|k| {
            s.contact[k]
                + (0..LUMPED_MASSES)
                    .map(|j| self.m[j] * s.per_kg[j][k])
                    .sum::<f64>()
        })
    }

    /// Output minus servo angle of the fitted joints at a touch, and the flank signs.
    fn deflection(&self, s: &Sample) -> ([f64; FITTED_JOINTS], [f64; FITTED_JOINTS]) {
        let tau = self.torques(s);
        let flank = tau.map(|t| (t / FLANK_TORQUE_NM).clamp(-1.0, 1.0));
        (
            std::array::from_fn(|k| self.c[k] * tau[k] + self.h[k] * flank[k]),
            flank,
        )
    }

    fn trusted(&self, s: &Sample) -> bool {
        self.torques(s).iter().all(|t| t.abs() >= TRUST_TORQUE_NM)
    }

    fn compliance(&self, start: &Compliance) -> Compliance {
        let mut c = start.clone();
        for k in 0..FITTED_JOINTS {
            c.stiffness_nm_rad[k] = 1.0 / self.c[k].max(MIN_COMPLIANCE);
            c.backlash_deg[k] = 2.0 * self.h[k].max(0.0).to_degrees();
        }
        c.masses_kg = self.m;
        c
    }
}

/// Which parameters a linear solve fits (besides the half bands and the points).
#[derive(Clone, Copy, PartialEq)]
enum Unknown {
    Compliances,
    Masses,
}

/// One linearised least-squares solve over the touches marked in `used`: the
/// new estimate and the standard deviations of its first 2 x [`FITTED_JOINTS`] parameters.
/// With `pin`, a solve that puts a compliance or half band below its floor ([`MIN_COMPLIANCE`],
/// no band) is made again with it pinned there, until none is (clamped afterwards instead, the
/// ideal arm's fit kept 0.7 mm residuals and a 0.11 degree band the others had balanced).
fn solve(
    robot: &Robot,
    samples: &[Sample],
    used: &[bool],
    est: &Estimate,
    unknown: Unknown,
    pin: bool,
) -> Option<(Estimate, Vec<f64>)> {
    let mut pins = [false; 2 * FITTED_JOINTS];
    loop {
        let (next, sd, raw) = solve_pinned(robot, samples, used, est, unknown, &pins)?;
        let mut more = false;
        for (j, held) in pins.iter_mut().enumerate() {
            let floor = match (j < FITTED_JOINTS, unknown) {
                (true, Unknown::Compliances) => MIN_COMPLIANCE,
                (true, Unknown::Masses) => continue,
                (false, _) => 0.0,
            };
            if pin && !*held && raw[j] < floor {
                *held = true;
                more = true;
            }
        }
        if !more {
            return Some((next, sd));
        }
    }
}

/// Smallest compliance of a fitted joint, rad per N m (1e-6: a million N m/rad, rigid to the
/// touches' resolution).
const MIN_COMPLIANCE: f64 = 1e-6;
/// Weight of the row that pins a compliance or half band at its floor, against the touch rows'
/// Jacobian-times-torque entries of 0.01-1 (1e3: the pinned value moves by under 1e-3 of what
/// the touches pull).
const PIN_WEIGHT: f64 = 1e3;

/// [`solve`] with the parameters marked in `pins` (compliances, then half bands) held at their
/// floors; also the solved parameters before any floor.
fn solve_pinned(
    robot: &Robot,
    samples: &[Sample],
    used: &[bool],
    est: &Estimate,
    unknown: Unknown,
    pins: &[bool; 2 * FITTED_JOINTS],
) -> Option<(Estimate, Vec<f64>, Vec<f64>)> {
    let rows: Vec<&Sample> = samples
        .iter()
        .zip(used)
        .filter(|(_, u)| **u)
        .map(|(s, _)| s)
        .collect();
    let first = 2 * FITTED_JOINTS;
    let n = first + 3 * est.points.len();
    let prior = if unknown == Unknown::Masses {
        LUMPED_MASSES
    } else {
        0
    };
    let pinned: Vec<usize> = (0..first).filter(|&j| pins[j]).collect();
    let extra = prior + pinned.len();
    let mut a = DMatrix::zeros(3 * rows.len() + extra, n);
    let mut b = DVector::zeros(3 * rows.len() + extra);
    for (i, s) in rows.iter().enumerate() {
        let (d, flank) = est.deflection(s);
        let mut at = s.q.clone();
        for (a, dk) in at.iter_mut().zip(d) {
            *a += dk;
        }
        let jac: Matrix3xX<f64> = robot.jacobian(&at).fixed_rows::<3>(0).into_owned();
        let mut known = robot.fk(&at).position;
        for (k, dk) in d.iter().enumerate() {
            known -= jac.column(k) * *dk;
            if unknown == Unknown::Masses {
                known += jac.column(k) * est.c[k] * s.contact[k];
            }
        }
        let tau = est.torques(s);
        for r in 0..3 {
            for k in 0..FITTED_JOINTS {
                a[(3 * i + r, k)] = match unknown {
                    Unknown::Compliances => jac[(r, k)] * tau[k],
                    Unknown::Masses => (0..FITTED_JOINTS)
                        .map(|kk| jac[(r, kk)] * est.c[kk] * s.per_kg[k][kk])
                        .sum(),
                };
                a[(3 * i + r, FITTED_JOINTS + k)] = jac[(r, k)] * flank[k];
            }
            a[(3 * i + r, first + 3 * s.point + r)] = -1.0;
            b[3 * i + r] = -known[r];
        }
    }
    for j in 0..prior {
        a[(3 * rows.len() + j, j)] = MASS_PRIOR_M_PER_KG;
        b[3 * rows.len() + j] = MASS_PRIOR_M_PER_KG * START_MASS;
    }
    for (i, &j) in pinned.iter().enumerate() {
        let floor = if j < FITTED_JOINTS {
            MIN_COMPLIANCE
        } else {
            0.0
        };
        a[(3 * rows.len() + prior + i, j)] = PIN_WEIGHT;
        b[3 * rows.len() + prior + i] = PIN_WEIGHT * floor;
    }
    let x = a.clone().svd(true, true).solve(&b, 1e-15).ok()?;
    let dof = (3 * rows.len()).checked_sub(n).filter(|d| *d > 0)?;
    let var = (&a * &x - &b).norm_squared() / dof as f64;
    let cov = (a.transpose() * &a).try_inverse()?;
    let sd = (0..first).map(|j| (var * cov[(j, j)]).sqrt()).collect();
    let mut next = est.clone();
    for k in 0..FITTED_JOINTS {
        match unknown {
            Unknown::Compliances => next.c[k] = x[k].max(MIN_COMPLIANCE),
            Unknown::Masses => next.m[k] = x[k].clamp(0.0, MAX_MASS_KG),
        }
        next.h[k] = x[FITTED_JOINTS + k];
    }
    for (p, pt) in next.points.iter_mut().enumerate() {
        *pt = Vector3::new(x[first + 3 * p], x[first + 3 * p + 1], x[first + 3 * p + 2]);
    }
    Some((next, sd, x.iter().take(first).copied().collect()))
}

/// Rounds at the end of [`rounds`] whose solves keep the compliances and bands at or above
/// their floors (3: on the ideal arm the pinned set settles in two; a free solve's negative
/// values in the early rounds are flanks still read with the start masses, and pinning them
/// there led the worn arm's fit astray, 39 mm RMS).
const PINNED_ROUNDS: usize = 3;

/// Which touches a round's solves use.
#[derive(Clone, Copy)]
enum Rows<'a> {
    /// Those marked, less those whose load torques the current estimate leaves under
    /// [`TRUST_TORQUE_NM`] (the first fit, while the masses settle).
    Trusted(&'a [bool]),
    /// Exactly those marked, whatever the estimate (the second fit: a set that changed from
    /// solve to solve as the masses moved made the alternation jump between objectives; with
    /// 1 degree of backlash on the pitch joints the second fit ran off to 110-290 mm RMS
    /// from a first fit that had settled on the planted bands within 0.07 degree).
    Fixed(&'a [bool]),
}

impl Rows<'_> {
    fn mask(&self, samples: &[Sample], est: &Estimate) -> Vec<bool> {
        match self {
            Rows::Trusted(used) => (samples.iter().zip(*used))
                .map(|(s, u)| *u && est.trusted(s))
                .collect(),
            Rows::Fixed(used) => used.to_vec(),
        }
    }
}

/// Median distance (m) between the modelled loaded tip of each touch marked in `set` and its
/// point, with the model `est` gives as written out (`start`'s wrist roll, bands not below 0).
fn median_miss(
    robot: &Robot,
    samples: &[Sample],
    set: &[bool],
    est: &Estimate,
    start: &Compliance,
) -> f64 {
    let model = est.compliance(start);
    let mut misses: Vec<f64> = (samples.iter().zip(set))
        .filter(|(_, u)| **u)
        .map(|(s, _)| (model.loaded_tip(robot, &s.q, &s.force) - est.points[s.point]).norm())
        .collect();
    misses.sort_by(f64::total_cmp);
    misses.get(misses.len() / 2).copied().unwrap_or(0.0)
}

/// A fit whose last round misses its touches ([`median_miss`]) more than this many times its
/// best round's has run off, and the best round stands (2: a settled fit changes its median
/// miss by a few percent from round to round; a fit run off misses by tens of millimetres).
const RUN_OFF_FACTOR: f64 = 2.0;

/// [`FIT_ROUNDS`] rounds of the two solves from `est` over the touches `rows` gives, then
/// [`PINNED_ROUNDS`] with the floors held; the last round's estimate and its compliance
/// solve's deviations, unless it has run off ([`RUN_OFF_FACTOR`]; scored over the touches of
/// [`Rows::Fixed`], else over all): then the best round's. The alternation can run off from
/// a settled estimate (a mass driven to its bound turns load torques, and with them flanks,
/// round): measured on the simulated arm with 1 degree of backlash on the pitch joints (the
/// second fit, 110-290 mm RMS after a first fit within 0.07 degree of the planted bands) and
/// with 10 mm of sag at full reach (the first fit, 53 mm).
fn rounds(
    robot: &Robot,
    samples: &[Sample],
    rows: Rows,
    mut est: Estimate,
    start: &Compliance,
) -> Result<(Estimate, Vec<f64>), CalibError> {
    let all = vec![true; samples.len()];
    let scored = match rows {
        Rows::Fixed(set) => set,
        Rows::Trusted(_) => &all,
    };
    let mut sd = Vec::new();
    let mut best: Option<(f64, Estimate, Vec<f64>)> = None;
    let mut last = f64::INFINITY;
    for round in 0..FIT_ROUNDS + PINNED_ROUNDS {
        let pin = round >= FIT_ROUNDS;
        let stuck = || {
            CalibError::Refused(
                "compliance: the touches do not determine the model (too few with every joint \
                 loaded; check the loads)"
                    .into(),
            )
        };
        let used = rows.mask(samples, &est);
        (est, sd) =
            solve(robot, samples, &used, &est, Unknown::Compliances, pin).ok_or_else(stuck)?;
        let used = rows.mask(samples, &est);
        est = solve(robot, samples, &used, &est, Unknown::Masses, pin)
            .ok_or_else(stuck)?
            .0;
        last = median_miss(robot, samples, scored, &est, start);
        if best.as_ref().is_none_or(|b| last < b.0) {
            best = Some((last, est.clone(), sd.clone()));
        }
    }
    match best {
        Some((miss, e, s)) if last > RUN_OFF_FACTOR * miss => Ok((e, s)),
        _ => Ok((est, sd)),
    }
}

/// Fits the model to `touches` (one per pose of `poses`): a first fit over all, the touches
/// it leaves far off set aside, a second fit over the rest.
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
    let unit = |j: Option<usize>| Compliance {
        stiffness_nm_rad: [1.0; 5],
        backlash_deg: [0.0; 5],
        masses_kg: std::array::from_fn(|i| f64::from(u8::from(Some(i) == j))),
    };
    let samples: Vec<Sample> = poses
        .iter()
        .zip(touches)
        .map(|(p, t)| Sample {
            point: p.point,
            q: t.joints.to_vec(),
            force: Vector3::from(p.force_n),
            contact: unit(None).torques(robot, &t.joints, &Vector3::from(p.force_n)),
            per_kg: std::array::from_fn(|j| {
                unit(Some(j)).torques(robot, &t.joints, &Vector3::zeros())
            }),
        })
        .collect();
    let mut points = vec![Vector3::zeros(); n_points];
    for (pt, sum) in points.iter_mut().enumerate() {
        let tips: Vec<Vector3<f64>> = poses
            .iter()
            .zip(touches)
            .filter(|(p, _)| p.point == pt)
            .map(|(_, t)| t.tip())
            .collect();
        *sum = tips.iter().sum::<Vector3<f64>>() / tips.len().max(1) as f64;
    }
    let est = Estimate {
        c: [1.0 / START_STIFFNESS; FITTED_JOINTS],
        h: [0.0; FITTED_JOINTS],
        m: [START_MASS; LUMPED_MASSES],
        points,
    };
    let all = vec![true; touches.len()];
    let (est, _) = rounds(robot, &samples, Rows::Trusted(&all), est, start)?;
    let per_touch = |e: &Estimate| -> Vec<f64> {
        let c = e.compliance(start);
        poses
            .iter()
            .zip(touches)
            .map(|(p, t)| {
                let tip = c.loaded_tip(robot, &t.joints, &Vector3::from(p.force_n));
                (tip - e.points[p.point]).norm() * 1e3
            })
            .collect()
    };
    let first = per_touch(&est);
    let trusted: Vec<bool> = samples.iter().map(|s| est.trusted(s)).collect();
    let mut sorted: Vec<f64> = first
        .iter()
        .zip(&trusted)
        .filter(|(_, t)| **t)
        .map(|(r, _)| *r)
        .collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let limit = (OUTLIER_FACTOR * median).max(OUTLIER_FLOOR_MM);
    let kept_mask: Vec<bool> = (first.iter().zip(&trusted))
        .map(|(r, t)| *t && *r <= limit)
        .collect();
    let (est, sd) = rounds(robot, &samples, Rows::Fixed(&kept_mask), est, start)?;
    let residuals_mm = per_touch(&est);
    let kept: Vec<f64> = residuals_mm
        .iter()
        .zip(&kept_mask)
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
        compliance: est.compliance(start),
        stiffness_sd: std::array::from_fn(|k| sd[k] / (est.c[k] * est.c[k])),
        backlash_sd: std::array::from_fn(|k| 2.0 * sd[FITTED_JOINTS + k].to_degrees()),
        points: est.points.iter().map(|p| [p.x, p.y, p.z]).collect(),
        residuals_mm,
        rms_mm,
        set_aside: kept_mask.iter().filter(|u| !**u).count(),
    })
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

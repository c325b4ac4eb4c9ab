//! The simulated cell's grinding settings (`[sim.grinding]` of `run`'s config): the true tool,
//! removal law and part mounting that `crate::sim::grind` grinds a virtual part with. They live
//! with the simulated board's other settings ([`crate::sim::SimOptions`]) so that the flow runs
//! one way: the simulator reads them; nothing under `plan/` does.
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// The true tool, removal law and part mounting of the simulated cell (`[sim.grinding]`).
/// Numbers are the simulated cell's truth, chosen, not measured: `calibrate removal` is what
/// measures a real cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GrindConfig {
    /// The nominal Preston coefficient, mm^2/N (= 1/MPa): the removal rate in mm/s is k x
    /// pressure (MPa) x speed (mm/s) for exponents 1. Default [`NOMINAL_PRESTON_K`], the
    /// shipped calibration/tool.toml's `preston_k_mm2_n`.
    pub preston_k: f64,
    /// True k / nominal k (default [`DEFAULT_K_FACTOR`], 1.3: an uncalibrated tool whose true
    /// k is 30 % above the shipped tool.toml's, which the loop's refit must learn).
    pub k_factor: f64,
    /// Amplitude of the local variation of the true k, share (default 0.10: +-10 %).
    pub k_noise: f64,
    /// Wavelength of that variation over the part, mm (default 8: a few patches per defect).
    pub k_noise_wavelength_mm: f64,
    /// Seed of the variation field and of the rescan (default 29).
    pub seed: u64,
    /// Preston exponent on pressure (default 1.1).
    pub pressure_exponent: f64,
    /// Preston exponent on speed (default 0.9).
    pub speed_exponent: f64,
    /// Pressure at which the law with exponents equals the linear one, MPa (default 1).
    pub reference_pressure_mpa: f64,
    /// Speed at which the law with exponents equals the linear one, mm/s (default 500).
    pub reference_speed_mm_s: f64,
    /// Spring rate of the compliant tool mount, N/mm: force = rate x penetration (default 1,
    /// the shipped tool.toml's mount: the simulated cell carries the same spring as the tool it
    /// grinds with; at the former 20 N/mm the planner's 2 mm preload pressed with 40 N).
    pub spring_rate_n_mm: f64,
    /// Effective (Hertz) modulus of the abrasive ball against the part, MPa (default
    /// [`NOMINAL_MODULUS_MPA`], 20: the shipped tool.toml's rubber-bonded abrasive; patch
    /// radius 0.6 mm at 2 N on a 3 mm ball).
    pub modulus_mpa: f64,
    /// Spindle speed, rev/min (default [`NOMINAL_SPINDLE_RPM`], 10000: the shipped
    /// tool.toml's).
    pub spindle_rpm: f64,
    /// Radius of the ball, mm (default 3, the shipped tool.toml's).
    pub ball_radius_mm: f64,
    /// The direction in which the simulated tool's mount gives (default
    /// [`MountGive::SpindleAxis`]: the shipped tool, a rotary tool on a spring-loaded,
    /// axially floating holder).
    pub compliance_direction: MountGive,
    /// Ball centre in the last link's frame (arm_link5), mm; the spindle turns about that
    /// frame's z (default [0, 0, 19.3], the shipped tool.toml's).
    pub tip_offset_mm: [f64; 3],
    /// Hidden offset of the part on its fixture, reference frame, mm (default 0).
    pub mount_offset_mm: [f64; 3],
    /// Hidden rotation of the part on its fixture, roll pitch yaw about the reference frame's
    /// x, y, z, degrees (default 0).
    pub mount_rotation_deg: [f64; 3],
    /// Scanner noise of the rescan (after.ply), mm per coordinate (default 0.015, synth's).
    pub rescan_noise_mm: f64,
    /// Outliers of the rescan, share of points (default 0.01, synth's).
    pub rescan_outliers: f64,
    /// Largest translation of the rescan's random pose, mm (default 60, synth's).
    pub rescan_max_translation_mm: f64,
    /// Gear backlash per joint (servos 1-5), the full width of the dead band, degrees
    /// (default [`DEFAULT_BACKLASH_DEG`], 0.5 each: shared/DOFBOT.md's simulated-arm default;
    /// up to 1 on a worn arm). The gear rests on the flank its load torque pushes it to
    /// (`crate::sim::grind::slack`).
    pub backlash_deg: [f64; 5],
    /// Droop of the tool under gravity with the stretched arm held horizontal, mm (default
    /// [`DEFAULT_SAG_MM`], 5: shared/DOFBOT.md's "5..10 mm at full reach"): sets the joints'
    /// stiffness, the sag of any pose follows from its gravity torques; what the workcell
    /// calibration saw near the part is absorbed.
    pub sag_full_reach_mm: f64,
    /// The servos' tracking lag behind their commands, ms (default [`DEFAULT_LAG_MS`], 20:
    /// one bus period, shared/DOFBOT.md's "a command lag of one bus period or more").
    pub tracking_lag_ms: f64,
    /// An ideal arm: no backlash, no sag, no lag whatever the keys above say (default false;
    /// for tests that take the planner's own errors apart from the arm's).
    pub ideal_arm: bool,
}

impl Default for GrindConfig {
    fn default() -> Self {
        GrindConfig {
            preston_k: NOMINAL_PRESTON_K,
            k_factor: DEFAULT_K_FACTOR,
            k_noise: 0.10,
            k_noise_wavelength_mm: 8.0,
            seed: 29,
            pressure_exponent: 1.1,
            speed_exponent: 0.9,
            reference_pressure_mpa: 1.0,
            reference_speed_mm_s: 500.0,
            spring_rate_n_mm: 1.0,
            modulus_mpa: NOMINAL_MODULUS_MPA,
            spindle_rpm: NOMINAL_SPINDLE_RPM,
            ball_radius_mm: 3.0,
            compliance_direction: MountGive::SpindleAxis,
            tip_offset_mm: [0.0, 0.0, 19.3],
            mount_offset_mm: [0.0; 3],
            mount_rotation_deg: [0.0; 3],
            rescan_noise_mm: 0.015,
            rescan_outliers: 0.01,
            rescan_max_translation_mm: 60.0,
            backlash_deg: [DEFAULT_BACKLASH_DEG; 5],
            sag_full_reach_mm: DEFAULT_SAG_MM,
            tracking_lag_ms: DEFAULT_LAG_MS,
            ideal_arm: false,
        }
    }
}

/// How the simulated tool's compliant mount gives (`[sim.grinding] compliance_direction`),
/// the simulator's own statement of the tool, apart from the planner's tool.toml.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MountGive {
    /// The ball centre stays where the arm puts it and the spring takes the penetration along
    /// the surface normal (the simulator before issue 50).
    SurfaceNormal,
    /// The ball slides back along the spindle axis until it touches the surface
    /// (`crate::sim::grind::part`, docs/ALGORITHMS.md "Simulated grinding").
    SpindleAxis,
}

/// Nominal Preston coefficient of the simulated tool, mm^2/N: the shipped
/// calibration/tool.toml's `[removal] preston_k_mm2_n` (5e-6), written here rather than read
/// from the planner's file, so that the simulator's truth never follows the planner's model.
/// The former default, 1e-4 (20 x the tool file's, at half its modulus and spindle speed),
/// ground the demo's virtual part 3.24 mm deep in one pass (measured, issue 29).
pub const NOMINAL_PRESTON_K: f64 = 5e-6;
/// True k / nominal k by default: 1.3, the issue's "planner's k 30 % off the simulator's true
/// k"; an uncalibrated tool that the loop's refit of k must learn.
pub const DEFAULT_K_FACTOR: f64 = 1.3;
/// Nominal Hertz modulus of the simulated abrasive, MPa: the shipped tool.toml's
/// `[removal] modulus_mpa` (20).
pub const NOMINAL_MODULUS_MPA: f64 = 20.0;
/// Nominal spindle speed of the simulated tool, rev/min: the shipped tool.toml's
/// `[removal] spindle_rpm` (10000).
pub const NOMINAL_SPINDLE_RPM: f64 = 10000.0;

/// Default backlash per joint, degrees: 0.5, the full dead band shared/DOFBOT.md gives the
/// simulated arm by default (its "Reported accuracy": up to 1 deg per servo; an open ROS 2
/// driver for this arm left 0.3-0.9 deg of joint error under load). Before issue 50 it was 0:
/// with 1 degree and 5 mm of centred sag a grind of tests/cycle.rs's seed-3 case fitted k at
/// 0.56 x the planner's instead of 1.57 x and ground a pit to -0.159 mm (issue 29).
pub const DEFAULT_BACKLASH_DEG: f64 = 0.5;
/// Default droop at full horizontal reach, mm: 5, shared/DOFBOT.md's "sag 5..10 mm at full
/// reach", its simulated-arm default.
pub const DEFAULT_SAG_MM: f64 = 5.0;
/// Default tracking lag, ms: 20, one period of the stream's 20 ms bus period
/// (shared/DOFBOT.md: "a command lag of one bus period or more").
pub const DEFAULT_LAG_MS: f64 = 20.0;
/// Largest tracking lag accepted, ms: a second behind is a stalled servo.
const MAX_LAG_MS: f64 = 1000.0;
/// Largest backlash, degrees, and sag, mm, accepted: more is a broken arm, not a worn one.
const MAX_BACKLASH_DEG: f64 = 10.0;
const MAX_SAG_MM: f64 = 50.0;

/// Largest hidden mounting offset, mm, and rotation, degrees: a part misplaced by more is
/// not on the fixture.
const MAX_MOUNT_MM: f64 = 50.0;
const MAX_MOUNT_DEG: f64 = 45.0;
/// Accepted Preston coefficients, mm^2/N: the shipped tool's 5e-6 and the former simulator
/// default 1e-4 (which ground 3 mm deep in one pass) lie well inside; 1e300 made NaN
/// rescans, and below 1e-10 nothing measurable is ground in any run.
const PRESTON_K_RANGE: (f64, f64) = (1e-10, 1e-2);
/// Accepted Hertz moduli of the abrasive (and reference pressures), MPa: from a soft foam
/// (1e-3 MPa) to steel (2e5 MPa); 1e-300 made the contact solve run without end.
const MODULUS_RANGE: (f64, f64) = (1e-3, 1e6);
/// Accepted ball radii, mm: grinding balls on a DOFBOT are a few millimetres; 0.1-50 mm
/// covers every burr that fits the arm (1e300 made the simulated contact run without end).
const BALL_RADIUS_RANGE: (f64, f64) = (0.1, 50.0);
/// Largest exponent accepted: Preston exponents seen in the literature lie within 0.5..2.
const MAX_EXPONENT: f64 = 3.0;

impl GrindConfig {
    /// Checks every setting; the message names the key in backticks.
    pub fn check(&self) -> Result<(), String> {
        let scalars: [(&str, f64, (f64, f64), &str); 17] = [
            ("preston_k", self.preston_k, PRESTON_K_RANGE, "mm^2/N"),
            ("k_factor", self.k_factor, (0.01, 100.0), ""),
            ("k_noise", self.k_noise, (0.0, 0.99), "(share)"),
            (
                "k_noise_wavelength_mm",
                self.k_noise_wavelength_mm,
                (0.01, 1e4),
                "mm",
            ),
            (
                "pressure_exponent",
                self.pressure_exponent,
                (0.0, MAX_EXPONENT),
                "",
            ),
            (
                "speed_exponent",
                self.speed_exponent,
                (0.0, MAX_EXPONENT),
                "",
            ),
            (
                "reference_pressure_mpa",
                self.reference_pressure_mpa,
                (1e-3, MODULUS_RANGE.1),
                "MPa",
            ),
            (
                "reference_speed_mm_s",
                self.reference_speed_mm_s,
                (1e-3, 1e6),
                "mm/s",
            ),
            (
                "spring_rate_n_mm",
                self.spring_rate_n_mm,
                (1e-3, 1e4),
                "N/mm",
            ),
            ("modulus_mpa", self.modulus_mpa, MODULUS_RANGE, "MPa"),
            ("spindle_rpm", self.spindle_rpm, (0.0, 1e6), "rev/min"),
            (
                "ball_radius_mm",
                self.ball_radius_mm,
                BALL_RADIUS_RANGE,
                "mm",
            ),
            ("rescan_noise_mm", self.rescan_noise_mm, (0.0, 5.0), "mm"),
            (
                "rescan_outliers",
                self.rescan_outliers,
                (0.0, 0.49),
                "(share)",
            ),
            (
                "rescan_max_translation_mm",
                self.rescan_max_translation_mm,
                (0.0, 1e4),
                "mm",
            ),
            (
                "tracking_lag_ms",
                self.tracking_lag_ms,
                (0.0, MAX_LAG_MS),
                "ms",
            ),
            (
                "sag_full_reach_mm",
                self.sag_full_reach_mm,
                (0.0, MAX_SAG_MM),
                "mm",
            ),
        ];
        let scalar = scalars.iter().find_map(|&(key, v, (lo, hi), unit)| {
            (!(v.is_finite() && (lo..=hi).contains(&v)))
                .then(|| format!("`{key}` = {v:?} {unit} is outside {lo:?}..={hi:?} {unit}"))
        });
        match scalar.or_else(|| self.array_problem()) {
            Some(m) => Err(m),
            None => Ok(()),
        }
    }

    /// The first array setting out of its range, named with its key.
    fn array_problem(&self) -> Option<String> {
        let arrays = [
            ("tip_offset_mm", &self.tip_offset_mm[..], 1000.0, "mm"),
            (
                "mount_offset_mm",
                &self.mount_offset_mm[..],
                MAX_MOUNT_MM,
                "mm",
            ),
            (
                "mount_rotation_deg",
                &self.mount_rotation_deg[..],
                MAX_MOUNT_DEG,
                "deg",
            ),
        ];
        if let Some(x) = self
            .backlash_deg
            .iter()
            .find(|x| !(x.is_finite() && (0.0..=MAX_BACKLASH_DEG).contains(*x)))
        {
            return Some(format!(
                "`backlash_deg` has {x:?} deg, outside 0..={MAX_BACKLASH_DEG} deg"
            ));
        }
        arrays.into_iter().find_map(|(key, v, max, unit)| {
            v.iter()
                .find(|x| !(x.is_finite() && x.abs() <= max))
                .map(|x| format!("`{key}` has {x:?} {unit}, outside -{max}..={max} {unit}"))
        })
    }

    /// The servos' tracking lag, s (0 on an ideal arm).
    pub fn tracking_lag_s(&self) -> f64 {
        match self.ideal_arm {
            true => 0.0,
            false => self.tracking_lag_ms * 1e-3,
        }
    }

    /// The part's true pose on the fixture: the nominal `robot_from_reference` (metres)
    /// moved by the hidden offsets, as a matrix on reference points in metres.
    pub fn true_robot_from_reference(&self, nominal: &Matrix4<f64>) -> Matrix4<f64> {
        let [rx, ry, rz] = self.mount_rotation_deg.map(f64::to_radians);
        let t = Vector3::from(self.mount_offset_mm) * 1e-3;
        let offset = Isometry3::from_parts(
            Translation3::from(t),
            UnitQuaternion::from_euler_angles(rx, ry, rz),
        );
        nominal * offset.to_homogeneous()
    }
}

//! The board's mechanics between the servo and the tool that the servo read-back cannot see,
//! as shared/DOFBOT.md describes the arm ("backlash up to 1 deg per servo, ... sag 5..10 mm at
//! full reach"; its closing paragraph gives the simulated arm's defaults):
//! - gear backlash per joint whose output rests on the flank the load torque pushes it to
//!   (the link and tool weight plus the tool's contact force): the joint crosses its dead band
//!   only where that torque reverses, and where the torque is near zero (the base yaw and the
//!   wrist roll under gravity) it trails the motion by half the band;
//! - sag from joint compliance: each joint turns by its load torque over its stiffness (an
//!   elastostatic model), the stiffness set so that the stretched arm held horizontal droops
//!   `sag_full_reach_mm` at the tool.
//!
//! Parameters: `backlash_deg`, `sag_full_reach_mm`, `ideal_arm` of `[sim.grinding]`; the masses
//! below are the simulator's own. Nothing in the planner reads them.
use nalgebra::{Point3, Vector3};

use super::fk;
use crate::sim::GrindConfig;

/// Mass of a bus servo, kg: 0.065, a 15 kg.cm serial bus servo of the DOFBOT's class
/// (chosen; Yahboom publishes no mass). The servos of joints 3 and 4 sit on those joints' axes.
pub const SERVO_MASS_KG: f64 = 0.065;
/// Mass of one link's bracket, kg: 0.03 (chosen: a few aluminium sheet brackets), at the
/// link's middle.
pub const LINK_MASS_KG: f64 = 0.03;
/// Mass of the wrist (roll servo and its bracket), kg: the servo plus a bracket, at the middle
/// of the last link.
pub const WRIST_MASS_KG: f64 = SERVO_MASS_KG + LINK_MASS_KG;
/// Mass of the spindle and its compliant holder, kg: 0.15 (chosen: a small DC spindle), at the
/// ball centre.
pub const TOOL_MASS_KG: f64 = 0.15;
/// Gravity, m/s^2.
pub const GRAVITY_M_S2: f64 = 9.81;
/// Load torque, N m, under which a joint's gear is not pushed onto a flank and the output
/// trails the motion instead: 0.005, the torque of 5 g at 0.1 m, well under the arm's gravity
/// torques at the shoulder, elbow and wrist pitch (0.1-0.6 N m) and above the base yaw's and
/// wrist roll's (zero under gravity).
pub const HOLD_TORQUE_NM: f64 = 0.005;
/// Step of the numeric derivative that sets the stiffness, rad per N m.
const COMPLIANCE_PROBE: f64 = 1e-6;

/// A point load on the arm: where (robot frame, m), the force (N), and the last joint (0-based)
/// whose motion carries it (the joints up to it feel its torque).
type Load = (Vector3<f64>, Vector3<f64>, usize);

/// The arm's masses at joint angles `q` (the tool ball centre `ball`) and the tool's contact
/// force `contact_n` (N, robot frame, on the ball).
fn loads(q: &[f64; 5], ball: Vector3<f64>, contact_n: Vector3<f64>) -> [Load; 6] {
    let (j, _) = fk::joints(q);
    let w = |kg: f64| Vector3::new(0.0, 0.0, -kg * GRAVITY_M_S2);
    let mid = |a: usize, b: usize| 0.5 * (j[a].0 + j[b].0);
    [
        (mid(1, 2), w(LINK_MASS_KG), 1),
        (j[2].0, w(SERVO_MASS_KG), 1),
        (mid(2, 3), w(LINK_MASS_KG), 2),
        (j[3].0, w(SERVO_MASS_KG), 2),
        (mid(3, 4), w(WRIST_MASS_KG), 3),
        (ball, w(TOOL_MASS_KG) + contact_n, 4),
    ]
}

/// Load torque about each joint's axis at joint angles `q` with the contact force `contact_n`
/// (N, robot frame) on the ball `tip_m` (last link's frame), N m; positive turns the joint
/// towards larger angles.
pub fn load_torques(q: &[f64; 5], tip_m: &[f64; 3], contact_n: Vector3<f64>) -> [f64; 5] {
    let (j, last) = fk::joints(q);
    let ball = (last * Point3::from(Vector3::from(*tip_m))).coords;
    let all = loads(q, ball, contact_n);
    std::array::from_fn(|k| {
        let (o, a) = j[k];
        all.iter()
            .filter(|(_, _, after)| *after >= k)
            .map(|(p, f, _)| a.dot(&(p - o).cross(f)))
            .sum()
    })
}

/// Gear backlash: each joint's output sits on the flank its load torque pushes it to, or,
/// where that torque is under [`HOLD_TORQUE_NM`], follows its servo through the dead band
/// (starting centred), trailing a motion by half the band.
#[derive(Debug, Clone)]
pub struct Backlash {
    half_rad: [f64; 5],
    output: Option<[f64; 5]>,
}

impl Backlash {
    /// A dead band of `width_deg` per joint (0: none).
    pub fn new(width_deg: &[f64; 5]) -> Self {
        Backlash {
            half_rad: width_deg.map(|w| 0.5 * w.to_radians()),
            output: None,
        }
    }

    /// The joints' output angles for the servo-side angles `q` (rad) under load torques
    /// `torque` (N m); calls must follow the servos' motion in time.
    pub fn follow(&mut self, q: [f64; 5], torque: [f64; 5]) -> [f64; 5] {
        let out = std::array::from_fn(|k| {
            let h = self.half_rad[k];
            if torque[k].abs() > HOLD_TORQUE_NM {
                q[k] + h * torque[k].signum()
            } else {
                self.output
                    .map_or(q[k], |prev| prev[k].clamp(q[k] - h, q[k] + h))
            }
        });
        self.output = Some(out);
        out
    }
}

/// The simulated arm's mechanics: backlash and joint compliance (one stiffness for every
/// joint, set from the sag at full reach), for the tool ball `tip_m`.
#[derive(Debug, Clone)]
pub struct Arm {
    backlash: Backlash,
    /// Joint compliance, rad per N m (1 / stiffness).
    compliance: f64,
    tip_m: [f64; 3],
}

impl Arm {
    /// The arm of `cfg` (ideal when `cfg.ideal_arm`): its backlash, and the compliance that
    /// droops the stretched horizontal arm `sag_full_reach_mm` at the ball.
    pub fn new(cfg: &GrindConfig) -> Self {
        let tip_m = cfg.tip_offset_mm.map(|v| v * 1e-3);
        let (band, sag) = match cfg.ideal_arm {
            true => ([0.0; 5], 0.0),
            false => (cfg.backlash_deg, cfg.sag_full_reach_mm),
        };
        Arm {
            backlash: Backlash::new(&band),
            compliance: sag * 1e-3 / droop_per_compliance(&tip_m),
            tip_m,
        }
    }

    /// The ball centre in the last link's frame, m.
    pub fn tip_m(&self) -> [f64; 3] {
        self.tip_m
    }

    /// Joint stiffness, N m per rad (infinite for a rigid arm).
    pub fn stiffness_nm_rad(&self) -> f64 {
        1.0 / self.compliance
    }

    /// Ball centre (robot frame, m) and tool axis with the servos at `q` (rad) and the
    /// contact force `contact_n` (N, robot frame) on the ball; calls must follow time.
    pub fn tool(&mut self, q: [f64; 5], contact_n: Vector3<f64>) -> (Point3<f64>, Vector3<f64>) {
        let torque = load_torques(&q, &self.tip_m, contact_n);
        let out = self.backlash.follow(q, torque);
        self.bent(out, torque)
    }

    /// Ball centre and tool axis of a joint pose held still at `q` under `contact_n`, each
    /// loaded joint on its flank (no history: for the calibration the sim's cell absorbed).
    pub fn held(&self, q: [f64; 5], contact_n: Vector3<f64>) -> (Point3<f64>, Vector3<f64>) {
        let torque = load_torques(&q, &self.tip_m, contact_n);
        let out = self.backlash.clone().follow(q, torque);
        self.bent(out, torque)
    }

    fn bent(&self, q: [f64; 5], torque: [f64; 5]) -> (Point3<f64>, Vector3<f64>) {
        let q: [f64; 5] = std::array::from_fn(|k| q[k] + self.compliance * torque[k]);
        fk::tool(&q, &self.tip_m)
    }
}

/// The stretched arm held horizontal (shoulder at 90 degrees, elbow and wrist straight),
/// joint angles, rad.
pub const HORIZONTAL: [f64; 5] = [0.0, std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0];

/// Drop of the ball (m) of the horizontal arm per unit joint compliance (rad per N m) under
/// its own weight.
pub fn droop_per_compliance(tip_m: &[f64; 3]) -> f64 {
    let q = HORIZONTAL;
    let torque = load_torques(&q, tip_m, Vector3::zeros());
    let bent: [f64; 5] = std::array::from_fn(|k| q[k] + COMPLIANCE_PROBE * torque[k]);
    (fk::tool(&q, tip_m).0.z - fk::tool(&bent, tip_m).0.z) / COMPLIANCE_PROBE
}

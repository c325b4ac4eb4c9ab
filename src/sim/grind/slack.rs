//! The board's mechanics between the servo and the tool that the servo read-back cannot see:
//! gear backlash per joint and the arm's sag under gravity (shared/DOFBOT.md: "backlash up to
//! 1 deg per servo, ... sag 5..10 mm at full reach"). Parameters: `backlash_deg`,
//! `sag_full_reach_mm` of `[sim.grinding]`; nothing in the planner reads them.
use nalgebra::Point3;

use super::fk::DOFBOT_JOINTS;

/// Gear backlash: each joint's output follows its servo through a dead band of the joint's
/// width, centred at the start (the arm starts at rest where it was zeroed); moving one way
/// the output trails the servo by half the width, and a reversal crosses the band first.
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

    /// The joints' output angles for the servo-side angles `q` (rad); calls must follow
    /// the servos' motion in time.
    pub fn follow(&mut self, q: [f64; 5]) -> [f64; 5] {
        let out = match self.output {
            None => q,
            Some(prev) => std::array::from_fn(|k| {
                let h = self.half_rad[k];
                prev[k].clamp(q[k] - h, q[k] + h)
            }),
        };
        self.output = Some(out);
        out
    }
}

/// Horizontal reach of the stretched arm, m: the DOFBOT's link lengths from the shoulder
/// (joint 2) to the last link's origin, plus the tool ball centre `tip_z_m` past it.
pub fn full_reach_m(tip_z_m: f64) -> f64 {
    DOFBOT_JOINTS[2..]
        .iter()
        .map(|(xyz, _, _)| xyz[0].hypot(xyz[1]))
        .sum::<f64>()
        + tip_z_m
}

/// Gravity sag: the servos' compliance lets the arm droop by a torque-proportional angle,
/// the torque grows with the horizontal reach r, and the drop at the tool with r times that
/// angle: droop(r) = `sag_full_mm` (r / full reach)^2. The workcell calibration touches the
/// fixture with the arm sagging, so the droop at the part's origin (`r0_m`) is absorbed; what
/// moves the tool is the difference over the part.
#[derive(Debug, Clone, Copy)]
pub struct Sag {
    /// Droop at full reach, m.
    full_m: f64,
    /// Full reach, m.
    reach_m: f64,
    /// Horizontal reach of the part's origin, m.
    r0_m: f64,
}

impl Sag {
    /// Sag of `sag_full_mm` at full reach (with the tool ball `tip_z_m` past the last link),
    /// absorbed at the horizontal reach `r0_m` of the part's origin.
    pub fn new(sag_full_mm: f64, tip_z_m: f64, r0_m: f64) -> Self {
        Sag {
            full_m: sag_full_mm * 1e-3,
            reach_m: full_reach_m(tip_z_m),
            r0_m,
        }
    }

    /// The ball centre `c` (robot frame, m, z up) moved by the droop.
    pub fn apply(&self, c: Point3<f64>) -> Point3<f64> {
        let rel = |r: f64| (r / self.reach_m).powi(2);
        let drop = self.full_m * (rel(c.x.hypot(c.y)) - rel(self.r0_m));
        Point3::new(c.x, c.y, c.z - drop)
    }
}

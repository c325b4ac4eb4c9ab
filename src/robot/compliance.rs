//! The planner's elastostatic and backlash model of the arm (issue 50): each joint's output
//! turns from its servo's angle by its load torque over its stiffness, plus half its gear's
//! dead band towards the side the load torque pushes it (the flank). Loads: the arm's weight
//! as four lumped masses (at the elbow, wrist-pitch and wrist-roll joints' origins and at the
//! tool tip) and the tool's contact force at the tip. The parameters come from servos.toml's
//! `[compliance]` table, written by `calibrate compliance` from touch-offs
//! (docs/CALIBRATION.md); nothing here reads the simulator.
//!
//! [`Compliance::command`] turns the joint angles the loaded arm must reach into the servo
//! angles to command; [`Compliance::loaded_tip`] is the other way round.
pub use super::calibration::{Compliance, LUMPED_MASSES};
use super::model::Robot;
use nalgebra::Vector3;

/// Gravity, m/s^2.
pub const GRAVITY_M_S2: f64 = 9.81;
/// Load torque, N m, over which the model trusts the flank a joint sits on: under it the
/// backlash term scales down linearly to 0 (the gear may sit anywhere in its band; the
/// planner assumes the middle), or, for an arm in motion, towards the flank the motion left
/// the gear on (`Compliance::deflection_trailing`). 0.01: a tenth of the smallest gravity
/// torque of the pitch joints over the DOFBOT's working volume, and small against the 2 N
/// contact force's torques (0.2-0.6 N m), so loaded joints get the whole half band.
pub const FLANK_TORQUE_NM: f64 = 0.01;
/// Fixed-point passes of [`Compliance::command`]: the deflection changes by stiffness-times
/// torque-slope (under 1 %) per pass, so three passes leave under 1e-6 of it.
const COMMAND_PASSES: usize = 3;

impl Compliance {
    /// Load torque about each joint's axis (N m, positive turns the joint towards larger
    /// angles) at joint angles `q` with the contact force `force_n` (N, robot frame) on the
    /// tool tip.
    pub fn torques(&self, robot: &Robot, q: &[f64], force_n: &Vector3<f64>) -> Vec<f64> {
        let (frames, axes) = robot.joint_frames(q);
        let tip = robot.fk(q).position;
        let weight = |kg: f64| Vector3::new(0.0, 0.0, -kg * GRAVITY_M_S2);
        // (point, force, index of the first joint NOT upstream of it)
        let mut loads: Vec<(Vector3<f64>, Vector3<f64>, usize)> = Vec::new();
        for (i, m) in self.masses_kg.iter().enumerate().take(LUMPED_MASSES - 1) {
            let j = (i + 2).min(frames.len() - 1);
            loads.push((frames[j].translation.vector, weight(*m), j));
        }
        loads.push((
            tip,
            weight(self.masses_kg[LUMPED_MASSES - 1]) + force_n,
            frames.len(),
        ));
        (0..frames.len())
            .map(|k| {
                let o = frames[k].translation.vector;
                loads
                    .iter()
                    .filter(|(_, _, first_not)| k < *first_not)
                    .map(|(p, f, _)| axes[k].dot(&(p - o).cross(f)))
                    .sum()
            })
            .collect()
    }

    /// Output minus servo angle of each joint (rad) at servo angles `q` under `force_n`.
    pub fn deflection(&self, robot: &Robot, q: &[f64], force_n: &Vector3<f64>) -> Vec<f64> {
        self.deflection_trailing(robot, q, force_n, &[])
    }

    /// [`Compliance::deflection`] of an arm in motion: a joint whose load torque `t` is under
    /// [`FLANK_TORQUE_NM`] sits on its load's flank if `t` is over the torque that holds its
    /// gear, and else on the flank its motion left it on, `trail` (per joint, -1 or 1, see
    /// `motion::compensate`: a gear's output trails its servo through the dead band when no
    /// load holds it). That holding torque is not known; taken as anywhere in
    /// 0..`FLANK_TORQUE_NM` alike, the expected flank is `t / F + (1 - |t| / F) trail`: the
    /// trail's flank where the two agree, the load's at `F`. With no trail (an empty slice,
    /// or 0) that is the share of the half band the torque gives (the middle at no torque).
    pub fn deflection_trailing(
        &self,
        robot: &Robot,
        q: &[f64],
        force_n: &Vector3<f64>,
        trail: &[f64],
    ) -> Vec<f64> {
        let tau = self.torques(robot, q, force_n);
        tau.iter()
            .enumerate()
            .map(|(k, t)| {
                let held = (t / FLANK_TORQUE_NM).clamp(-1.0, 1.0);
                let flank = expected_flank(held, trail.get(k).copied().unwrap_or(0.0));
                t / self.stiffness_nm_rad[k] + 0.5 * self.backlash_deg[k].to_radians() * flank
            })
            .collect()
    }

    /// The joints' output angles (rad) with the servos at `q` under `force_n`.
    pub fn loaded(&self, robot: &Robot, q: &[f64], force_n: &Vector3<f64>) -> Vec<f64> {
        let d = self.deflection(robot, q, force_n);
        q.iter().zip(&d).map(|(a, b)| a + b).collect()
    }

    /// Tool tip (robot frame, m) with the servos at `q` under `force_n`.
    pub fn loaded_tip(&self, robot: &Robot, q: &[f64], force_n: &Vector3<f64>) -> Vector3<f64> {
        robot.fk(&self.loaded(robot, q, force_n)).position
    }

    /// Servo angles (rad) that put the loaded joints (under `force_n`) at `q_out`.
    pub fn command(&self, robot: &Robot, q_out: &[f64], force_n: &Vector3<f64>) -> Vec<f64> {
        self.command_trailing(robot, q_out, force_n, &[])
    }

    /// [`Compliance::command`] of an arm in motion whose unloaded gears trail it on the
    /// flanks `trail` ([`Compliance::deflection_trailing`]).
    pub fn command_trailing(
        &self,
        robot: &Robot,
        q_out: &[f64],
        force_n: &Vector3<f64>,
        trail: &[f64],
    ) -> Vec<f64> {
        let mut c = q_out.to_vec();
        for _ in 0..COMMAND_PASSES {
            let d = self.deflection_trailing(robot, &c, force_n, trail);
            c = q_out.iter().zip(&d).map(|(a, b)| a - b).collect();
        }
        c
    }
}

/// The flank (-1..1) a gear is expected on under the load torque `held` (its share of
/// [`FLANK_TORQUE_NM`], -1..1) after its motion left it on `trail` (-1, 1; 0: unknown), for a
/// holding torque anywhere in 0..`FLANK_TORQUE_NM` alike
/// ([`Compliance::deflection_trailing`]).
fn expected_flank(held: f64, trail: f64) -> f64 {
    held + (1.0 - held.abs()) * trail
}

#[cfg(test)]
mod tests {
    use super::expected_flank;

    /// The trail's flank where load and trail agree or no load is felt, the load's at the
    /// trusted torque, the middle halfway when they disagree; the torque's share alone with
    /// no trail.
    #[test]
    fn the_expected_flank_runs_from_the_trail_to_the_load() {
        for (held, trail, want) in [
            (0.0, 1.0, 1.0),
            (0.4, 1.0, 1.0),
            (-0.4, -1.0, -1.0),
            (1.0, -1.0, 1.0),
            (-0.5, 1.0, 0.0),
            (0.25, -1.0, -0.5),
            (0.3, 0.0, 0.3),
        ] {
            assert!(
                (expected_flank(held, trail) - want).abs() < 1e-12,
                "{held} {trail}"
            );
        }
    }
}

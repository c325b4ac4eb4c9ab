//! Time-optimal point-to-point joint moves (the Ruckig algorithm, rsruckig) and the sampled
//! joint trajectory the bus streams. Method: docs/ALGORITHMS.md, section "Robot".
use rsruckig::prelude::{
    DurationDiscretization, InputParameter, Ruckig, Synchronization, ThrowErrorHandler, Trajectory,
};
use serde::{Deserialize, Serialize};

use crate::robot::JointSpec;

/// Settings of the joint trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrajectoryConfig {
    /// Sample period, seconds: one bus frame per sample (0.02, the bus period).
    pub period: f64,
    /// Round every move's duration up to a whole number of periods (true), so that the last
    /// sample of a move lands exactly on its target at rest.
    pub discrete_duration: bool,
}

impl Default for TrajectoryConfig {
    fn default() -> Self {
        TrajectoryConfig {
            period: 0.02,
            discrete_duration: true,
        }
    }
}

/// Per-joint kinematic limits of a move.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// Velocity limits, rad/s.
    pub velocity: Vec<f64>,
    /// Acceleration limits, rad/s^2.
    pub acceleration: Vec<f64>,
    /// Jerk limits, rad/s^3.
    pub jerk: Vec<f64>,
}

impl Limits {
    /// The limits of the robot's joints.
    pub fn from_joints(joints: &[JointSpec]) -> Self {
        Limits {
            velocity: joints.iter().map(|j| j.velocity).collect(),
            acceleration: joints.iter().map(|j| j.acceleration).collect(),
            jerk: joints.iter().map(|j| j.jerk).collect(),
        }
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.velocity.len()
    }
}

/// Why a move could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// The inputs have the wrong length or are not finite.
    #[error("bad move input: {0}")]
    Input(String),
    /// Ruckig rejected the input or failed.
    #[error("ruckig: {0}")]
    Ruckig(String),
}

/// A time-optimal, time-synchronised rest-to-rest move between two joint positions.
pub struct Move {
    trajectory: Trajectory<0>,
    dof: usize,
}

impl std::fmt::Debug for Move {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Move")
            .field("duration", &self.duration())
            .field("dof", &self.dof)
            .finish()
    }
}

impl Move {
    /// Computes the move from `from` to `to` within `limits` (Ruckig, position interface,
    /// time synchronisation, zero velocity and acceleration at both ends).
    pub fn new(
        from: &[f64],
        to: &[f64],
        limits: &Limits,
        config: &TrajectoryConfig,
    ) -> Result<Self, TrajectoryError> {
        let rest = vec![0.0; from.len()];
        Move::through(from, &rest, to, &rest, limits, config)
    }

    /// The time-optimal move from `from` at velocity `from_velocity` to `to` at
    /// `to_velocity`, zero acceleration at both ends (Ruckig's position interface with target
    /// velocities: a removal stroke passes its contacts without stopping).
    pub fn through(
        from: &[f64],
        from_velocity: &[f64],
        to: &[f64],
        to_velocity: &[f64],
        limits: &Limits,
        config: &TrajectoryConfig,
    ) -> Result<Self, TrajectoryError> {
        let dof = limits.dof();
        let lengths = [
            from.len(),
            to.len(),
            from_velocity.len(),
            to_velocity.len(),
            limits.acceleration.len(),
            limits.jerk.len(),
        ];
        if lengths.iter().any(|n| *n != dof) || dof == 0 {
            return Err(TrajectoryError::Input(format!(
                "lengths {lengths:?}, expected {dof}"
            )));
        }
        let all = from
            .iter()
            .chain(to)
            .chain(from_velocity)
            .chain(to_velocity);
        if all.clone().any(|v| !v.is_finite()) {
            return Err(TrajectoryError::Input("positions must be finite".into()));
        }
        let mut otg = Ruckig::<0, ThrowErrorHandler>::new(Some(dof), config.period);
        let mut input = InputParameter::<0>::new(Some(dof));
        input.synchronization = Synchronization::Time;
        input.duration_discretization = if config.discrete_duration {
            DurationDiscretization::Discrete
        } else {
            DurationDiscretization::Continuous
        };
        for i in 0..dof {
            input.current_position[i] = from[i];
            input.current_velocity[i] = from_velocity[i];
            input.target_position[i] = to[i];
            input.target_velocity[i] = to_velocity[i];
            input.max_velocity[i] = limits.velocity[i];
            input.max_acceleration[i] = limits.acceleration[i];
            input.max_jerk[i] = limits.jerk[i];
        }
        let mut trajectory = Trajectory::<0>::new(Some(dof));
        otg.calculate(&input, &mut trajectory)
            .map_err(|e| TrajectoryError::Ruckig(e.to_string()))?;
        Ok(Move { trajectory, dof })
    }

    /// Duration, seconds.
    pub fn duration(&self) -> f64 {
        self.trajectory.get_duration()
    }

    /// Lowest and highest position of the first axis over the whole move (Ruckig's exact
    /// extrema): a move that overshoots its target or backs up shows here.
    pub fn position_range(&mut self) -> (f64, f64) {
        let b = &self.trajectory.get_position_extrema()[0];
        (b.min, b.max)
    }

    /// Joint positions at time `t` (clamped to [0, duration]).
    pub fn position_at(&self, t: f64, out: &mut [f64]) {
        self.state_at(t, out, &mut vec![0.0; self.dof]);
    }

    /// Joint positions and velocities at time `t` (clamped to [0, duration]).
    pub fn state_at(&self, t: f64, position: &mut [f64], velocity: &mut [f64]) {
        let mut pos = rsruckig::prelude::DataArrayOrVec::<f64, 0>::new(Some(self.dof), 0.0);
        let mut vel = rsruckig::prelude::DataArrayOrVec::<f64, 0>::new(Some(self.dof), 0.0);
        let t = t.clamp(0.0, self.duration());
        self.trajectory.at_time(
            t,
            &mut Some(&mut pos),
            &mut Some(&mut vel),
            &mut None,
            &mut None,
            &mut None,
        );
        for (o, p) in position.iter_mut().zip(pos.iter()) {
            *o = *p;
        }
        for (o, v) in velocity.iter_mut().zip(vel.iter()) {
            *o = *v;
        }
    }
}

/// Joint positions sampled at a fixed period: sample k is at time k * period.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectory {
    /// Sample period, seconds.
    pub period: f64,
    /// Joints per sample.
    pub dof: usize,
    /// Samples, row-major (`dof` values each), radians.
    pub positions: Vec<f64>,
}

impl JointTrajectory {
    /// A trajectory holding one sample, `start`.
    pub fn starting_at(start: &[f64], period: f64) -> Self {
        JointTrajectory {
            period,
            dof: start.len(),
            positions: start.to_vec(),
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions.len() / self.dof.max(1)
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Sample `i`.
    pub fn sample(&self, i: usize) -> &[f64] {
        &self.positions[i * self.dof..(i + 1) * self.dof]
    }

    /// The last sample.
    pub fn last(&self) -> &[f64] {
        self.sample(self.len() - 1)
    }

    /// Time of the last sample, seconds.
    pub fn duration(&self) -> f64 {
        self.len().saturating_sub(1) as f64 * self.period
    }

    /// Appends a sample one period after the last.
    pub fn push(&mut self, q: &[f64]) {
        assert_eq!(q.len(), self.dof, "sample has the wrong number of joints");
        self.positions.extend_from_slice(q);
    }

    /// Appends `mv` (which must start at the last sample) sampled every period; the final
    /// sample is the move's target. Returns the number of samples added.
    pub fn append_move(&mut self, mv: &Move) -> usize {
        let steps = (mv.duration() / self.period - 1e-9).ceil().max(0.0) as usize;
        let mut q = vec![0.0; self.dof];
        for k in 1..=steps {
            mv.position_at(k as f64 * self.period, &mut q);
            self.positions.extend_from_slice(&q);
        }
        steps
    }

    /// Appends time-optimal rest-to-rest moves from the last sample through every waypoint.
    pub fn append_moves(
        &mut self,
        waypoints: &[Vec<f64>],
        limits: &Limits,
        config: &TrajectoryConfig,
    ) -> Result<(), TrajectoryError> {
        for w in waypoints {
            let from = self.last().to_vec();
            let mv = Move::new(&from, w, limits, config)?;
            self.append_move(&mv);
        }
        Ok(())
    }
}

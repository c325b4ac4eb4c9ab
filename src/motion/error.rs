//! Errors of the planner: bad input files (naming the file and the place), calibration
//! faults, and plans that fail validation (listing every offending point).
use std::path::Path;

use super::report::UnreachablePoint;
use super::trajectory::TrajectoryError;
use super::validate::Violation;
use crate::repair::InputError;
use crate::robot::RobotError;

/// Why a plan could not be made or loaded.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// An input file is unreadable or holds a bad value.
    #[error(transparent)]
    Input(#[from] InputError),
    /// The robot calibration files.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// A move could not be computed.
    #[error("{context}: {source}")]
    Trajectory {
        /// Which move.
        context: String,
        /// Ruckig's complaint.
        source: TrajectoryError,
    },
    /// Samples break joint, servo or speed limits.
    #[error("plan fails validation: {} violation(s): {}", .0.len(), list(.0))]
    Invalid(Vec<Violation>),
    /// Targets the arm cannot reach, when the configuration demands full reach.
    #[error("{} unreachable target(s): {}", .0.len(), list(.0))]
    Unreachable(Vec<UnreachablePoint>),
    /// A free motion cannot be made without a collision.
    #[error("collision: {0}")]
    Collision(String),
    /// Samples bring the tool or the arm into the part or a solid.
    #[error("plan fails the collision check: {} sample(s): {}", .0.len(), list(.0))]
    Collides(Vec<super::report::Collision>),
    /// The servo command stream cannot be built or does not match the samples.
    #[error("servo frames: {0}")]
    Frames(String),
    /// A setting is out of range.
    #[error("config: {0}")]
    Config(String),
}

/// Why the removal planner leaves a region out (`dwell::set_dwell`); each message is the one
/// the plan's report gives its contacts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DwellError {
    /// Every contact presses with more force than a servo can hold (the first one's reason:
    /// the point, the joint, the torque).
    #[error("region left out by the removal planner: {0}")]
    Overloaded(String),
    /// No core point lies within the tool's reach of the region's contacts.
    #[error(
        "region left out by the removal planner: no core point within the tool's reach \
         ({patch_radius_mm:.3} mm patch radius) of its {contacts} contacts, so no removal can \
         be planned or predicted"
    )]
    NoCoreInReach {
        /// The tool's patch radius, mm.
        patch_radius_mm: f64,
        /// The region's contacts.
        contacts: usize,
    },
    /// The dwell solve failed (its reason).
    #[error("region left out by the removal planner: {0}")]
    Unsolved(String),
    /// The removal's limits (`removal::cap`) lifted every contact: each, even at its shortest
    /// dwell, removes more than a point in its reach may lose.
    #[error(
        "region left out by the removal planner: nothing to grind at an allowance of \
         {allowance_mm:.3} mm (the highest deviation in reach is {highest_mm:.3} mm; every \
         contact would remove less than passing at full feed)"
    )]
    NothingToGrind {
        /// The allowance solved at, mm.
        allowance_mm: f64,
        /// The highest deviation over the core points in reach, mm.
        highest_mm: f64,
    },
    /// No contact of the region was reached on its walk, so nothing was solved.
    #[error("region left out by the removal planner: no contact of it was reached")]
    NothingWalked,
}

impl PlanError {
    /// A bad value at `place` of `file`.
    pub fn input(file: &Path, place: impl Into<String>, message: impl Into<String>) -> Self {
        PlanError::Input(InputError::new(file, place, message))
    }
}

/// The first ten items, `; `-separated, and how many more.
fn list<T: std::fmt::Display>(items: &[T]) -> String {
    let mut s: Vec<String> = items.iter().take(10).map(|v| v.to_string()).collect();
    if items.len() > 10 {
        s.push(format!("... and {} more", items.len() - 10));
    }
    s.join("; ")
}

#[cfg(test)]
mod tests {
    use super::DwellError;

    /// Each reason reads as the message `dwell::set_dwell` wrote before it was typed (the
    /// format strings of ef28d62, their lines wrapped here).
    #[test]
    fn a_dwell_error_reads_as_the_message_it_replaced() {
        let lead = "region left out by the removal planner";
        let (allowance, highest, radius, contacts) = (0.0304, 0.2178, 0.6082, 17);
        let nothing = DwellError::NothingToGrind {
            allowance_mm: allowance,
            highest_mm: highest,
        };
        let was = format!(
            "{lead}: nothing to grind at an allowance of {allowance:.3} mm (the highest \
             deviation in reach is {highest:.3} mm; every contact would remove less than \
             passing at full feed)"
        );
        assert_eq!(nothing.to_string(), was);
        let none_in_reach = DwellError::NoCoreInReach {
            patch_radius_mm: radius,
            contacts,
        };
        let was = format!(
            "region left out by the removal planner: no core point within the tool's reach \
             ({radius:.3} mm patch radius) of its {contacts} contacts, so no removal can be \
             planned or predicted"
        );
        assert_eq!(none_in_reach.to_string(), was);
        let why = "joint 2 holds 0.31 N m of 0.25";
        let was = format!("region left out by the removal planner: {why}");
        assert_eq!(DwellError::Overloaded(why.into()).to_string(), was);
        assert_eq!(DwellError::Unsolved(why.into()).to_string(), was);
    }
}

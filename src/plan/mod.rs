//! Planning: from tool poses to a validated, time-optimal joint trajectory sampled at the bus
//! period. (Grinding passes from regions.json come with issue 7's planner half.)
pub mod trajectory;
pub mod validate;

pub use trajectory::{JointTrajectory, Limits, Move, TrajectoryConfig, TrajectoryError};
pub use validate::{validate, LimitKind, ValidationConfig, Violation};

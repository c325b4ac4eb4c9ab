//! The cell: a checked plan streamed to the arm. It sits above `plan` (which makes the plan and
//! its frames as data) and `bus` (which sends frames and reads servos back); `run` and `demo`
//! call it. Method: docs/ALGORITHMS.md, "Cell: streaming a plan".
//!
//! Front function: [`execute`] with a [`RunConfig`] (result: [`RunReport`]); the measured
//! shift of a grind's removal, [`removal_shift::register`]; how far beyond its plan's
//! footprint it reached, [`removal_reach::measure`]; where it removed off the plan,
//! [`stray::stray`].
mod reach;
pub mod removal_reach;
pub mod removal_shift;
pub mod stray;
mod stream;

pub use reach::{reachable_sites, SITE_AXIS_MARGIN_DEG};
pub use stream::{execute, steps, RunConfig, RunReport, Step};

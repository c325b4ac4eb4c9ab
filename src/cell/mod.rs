//! The cell: a checked plan streamed to the arm. It sits above `plan` (which makes the plan and
//! its frames as data) and `bus` (which sends frames and reads servos back); `run` and `demo`
//! call it. Method: docs/ALGORITHMS.md, "Cell: streaming a plan".
//!
//! Front functions: [`execute`] with a [`RunConfig`] (result: [`RunReport`]); the closed
//! loop's stop rule [`cycle::decide`] with a [`cycle::CycleConfig`]; the removal calibration
//! [`removal_fit::fit`] with a [`removal_fit::FitConfig`].
pub mod cycle;
mod reach;
pub mod removal_shift;
mod stream;

pub use reach::{reachable_sites, SITE_AXIS_MARGIN_DEG};
pub use stream::{execute, steps, RunConfig, RunReport, Step};

//! The closed scan-grind-rescan loop (`polishbot cycle`, and `demo`'s loop) as a library
//! function: inspect, plan, grind and rescan (through an [`Executor`]: the simulated or the
//! real arm), refit Preston's k, until the part is within tolerance, an iteration makes no
//! progress or the iterations run out. Method: docs/ALGORITHMS.md, "The closed loop".
//!
//! Front function: [`run_cycle`] with a [`CycleConfig`]; one [`IterationRecord`] per
//! inspection ([`record`]), the stop rule [`decide`]. The planning stage with its files
//! ([`plan_into`]) and the k refit ([`refit`]) are here too: `plan` and `calibrate removal`
//! share them with the loop.
mod config;
mod engine;
mod figures;
pub mod ledger;
mod plan_stage;
pub mod record;
pub mod refit;

pub use config::{CycleConfig, DEFAULT_MAX_ITERATIONS, DEFAULT_MIN_PROGRESS, LEDGER_FROM_GRIND};
pub use engine::{
    planner_input, pose_rows, run_cycle, with_tool, CycleOutcome, Executor, First, GrindJob,
    LoopInputs, Rescan, FINE_RADIUS_MM,
};
pub use plan_stage::{plan_inputs, plan_into, PlanFileConfig, Planned};
pub use record::{
    achieved_residual, decide, decide_plan, planned_regions, predicted_rms, table_html, table_json,
    table_row, table_text, IterationRecord, Measured, Outcome, TABLE_HEADER,
};
pub use refit::one_line;

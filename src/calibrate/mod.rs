//! Calibration routines of a cell, in the order a new cell runs them (docs/CALIBRATION.md):
//!
//! 1. [`servo_offsets`]: the arm is held in the zero pose (torque off), each servo is read
//!    several times, and the servo angle at joint zero becomes its `zero_offset_deg`
//!    (servos.toml).
//! 2. [`tool_tip`]: the tool tip touches one fixed point from several orientations; the pivot
//!    least squares gives the tip in the flange frame (tool.toml).
//! 3. [`workcell()`]: the tool tip touches the fixture's fiducials; a rigid fit (no scale) of
//!    their reference-frame coordinates onto the touched positions gives
//!    `robot_from_reference` (workcell.toml).
//! 4. [`turntable::turntable`] (cells with a part turntable): the tool tip touches one fiducial
//!    on the table at several table angles; a plane and circle fit give the table's axis and
//!    centre (workcell.toml's `[turntable]`).
//! 5. [`verify()`]: moves through check poses, reads back, reports per-servo and tool-tip error;
//!    [`verify::verify_table`] turns a cell's turntable to check angles and reads it back.
//!
//! 6. [`compliance::compliance`]: the tool tip touches fixed points from several tilts under
//!    loads of both signs; a least-squares fit gives each joint's stiffness and backlash and
//!    the arm's lumped masses (servos.toml's `[compliance]`); `verify` checks a cell's table
//!    against loaded touch-offs of its own ([`compliance_check`]) and refuses a table they
//!    contradict.
//!
//! Touches come from a [`TouchSource`]: the interactive jog terminal ([`jog::JogTerminal`])
//! or a list of joint targets ([`jog::Scripted`]). All settings: [`CalibrationConfig`].
pub mod compliance;
pub mod compliance_check;
pub mod config;
pub mod files;
pub mod jog;
pub mod pivot;
pub mod read;
pub mod servos;
pub mod touch_plan;
pub mod turntable;
pub mod verify;
pub mod workcell;

pub use config::{CalibError, CalibrationConfig};
pub use files::{load_targets, Fiducial, Fixture};
pub use jog::{JogTerminal, Scripted, Touch, TouchSource};
pub use pivot::{tool_tip, PivotFit};
pub use servos::{servo_offsets, ServoOffset, ServoOffsets};
pub use turntable::{fit_turntable, TableFit};
pub use verify::{verify, VerifyReport};
pub use workcell::{workcell, WorkcellFit};

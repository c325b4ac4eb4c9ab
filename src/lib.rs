//! polishbot: scan-versus-reference metrology of knee-prosthesis parts and a DOFBOT grinding
//! controller. The stages follow `DESIGN.md` top to bottom; each has one front function and one
//! config struct.
// House rule: no function over 120 lines (threshold in clippy.toml); tests are exempt.
#![warn(clippy::too_many_lines)]
pub mod acquire;
pub mod bus;
pub mod calibrate;
pub mod cell;
pub mod cli;
pub mod cloud;
pub mod compare;
pub mod cycle;
pub mod design;
pub mod inspect;
pub mod motion;
pub mod preprocess;
pub mod progress;
pub mod regions;
pub mod register;
pub mod removal;
pub mod repair;
pub mod report;
pub mod robot;
pub mod settings;
pub mod sim;
pub mod spatial;
pub mod synth;

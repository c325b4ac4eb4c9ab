//! Command-line interface: one file per subcommand; each only wires stages and files together.
mod arm;
mod calibrate;
pub mod calibrate_compliance;
mod calibrate_removal;
mod calibrate_table;
mod calibrate_verify;
mod cell;
mod command;
mod common;
mod cycle;
mod demo;
mod filter;
mod info;
mod inspect;
mod merge;
mod plan;
mod register;
mod run;
pub mod settings;
mod setup_stop;
mod synth;
mod table;
mod tool_stop;

pub use command::{main, Cli, Command};
pub use common::{load_config, one_line, GeometryInput};

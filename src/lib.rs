//! polishbot: scan-versus-reference metrology of knee-prosthesis parts and a DOFBOT grinding
//! controller. The stages follow `DESIGN.md` top to bottom; each has one front function and one
//! config struct.
pub mod cli;
pub mod cloud;
pub mod progress;
pub mod register;
pub mod report;
pub mod synth;

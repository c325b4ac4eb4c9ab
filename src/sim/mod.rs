//! The simulator: a stand-in for the cell's hardware, used by tests, `--sim` and the demo.
//! The simulated servo board ([`model`]) behind the bus's [`crate::bus::Transport`] ([`SimArm`],
//! [`SimTransport`]) or behind the bus's I2C interface ([`FakeI2c`]), and the grinding
//! simulator ([`grind`]) that removes material from a virtual part where the replayed servos put
//! the tool, with its own settings ([`GrindConfig`], `[sim.grinding]`), and the virtual part a
//! simulated run grinds and rescans ([`virtual_part`]).
//!
//! It plugs into the bus through the bus's traits and imports nothing above the bus but synth's
//! scanner model (the rescan of a ground part): the
//! planner (`plan`, `removal`, `motion`) and the arm's model (`robot`) never import it (a
//! simulator that checks the planner shares none of its model or parameters).
//!
//! Front functions: [`SimArm::new`] with [`SimOptions`]; [`grind::grind`] with a
//! [`GrindConfig`] (result: [`grind::GrindReport`]).
pub mod arm;
pub mod fake_i2c;
pub mod grind;
pub mod grinding;
pub mod model;
pub mod virtual_part;

pub use arm::{SimArm, SimOptions, SimTransport};
pub use fake_i2c::{FakeI2c, I2cRecord};
pub use grinding::GrindConfig;
pub use model::{ExtraServo, Faults, Mechanics, PingReply, SimTiming};

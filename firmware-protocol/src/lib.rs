//! Sans-IO, `no_std` (no alloc) wire format of the Yahboom DOFBOT board, serial and I2C, after
//! `shared/DOFBOT.md` and Yahboom's `Arm_Lib.py` (where they differ on reply layouts,
//! Arm_Lib stands: see [`replies`]).
//!
//! * [`frame`]: the envelope `FF FC LEN FUNC payload CHK` (host to board) and
//!   `FF FB LEN TYPE payload CHK` (board to host), the checksum and a streaming [`Decoder`]
//!   that takes bytes in any chunking and resynchronises after garbage.
//! * [`commands`]: typed host commands encoded into a caller's buffer.
//! * [`values`]: the checked values commands carry (targets, poses, ids, buzzer).
//! * [`replies`]: typed board replies parsed from decoded frames.
//! * [`servo`]: servo ids, raw ranges and the angle <-> raw conversion per servo.
//! * [`i2c`]: each command as the SMBus transactions of the board's I2C interface.
//!
//! Values that cannot be sent safely (a raw position outside a servo's range, an angle outside
//! its span, a bad id) are refused when the typed value is built, never clamped, so no frame
//! outside the servo ranges can be produced through this API.
// House rule: no function over 120 lines (threshold in clippy.toml); tests are exempt.
#![warn(clippy::too_many_lines)]
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod check;
pub mod commands;
pub mod frame;
pub mod i2c;
pub mod replies;
pub mod servo;
pub mod values;

#[cfg(test)]
mod armlib_tests;
#[cfg(test)]
mod proptests;

pub use commands::{AnyTarget, BusId, Buzzer, Command, EveryRaw, ParseError, Pose, Target};
pub use frame::{checksum, Decoder, Direction, EncodeError, Frame, FrameError, Hex};
pub use i2c::{i2c_reply, Transaction, Transactions, I2C_ADDRESS};
pub use replies::{OffsetState, Reply, ReplyError};
pub use servo::{RangeError, ServoId, ServoScale};

//! Sans-IO, `no_std` (no alloc) wire format of the Yahboom DOFBOT serial bus, after
//! `shared/DOFBOT.md`.
//!
//! * [`frame`]: the envelope `FF FC LEN FUNC payload CHK` (host to board) and
//!   `FF FB LEN TYPE payload CHK` (board to host), the checksum and a streaming [`Decoder`]
//!   that takes bytes in any chunking and resynchronises after garbage.
//! * [`commands`]: typed host commands encoded into a caller's buffer.
//! * [`replies`]: typed board replies parsed from decoded frames.
//! * [`servo`]: servo ids, raw ranges and the angle <-> raw conversion per servo.
//!
//! Values that cannot be sent safely (a raw position outside a servo's range, an angle outside
//! its span, a bad id) are refused when the typed value is built, never clamped, so no frame
//! outside the servo ranges can be produced through this API.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod check;
pub mod commands;
pub mod frame;
pub mod replies;
pub mod servo;

#[cfg(test)]
mod proptests;

pub use commands::{AnyTarget, BusId, Buzzer, Command, EveryRaw, ParseError, Pose, Target};
pub use frame::{checksum, Decoder, Direction, EncodeError, Frame, FrameError};
pub use replies::{OffsetState, Reply, ReplyError};
pub use servo::{RangeError, ServoId, ServoScale};

//! Typed board-to-host replies, parsed from frames the [`crate::Decoder`] completed.
//!
//! Every reply is `FF FB LEN TYPE payload CHK`. Payloads, as Yahboom's serial `Arm_Lib.py`
//! (`Arm_Device.__receive_data` and `__parse_data`) reads them:
//!
//! ```text
//! TYPE  payload                  reply to            meaning
//! 0x0A  pos(u16) echo(u8)        0x30+id (read)      raw position; echo = 0x30+id
//! 0x0A  pos(u16)                 0x30+id (read)      the same without the echo byte
//! 0x0A  posL posH 0x37           0x37 (read any)     raw position, low byte first
//! 0x38  status(u8)               0x38 (ping)         0xDA alive, 0x00 no answer, else a servo error
//! 0x38  id(u8) status(u8)        0x38 (ping)         the same with the pinged id first
//! 0x33  state(u8)                0x1B                mid-offset state: 0 not found, 1 ok, 2 failed
//! 0x01  version(u8)              0x01                hardware version
//! 0x22  count(u8)                -                   action count
//! ```
//!
//! `__parse_data` takes a TYPE 0x0A payload as `servo_H, servo_L, id`: the position first,
//! the echoed 0x30+id last (`Arm_serial_servo_read` accepts the reply whose echo names the
//! servo it asked for). The serial `Arm_ping_servo` never reads a reply and no published code
//! fixes a serial ping frame: the I2C library reads one status byte (0xDA alive), so both a
//! 1-byte and a 2-byte (id, status) TYPE 0x38 payload are understood, and a board may send
//! none at all. A raw position of 0 or outside the servo's range is a failed read; that
//! judgement is the driver's (see [`crate::ServoScale::check_raw`]), the reply carries the raw
//! value as sent.
//!
//! `Arm_serial_servo_read_any` (0x37, any bus id) reads the same TYPE 0x0A frame through
//! `__parse_data` and then swaps the two position bytes: the board sends that position low
//! byte first. The library never looks at the third byte; this crate takes a reply whose third
//! byte is 0x37 (the request's FUNC, as 0x30+id is for 0x31..0x36) as the answer to a read-any,
//! and refuses any other third byte outside 0x31..0x36, as before. That echo value is this
//! crate's model of the board, not a published fact.
use core::fmt;

use crate::frame::{Direction, EncodeError, Frame};
use crate::servo::ServoId;

/// TYPE of a position reply.
pub const TYPE_POSITION: u8 = 0x0A;
/// TYPE of a ping reply.
pub const TYPE_PING: u8 = 0x38;
/// TYPE of a mid-offset state reply.
pub const TYPE_OFFSET_STATE: u8 = 0x33;
/// TYPE of a version reply.
pub const TYPE_VERSION: u8 = 0x01;
/// TYPE of an action-count reply.
pub const TYPE_ACTION_COUNT: u8 = 0x22;
/// Ping status byte of a servo that answered.
pub const PING_ALIVE: u8 = 0xDA;

/// Result of storing a mid offset (reply 0x33).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OffsetState {
    /// 0: no servo found.
    NotFound,
    /// 1: stored.
    Ok,
    /// 2: storing failed.
    Failed,
}

/// A board reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply {
    /// Raw position of a servo (TYPE 0x0A).
    Position {
        /// The servo, when the reply carries the 0x30+id echo.
        servo: Option<ServoId>,
        /// Raw position as sent by the board (0 = failed read).
        raw: u16,
    },
    /// Raw position of a bus servo read by id (TYPE 0x0A with echo 0x37: the answer to
    /// [`crate::Command::ReadAny`]), as the board meant it (its low-byte-first order undone).
    AnyPosition {
        /// Raw position (0 = failed read).
        raw: u16,
    },
    /// Ping answer (TYPE 0x38).
    Ping {
        /// Bus id pinged, when the reply carries it (2-byte payload).
        id: Option<u8>,
        /// Status byte: [`PING_ALIVE`] alive, 0 no answer, anything else a servo error.
        status: u8,
    },
    /// Mid-offset state (TYPE 0x33).
    OffsetState(OffsetState),
    /// Hardware version (TYPE 0x01).
    Version(u8),
    /// Action count (TYPE 0x22).
    ActionCount(u8),
}

/// A well-framed reply whose content is not understood.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplyError {
    /// TYPE not in the table above.
    UnknownType {
        /// TYPE byte.
        kind: u8,
    },
    /// Payload length wrong for the TYPE.
    BadPayload {
        /// TYPE byte.
        kind: u8,
        /// Payload length received.
        len: usize,
    },
    /// A byte value the reply does not define.
    BadValue {
        /// TYPE byte.
        kind: u8,
        /// The value.
        value: u8,
    },
}

impl fmt::Display for ReplyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReplyError::UnknownType { kind } => write!(f, "unknown reply type 0x{kind:02X}"),
            ReplyError::BadPayload { kind, len } => {
                write!(f, "reply type 0x{kind:02X}: wrong payload length {len}")
            }
            ReplyError::BadValue { kind, value } => {
                write!(f, "reply type 0x{kind:02X}: undefined value 0x{value:02X}")
            }
        }
    }
}

impl Reply {
    /// True for a ping reply whose status is [`PING_ALIVE`].
    pub fn ping_alive(&self) -> bool {
        matches!(
            self,
            Reply::Ping {
                status: PING_ALIVE,
                ..
            }
        )
    }

    /// Parses a decoded board frame.
    pub fn parse(frame: &Frame) -> Result<Reply, ReplyError> {
        let kind = frame.kind();
        let p = frame.payload();
        let bad = || ReplyError::BadPayload { kind, len: p.len() };
        match (kind, p.len()) {
            (TYPE_POSITION, 3) if p[2] == crate::commands::FUNC_READ_ANY => {
                Ok(Reply::AnyPosition {
                    raw: u16::from_le_bytes([p[0], p[1]]),
                })
            }
            (TYPE_POSITION, 3) => {
                let servo = p[2]
                    .checked_sub(crate::commands::FUNC_READ_BASE)
                    .and_then(|id| ServoId::new(id).ok())
                    .ok_or(ReplyError::BadValue { kind, value: p[2] })?;
                Ok(Reply::Position {
                    servo: Some(servo),
                    raw: u16::from_be_bytes([p[0], p[1]]),
                })
            }
            (TYPE_POSITION, 2) => Ok(Reply::Position {
                servo: None,
                raw: u16::from_be_bytes([p[0], p[1]]),
            }),
            (TYPE_PING, 1) => Ok(Reply::Ping {
                id: None,
                status: p[0],
            }),
            (TYPE_PING, 2) => Ok(Reply::Ping {
                id: Some(p[0]),
                status: p[1],
            }),
            (TYPE_OFFSET_STATE, 1) => Ok(Reply::OffsetState(match p[0] {
                0 => OffsetState::NotFound,
                1 => OffsetState::Ok,
                2 => OffsetState::Failed,
                value => return Err(ReplyError::BadValue { kind, value }),
            })),
            (TYPE_VERSION, 1) => Ok(Reply::Version(p[0])),
            (TYPE_ACTION_COUNT, 1) => Ok(Reply::ActionCount(p[0])),
            (
                TYPE_POSITION | TYPE_PING | TYPE_OFFSET_STATE | TYPE_VERSION | TYPE_ACTION_COUNT,
                _,
            ) => Err(bad()),
            _ => Err(ReplyError::UnknownType { kind }),
        }
    }

    /// The frame a board sends for this reply (used by simulators).
    pub fn to_frame(&self) -> Frame {
        let built = match *self {
            Reply::Position {
                servo: Some(id),
                raw,
            } => {
                let [hi, lo] = raw.to_be_bytes();
                Frame::new(
                    TYPE_POSITION,
                    &[hi, lo, crate::commands::FUNC_READ_BASE + id.get()],
                )
            }
            Reply::Position { servo: None, raw } => Frame::new(TYPE_POSITION, &raw.to_be_bytes()),
            Reply::AnyPosition { raw } => {
                let [lo, hi] = raw.to_le_bytes();
                Frame::new(TYPE_POSITION, &[lo, hi, crate::commands::FUNC_READ_ANY])
            }
            Reply::Ping {
                id: Some(id),
                status,
            } => Frame::new(TYPE_PING, &[id, status]),
            Reply::Ping { id: None, status } => Frame::new(TYPE_PING, &[status]),
            Reply::OffsetState(s) => Frame::new(
                TYPE_OFFSET_STATE,
                &[match s {
                    OffsetState::NotFound => 0,
                    OffsetState::Ok => 1,
                    OffsetState::Failed => 2,
                }],
            ),
            Reply::Version(v) => Frame::new(TYPE_VERSION, &[v]),
            Reply::ActionCount(n) => Frame::new(TYPE_ACTION_COUNT, &[n]),
        };
        built.expect("reply payloads are short")
    }

    /// Encodes the whole reply frame (`FF FB ...`) into `buf`.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        self.to_frame().encode(Direction::ToHost, buf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Decoder;

    #[test]
    fn replies_round_trip() {
        let s2 = ServoId::new(2).unwrap();
        let all = [
            Reply::Position {
                servo: Some(s2),
                raw: 2345,
            },
            Reply::Position {
                servo: None,
                raw: 0,
            },
            Reply::AnyPosition { raw: 2040 },
            Reply::Ping {
                id: Some(3),
                status: PING_ALIVE,
            },
            Reply::Ping {
                id: None,
                status: 0,
            },
            Reply::OffsetState(OffsetState::Failed),
            Reply::Version(3),
            Reply::ActionCount(9),
        ];
        for r in all {
            let mut buf = [0u8; 16];
            let n = r.encode(&mut buf).unwrap();
            let mut dec = Decoder::replies();
            let got: std::vec::Vec<_> = dec.feed(&buf[..n]).collect();
            assert_eq!(got.len(), 1);
            assert_eq!(Reply::parse(&got[0].unwrap()), Ok(r));
        }
    }

    #[test]
    fn unknown_and_short_replies_are_errors() {
        let f = Frame::new(0x77, &[1]).unwrap();
        assert_eq!(
            Reply::parse(&f),
            Err(ReplyError::UnknownType { kind: 0x77 })
        );
        let f = Frame::new(TYPE_POSITION, &[1]).unwrap();
        assert_eq!(
            Reply::parse(&f),
            Err(ReplyError::BadPayload {
                kind: TYPE_POSITION,
                len: 1
            })
        );
    }
}

//! Typed host-to-board commands, encoded into a caller's buffer.
//!
//! Every frame is `FF FC LEN FUNC payload CHK` (see [`crate::frame`]). Payloads, u16 big-endian:
//!
//! ```text
//! FUNC        payload                         LEN   command
//! 0x10+id     pos(u16) time_ms(u16)           07    MoveServo: servo id 1..6 to raw pos
//! 0x1D        6 x pos(u16) time_ms(u16)       11    MoveAll: all six servos in one frame
//! 0x19        id(u8) pos(u16) time_ms(u16)    08    MoveAny: any bus servo id 1..250
//! 0x17        pos(u16) time_ms(u16)           07    MoveEvery: every servo to one raw pos
//! 0x30+id     -                               03    ReadPosition of servo id (reply 0x0A)
//! 0x37        id(u8)                          04    ReadAny: any bus servo id (reply 0x0A)
//! 0x38        id(u8)                          04    Ping (reply 0x38: 0xDA alive, 0 not)
//! 0x1A        1 | 0                           04    Torque on | off, all servos
//! 0x18        new id(u8)                      04    SetId of the only servo on the bus
//! 0x1C        id(u8), 0 = factory             04    StoreMidOffset: current pos as mid
//! 0x1B        -                               03    ReadOffsetState (reply 0x33)
//! 0x06        0 off, 0xFF on, 1..50 x100 ms   04    Buzzer
//! 0x02        r g b                           06    Rgb LED
//! 0x05        0x01                            04    Reset the board
//! 0x01        -                               03    Version (reply 0x01)
//! ```
//!
//! time_ms = 0 means "as fast as the servo goes". Positions are validated when the typed
//! values ([`Target`], [`Pose`], [`AnyTarget`], [`EveryRaw`]) are built, so every command
//! that exists is safe to encode.
use core::fmt;

use crate::frame::{Direction, EncodeError, Frame};
use crate::servo::{RangeError, ServoId, SERVO_COUNT};
pub use crate::values::{AnyTarget, BusId, Buzzer, EveryRaw, Pose, Target};

/// FUNC of MoveServo for servo 1 (servo id adds to 0x10).
pub const FUNC_MOVE_SERVO_BASE: u8 = 0x10;
/// FUNC of MoveAll.
pub const FUNC_MOVE_ALL: u8 = 0x1D;
/// FUNC of MoveAny.
pub const FUNC_MOVE_ANY: u8 = 0x19;
/// FUNC of MoveEvery.
pub const FUNC_MOVE_EVERY: u8 = 0x17;
/// FUNC base of ReadPosition (servo id adds to 0x30).
pub const FUNC_READ_BASE: u8 = 0x30;
/// FUNC of ReadAny (Arm_Lib's `Arm_serial_servo_read_any`).
pub const FUNC_READ_ANY: u8 = 0x37;
/// FUNC of Ping.
pub const FUNC_PING: u8 = 0x38;
/// FUNC of Torque.
pub const FUNC_TORQUE: u8 = 0x1A;
/// FUNC of SetId.
pub const FUNC_SET_ID: u8 = 0x18;
/// FUNC of StoreMidOffset.
pub const FUNC_STORE_MID: u8 = 0x1C;
/// FUNC of ReadOffsetState.
pub const FUNC_OFFSET_STATE: u8 = 0x1B;
/// FUNC of Buzzer.
pub const FUNC_BUZZER: u8 = 0x06;
/// FUNC of Rgb.
pub const FUNC_RGB: u8 = 0x02;
/// FUNC of Reset.
pub const FUNC_RESET: u8 = 0x05;
/// FUNC of Version.
pub const FUNC_VERSION: u8 = 0x01;
/// Length in bytes of an encoded MoveAll frame.
pub const MOVE_ALL_FRAME_LEN: usize = 2 + 0x11;

/// A host command. Build the position-carrying variants from validated values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// 0x10+id: one servo to a raw position in `time_ms`.
    MoveServo {
        /// Servo and position.
        target: Target,
        /// Move time, ms (0 = fastest).
        time_ms: u16,
    },
    /// 0x1D: all six servos in one frame.
    MoveAll {
        /// Positions of servos 1..=6.
        pose: Pose,
        /// Move time, ms (0 = fastest).
        time_ms: u16,
    },
    /// 0x19: any bus servo id.
    MoveAny {
        /// Bus servo and position.
        target: AnyTarget,
        /// Move time, ms.
        time_ms: u16,
    },
    /// 0x17: every servo to one raw position.
    MoveEvery {
        /// The position.
        raw: EveryRaw,
        /// Move time, ms.
        time_ms: u16,
    },
    /// 0x30+id: read a servo's raw position.
    ReadPosition(ServoId),
    /// 0x37: read any bus servo's raw position (reply TYPE 0x0A, position low byte first:
    /// [`crate::Reply::AnyPosition`]).
    ReadAny(BusId),
    /// 0x38: ping a bus servo.
    Ping(BusId),
    /// 0x1A: torque on (true) or off for all servos.
    Torque(bool),
    /// 0x18: set the id of the only servo on the bus.
    SetId(BusId),
    /// 0x1C: store a servo's current position as its mid position (None = factory reset).
    StoreMidOffset(Option<BusId>),
    /// 0x1B: read the mid-offset state.
    ReadOffsetState,
    /// 0x06: buzzer.
    Buzzer(Buzzer),
    /// 0x02: RGB LED colour.
    Rgb {
        /// Red.
        r: u8,
        /// Green.
        g: u8,
        /// Blue.
        b: u8,
    },
    /// 0x05: reset the board.
    Reset,
    /// 0x01: read the hardware version.
    Version,
}

fn be(v: u16) -> [u8; 2] {
    v.to_be_bytes()
}

impl Command {
    /// FUNC byte of this command.
    pub fn func(&self) -> u8 {
        match self {
            Command::MoveServo { target, .. } => FUNC_MOVE_SERVO_BASE + target.id.get(),
            Command::MoveAll { .. } => FUNC_MOVE_ALL,
            Command::MoveAny { .. } => FUNC_MOVE_ANY,
            Command::MoveEvery { .. } => FUNC_MOVE_EVERY,
            Command::ReadPosition(id) => FUNC_READ_BASE + id.get(),
            Command::ReadAny(_) => FUNC_READ_ANY,
            Command::Ping(_) => FUNC_PING,
            Command::Torque(_) => FUNC_TORQUE,
            Command::SetId(_) => FUNC_SET_ID,
            Command::StoreMidOffset(_) => FUNC_STORE_MID,
            Command::ReadOffsetState => FUNC_OFFSET_STATE,
            Command::Buzzer(_) => FUNC_BUZZER,
            Command::Rgb { .. } => FUNC_RGB,
            Command::Reset => FUNC_RESET,
            Command::Version => FUNC_VERSION,
        }
    }

    /// Short lowercase name, for logs and journals.
    pub fn name(&self) -> &'static str {
        match self {
            Command::MoveServo { .. } => "move_servo",
            Command::MoveAll { .. } => "move_all",
            Command::MoveAny { .. } => "move_any",
            Command::MoveEvery { .. } => "move_every",
            Command::ReadPosition(_) => "read_position",
            Command::ReadAny(_) => "read_any",
            Command::Ping(_) => "ping",
            Command::Torque(_) => "torque",
            Command::SetId(_) => "set_id",
            Command::StoreMidOffset(_) => "store_mid_offset",
            Command::ReadOffsetState => "read_offset_state",
            Command::Buzzer(_) => "buzzer",
            Command::Rgb { .. } => "rgb",
            Command::Reset => "reset",
            Command::Version => "version",
        }
    }

    /// True for commands that move servos.
    pub fn is_motion(&self) -> bool {
        matches!(
            self,
            Command::MoveServo { .. }
                | Command::MoveAll { .. }
                | Command::MoveAny { .. }
                | Command::MoveEvery { .. }
        )
    }

    /// The frame (FUNC and payload) of this command.
    pub fn to_frame(&self) -> Frame {
        let mut p = [0u8; 2 * SERVO_COUNT + 2];
        let n = match *self {
            Command::MoveServo { target, time_ms } => put(&mut p, &[&be(target.raw), &be(time_ms)]),
            Command::MoveAll { pose, time_ms } => {
                for (i, raw) in pose.raw.iter().enumerate() {
                    p[2 * i..2 * i + 2].copy_from_slice(&be(*raw));
                }
                p[2 * SERVO_COUNT..].copy_from_slice(&be(time_ms));
                2 * SERVO_COUNT + 2
            }
            Command::MoveAny { target, time_ms } => {
                put(&mut p, &[&[target.id.get()], &be(target.raw), &be(time_ms)])
            }
            Command::MoveEvery { raw, time_ms } => put(&mut p, &[&be(raw.0), &be(time_ms)]),
            Command::ReadPosition(_) | Command::ReadOffsetState | Command::Version => 0,
            Command::Ping(id) | Command::SetId(id) | Command::ReadAny(id) => {
                put(&mut p, &[&[id.get()]])
            }
            Command::Torque(on) => put(&mut p, &[&[on as u8]]),
            Command::StoreMidOffset(id) => put(&mut p, &[&[id.map_or(0, BusId::get)]]),
            Command::Buzzer(b) => put(&mut p, &[&[b.0]]),
            Command::Rgb { r, g, b } => put(&mut p, &[&[r, g, b]]),
            Command::Reset => put(&mut p, &[&[0x01]]),
        };
        Frame::new(self.func(), &p[..n]).expect("command payloads are short")
    }

    /// Encodes the whole frame (`FF FC ...`) into `buf`; returns the number of bytes written.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        self.to_frame().encode(Direction::ToBoard, buf)
    }

    /// Parses a decoded host frame back into a command (what a board or a simulator does).
    /// Out-of-range values are refused exactly as when building the command.
    pub fn parse(frame: &Frame) -> Result<Command, ParseError> {
        Self::parse_motion(frame.kind(), frame.payload())
    }

    /// [`Command::parse`] of the moves and the position reads (FUNC `f`, payload `p`); any
    /// other FUNC goes on to [`Command::parse_setting`].
    fn parse_motion(f: u8, p: &[u8]) -> Result<Command, ParseError> {
        let u16_at = |i: usize| u16::from_be_bytes([p[i], p[i + 1]]);
        let cmd = match f {
            0x11..=0x16 => {
                expect_len(f, p, 4)?;
                let id = ServoId::new(f - FUNC_MOVE_SERVO_BASE)?;
                Command::MoveServo {
                    target: Target::new(id, u16_at(0))?,
                    time_ms: u16_at(2),
                }
            }
            FUNC_MOVE_ALL => {
                expect_len(f, p, 2 * SERVO_COUNT + 2)?;
                let mut raw = [0u16; SERVO_COUNT];
                for (i, r) in raw.iter_mut().enumerate() {
                    *r = u16_at(2 * i);
                }
                Command::MoveAll {
                    pose: Pose::new(raw)?,
                    time_ms: u16_at(2 * SERVO_COUNT),
                }
            }
            FUNC_MOVE_ANY => {
                expect_len(f, p, 5)?;
                let target = AnyTarget::new(BusId::new(p[0])?, u16_at(1))?;
                Command::MoveAny {
                    target,
                    time_ms: u16_at(3),
                }
            }
            FUNC_MOVE_EVERY => {
                expect_len(f, p, 4)?;
                Command::MoveEvery {
                    raw: EveryRaw::new(u16_at(0))?,
                    time_ms: u16_at(2),
                }
            }
            0x31..=0x36 => {
                expect_len(f, p, 0)?;
                Command::ReadPosition(ServoId::new(f - FUNC_READ_BASE)?)
            }
            _ => return Self::parse_setting(f, p),
        };
        Ok(cmd)
    }

    /// [`Command::parse`] of the bus, board, buzzer and LED commands (FUNC `f`, payload `p`).
    fn parse_setting(f: u8, p: &[u8]) -> Result<Command, ParseError> {
        let cmd = match f {
            FUNC_PING | FUNC_READ_ANY => {
                expect_len(f, p, 1)?;
                let id = BusId::new(p[0])?;
                [Command::Ping(id), Command::ReadAny(id)][usize::from(f == FUNC_READ_ANY)]
            }
            FUNC_TORQUE => {
                expect_len(f, p, 1)?;
                match p[0] {
                    0 => Command::Torque(false),
                    1 => Command::Torque(true),
                    _ => {
                        return Err(ParseError::BadValue {
                            func: f,
                            value: p[0],
                        })
                    }
                }
            }
            FUNC_SET_ID => {
                expect_len(f, p, 1)?;
                Command::SetId(BusId::new(p[0])?)
            }
            FUNC_STORE_MID => {
                expect_len(f, p, 1)?;
                Command::StoreMidOffset(if p[0] == 0 {
                    None
                } else {
                    Some(BusId::new(p[0])?)
                })
            }
            FUNC_OFFSET_STATE => {
                expect_len(f, p, 0)?;
                Command::ReadOffsetState
            }
            FUNC_BUZZER => {
                expect_len(f, p, 1)?;
                Command::Buzzer(match p[0] {
                    0 => Buzzer::OFF,
                    0xFF => Buzzer::ON,
                    t => Buzzer::for_tenths(t)?,
                })
            }
            FUNC_RGB => {
                expect_len(f, p, 3)?;
                Command::Rgb {
                    r: p[0],
                    g: p[1],
                    b: p[2],
                }
            }
            FUNC_RESET => {
                expect_len(f, p, 1)?;
                if p[0] != 1 {
                    return Err(ParseError::BadValue {
                        func: f,
                        value: p[0],
                    });
                }
                Command::Reset
            }
            FUNC_VERSION => {
                expect_len(f, p, 0)?;
                Command::Version
            }
            _ => return Err(ParseError::UnknownFunc { func: f }),
        };
        Ok(cmd)
    }
}

/// Checks that the payload `p` of the FUNC `f` is `n` bytes long.
fn expect_len(f: u8, p: &[u8], n: usize) -> Result<(), ParseError> {
    if p.len() == n {
        Ok(())
    } else {
        Err(ParseError::BadPayload {
            func: f,
            len: p.len(),
        })
    }
}

/// A host frame that is not a valid command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParseError {
    /// FUNC byte not in DOFBOT.md's table.
    UnknownFunc {
        /// The FUNC byte.
        func: u8,
    },
    /// Payload length wrong for the FUNC.
    BadPayload {
        /// The FUNC byte.
        func: u8,
        /// Payload length received.
        len: usize,
    },
    /// A byte value the command does not define.
    BadValue {
        /// The FUNC byte.
        func: u8,
        /// The value.
        value: u8,
    },
    /// A position, id or angle out of range.
    Range(RangeError),
}

impl From<RangeError> for ParseError {
    fn from(e: RangeError) -> Self {
        ParseError::Range(e)
    }
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParseError::UnknownFunc { func } => write!(f, "unknown command 0x{func:02X}"),
            ParseError::BadPayload { func, len } => {
                write!(f, "command 0x{func:02X}: wrong payload length {len}")
            }
            ParseError::BadValue { func, value } => {
                write!(f, "command 0x{func:02X}: undefined value 0x{value:02X}")
            }
            ParseError::Range(e) => write!(f, "{e}"),
        }
    }
}

fn put(p: &mut [u8], parts: &[&[u8]]) -> usize {
    let mut n = 0;
    for part in parts {
        p[n..n + part.len()].copy_from_slice(part);
        n += part.len();
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(cmd: Command) -> std::vec::Vec<u8> {
        let mut buf = [0u8; 64];
        let n = cmd.encode(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn golden_single_servo_frame_from_dofbot_md() {
        let target = Target::new(ServoId::new(1).unwrap(), 2000).unwrap();
        let cmd = Command::MoveServo {
            target,
            time_ms: 500,
        };
        assert_eq!(
            bytes(cmd),
            [0xFF, 0xFC, 0x07, 0x11, 0x07, 0xD0, 0x01, 0xF4, 0xE4]
        );
    }

    #[test]
    fn golden_six_servo_frame_byte_by_byte() {
        // Layout by DOFBOT.md: FF FC, LEN 0x11, FUNC 0x1D, six big-endian positions, time, CHK.
        let raw = [2000u16, 1500, 2500, 900, 3700, 3100];
        let pose = Pose::new(raw).unwrap();
        let got = bytes(Command::MoveAll {
            pose,
            time_ms: 1000,
        });
        let expected: [u8; 19] = [
            0xFF, 0xFC, 0x11, 0x1D, 0x07, 0xD0, 0x05, 0xDC, 0x09, 0xC4, 0x03, 0x84, 0x0E, 0x74,
            0x0C, 0x1C, 0x03, 0xE8, 0xCF,
        ];
        // CHK by hand: 0x11+0x1D+0x07+0xD0+0x05+0xDC+0x09+0xC4+0x03+0x84+0x0E+0x74+0x0C+0x1C
        // +0x03+0xE8 = 0x4CF -> 0xCF.
        assert_eq!(got.len(), MOVE_ALL_FRAME_LEN);
        for (i, (g, e)) in got.iter().zip(expected.iter()).enumerate() {
            assert_eq!(g, e, "byte {i}");
        }
    }

    #[test]
    fn out_of_range_is_refused_not_clamped() {
        let s1 = ServoId::new(1).unwrap();
        assert!(Target::new(s1, 899).is_err());
        assert!(Target::new(s1, 3101).is_err());
        assert!(Target::new(ServoId::new(5).unwrap(), 380).is_ok());
        assert!(Pose::new([2000, 2000, 2000, 2000, 3701, 2000]).is_err());
        assert!(EveryRaw::new(3101).is_err() && EveryRaw::new(3100).is_ok());
        assert!(BusId::new(0).is_err() && BusId::new(251).is_err());
        assert!(AnyTarget::new(BusId::new(7).unwrap(), 95).is_err());
        assert!(AnyTarget::new(BusId::new(7).unwrap(), 96).is_ok());
        assert!(AnyTarget::new(BusId::new(2).unwrap(), 96).is_err());
        assert!(Buzzer::for_tenths(51).is_err());
    }

    #[test]
    fn every_command_parses_back() {
        let id = ServoId::new(3).unwrap();
        let cmds = [
            Command::MoveServo {
                target: Target::new(id, 1234).unwrap(),
                time_ms: 7,
            },
            Command::MoveAll {
                pose: Pose::new([900, 3100, 2000, 2000, 380, 2000]).unwrap(),
                time_ms: 0,
            },
            Command::MoveAny {
                target: AnyTarget::new(BusId::new(9).unwrap(), 4000).unwrap(),
                time_ms: 65535,
            },
            Command::MoveEvery {
                raw: EveryRaw::new(2000).unwrap(),
                time_ms: 300,
            },
            Command::ReadPosition(id),
            Command::Ping(BusId::new(6).unwrap()),
            Command::Torque(true),
            Command::Torque(false),
            Command::SetId(BusId::new(4).unwrap()),
            Command::StoreMidOffset(None),
            Command::StoreMidOffset(Some(BusId::new(2).unwrap())),
            Command::ReadOffsetState,
            Command::Buzzer(Buzzer::ON),
            Command::Buzzer(Buzzer::for_tenths(5).unwrap()),
            Command::Rgb { r: 1, g: 2, b: 3 },
            Command::Reset,
            Command::Version,
        ];
        for cmd in cmds {
            let b = bytes(cmd);
            let mut dec = crate::Decoder::commands();
            let frames: std::vec::Vec<_> = dec.feed(&b).collect();
            assert_eq!(frames.len(), 1);
            let frame = frames[0].unwrap();
            assert_eq!(Command::parse(&frame), Ok(cmd), "{}", cmd.name());
            assert_eq!(b[2] as usize, b.len() - 2, "LEN of {}", cmd.name());
        }
    }
}

//! The board's I2C register interface (Yahboom's smbus `Arm_Lib.py`, bus 1, address 0x15):
//! each [`Command`] as the SMBus transactions that library performs for it, and the reply read
//! back, sans-IO. A transport performs the [`Transaction`]s in order (waiting where a
//! [`Transaction::Wait`] says) and hands the value of the final read to [`i2c_reply`].
//!
//! ```text
//! command            transactions (Arm_Lib function)
//! MoveServo          block(0x10+id, [pH pL tH tL])               Arm_serial_servo_write
//! MoveAll            block(0x1E, [tH tL]); block(0x1D, 12 bytes)  Arm_serial_servo_write6
//! MoveAny            block(0x19, [id pH pL tH tL])               Arm_serial_servo_write_any
//! MoveEvery          block(0x17, [pH pL tH tL])                  Arm_serial_servo_write_any(0)
//! ReadPosition       byte(0x30+id, 0); 3 ms; word(0x30+id)       Arm_serial_servo_read
//! ReadAny            byte(0x37, id); 3 ms; word(0x37)            Arm_serial_servo_read_any
//! Ping               byte(0x38, id); 3 ms; read byte(0x38)       Arm_ping_servo
//! Torque             byte(0x1A, 1|0)                             Arm_serial_set_torque
//! SetId              byte(0x18, id)                              Arm_serial_set_id
//! StoreMidOffset     byte(0x1C, id|0)                            Arm_serial_servo_write_offset_switch
//! ReadOffsetState    byte(0x1B, 1); 1 ms; read byte(0x1B)        Arm_serial_servo_write_offset_state
//! Buzzer             byte(0x06, value)                           Arm_Buzzer_On / Off
//! Rgb                block(0x02, [r g b])                        Arm_RGB_set
//! Reset              byte(0x05, 1)                               Arm_reset
//! Version            byte(0x01, 1); 1 ms; read byte(0x01)        Arm_get_hardversion
//! ```
//!
//! SMBus words are little-endian and the board sends the position big-endian, so the word
//! read is byte-swapped (as Arm_Lib does); a word of 0 is a failed read.
use crate::commands::{BusId, Command, FUNC_MOVE_ALL};
use crate::replies::{OffsetState, Reply, ReplyError, TYPE_OFFSET_STATE};
use crate::servo::SERVO_COUNT;

/// The board's default 7-bit I2C address.
pub const I2C_ADDRESS: u8 = 0x15;
/// Register taking the move time of the next six-servo block (Arm_Lib writes it first).
pub const REG_MOVE_ALL_TIME: u8 = 0x1E;
/// Longest block written: the twelve position bytes of a six-servo move.
pub const MAX_BLOCK: usize = 2 * SERVO_COUNT;
/// Arm_Lib's pause between a read request and the read of a position or a ping, µs
/// (`time.sleep(0.003)`).
pub const READ_WAIT_US: u32 = 3_000;
/// Arm_Lib's pause before reading the offset state or the version, µs (`time.sleep(.001)`).
pub const STATE_WAIT_US: u32 = 1_000;
/// Most transactions one command takes (request, wait, read).
pub const MAX_TRANSACTIONS: usize = 3;

/// One SMBus transaction with the board (the smbus call it mirrors in brackets).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transaction {
    /// Block write of `data[..len]` to register `reg` (`write_i2c_block_data`).
    WriteBlock {
        /// Register (command byte).
        reg: u8,
        /// Bytes used in `data`.
        len: u8,
        /// The block, zero-padded.
        data: [u8; MAX_BLOCK],
    },
    /// One byte to register `reg` (`write_byte_data`).
    WriteByte {
        /// Register.
        reg: u8,
        /// The byte.
        value: u8,
    },
    /// Wait before the next transaction, µs.
    Wait {
        /// Microseconds.
        us: u32,
    },
    /// Read a word from register `reg` (`read_word_data`, little-endian).
    ReadWord {
        /// Register.
        reg: u8,
    },
    /// Read a byte from register `reg` (`read_byte_data`).
    ReadByte {
        /// Register.
        reg: u8,
    },
}

impl Transaction {
    /// A block write of `bytes` (at most [`MAX_BLOCK`]).
    pub fn block(reg: u8, bytes: &[u8]) -> Transaction {
        let mut data = [0u8; MAX_BLOCK];
        data[..bytes.len()].copy_from_slice(bytes);
        Transaction::WriteBlock {
            reg,
            len: bytes.len() as u8,
            data,
        }
    }

    /// The bytes of a block write (empty for the other kinds).
    pub fn block_bytes(&self) -> &[u8] {
        match self {
            Transaction::WriteBlock { len, data, .. } => &data[..*len as usize],
            _ => &[],
        }
    }
}

/// The transactions of one command, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Transactions {
    items: [Transaction; MAX_TRANSACTIONS],
    n: usize,
}

impl Transactions {
    fn of(list: &[Transaction]) -> Transactions {
        let mut items = [Transaction::Wait { us: 0 }; MAX_TRANSACTIONS];
        items[..list.len()].copy_from_slice(list);
        Transactions {
            items,
            n: list.len(),
        }
    }

    /// The transactions.
    pub fn as_slice(&self) -> &[Transaction] {
        &self.items[..self.n]
    }
}

fn request(reg: u8, value: u8, wait_us: u32, read: Transaction) -> Transactions {
    Transactions::of(&[
        Transaction::WriteByte { reg, value },
        Transaction::Wait { us: wait_us },
        read,
    ])
}

fn write_byte(reg: u8, value: u8) -> Transactions {
    Transactions::of(&[Transaction::WriteByte { reg, value }])
}

impl Command {
    /// The SMBus transactions Arm_Lib's I2C variant performs for this command.
    pub fn to_i2c(&self) -> Transactions {
        let f = self.func();
        let p = self.to_frame();
        let p = p.payload();
        match *self {
            Command::MoveAll { .. } => Transactions::of(&[
                Transaction::block(REG_MOVE_ALL_TIME, &p[MAX_BLOCK..]),
                Transaction::block(FUNC_MOVE_ALL, &p[..MAX_BLOCK]),
            ]),
            Command::MoveServo { .. }
            | Command::MoveAny { .. }
            | Command::MoveEvery { .. }
            | Command::Rgb { .. } => Transactions::of(&[Transaction::block(f, p)]),
            Command::ReadPosition(_) => {
                request(f, 0, READ_WAIT_US, Transaction::ReadWord { reg: f })
            }
            Command::ReadAny(id) => {
                request(f, id.get(), READ_WAIT_US, Transaction::ReadWord { reg: f })
            }
            Command::Ping(id) => {
                request(f, id.get(), READ_WAIT_US, Transaction::ReadByte { reg: f })
            }
            Command::ReadOffsetState | Command::Version => {
                request(f, 1, STATE_WAIT_US, Transaction::ReadByte { reg: f })
            }
            Command::StoreMidOffset(id) => write_byte(f, id.map_or(0, BusId::get)),
            Command::Torque(_) | Command::SetId(_) | Command::Buzzer(_) | Command::Reset => {
                write_byte(f, p[0])
            }
        }
    }
}

/// The reply to `cmd` from the value of its final read (`None` for commands without a read).
/// A position word is byte-swapped to the board's big-endian value; 0 stays 0 (a failed
/// read, the driver's judgement).
pub fn i2c_reply(cmd: &Command, value: u16) -> Result<Option<Reply>, ReplyError> {
    let byte = value as u8;
    Ok(Some(match *cmd {
        Command::ReadPosition(id) => Reply::Position {
            servo: Some(id),
            raw: value.swap_bytes(),
        },
        Command::ReadAny(_) => Reply::AnyPosition {
            raw: value.swap_bytes(),
        },
        Command::Ping(id) => Reply::Ping {
            id: Some(id.get()),
            status: byte,
        },
        Command::ReadOffsetState => Reply::OffsetState(match byte {
            0 => OffsetState::NotFound,
            1 => OffsetState::Ok,
            2 => OffsetState::Failed,
            value => {
                return Err(ReplyError::BadValue {
                    kind: TYPE_OFFSET_STATE,
                    value,
                })
            }
        }),
        Command::Version => Reply::Version(byte),
        _ => return Ok(None),
    }))
}

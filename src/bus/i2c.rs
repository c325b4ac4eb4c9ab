//! I2C back-end for the stock board (Jetson Nano and Raspberry Pi kits: bus 1, address
//! 0x15). The driver writes the same validated command frames as on a serial port; this
//! transport decodes each one back into its [`Command`], performs the SMBus transactions
//! `dofbot-protocol` lists for it ([`Command::to_i2c`], Yahboom's smbus `Arm_Lib.py`), keeps
//! the waits between them, and hands the value read back to the driver as the reply frame the
//! serial board would have sent. The device is an [`I2cBus`]: Linux i2c-dev through the
//! `i2cdev` crate, or the in-process fake of [`super::fake_i2c`].
use std::time::Duration;

use dofbot_protocol::frame::MAX_FRAME;
use dofbot_protocol::i2c::{i2c_reply, Transaction};
use dofbot_protocol::{Command, Decoder, Frame, Reply, ReplyError};

use super::error::BusError;
use super::transport::Transport;

/// The SMBus operations the board's I2C interface takes, on one device address, with the
/// device's clock.
pub trait I2cBus: Send {
    /// `write_i2c_block_data(addr, reg, data)`.
    fn write_block(&mut self, reg: u8, data: &[u8]) -> Result<(), BusError>;
    /// `write_byte_data(addr, reg, value)`.
    fn write_byte(&mut self, reg: u8, value: u8) -> Result<(), BusError>;
    /// `read_word_data(addr, reg)`: the SMBus word, little-endian as the bus delivers it.
    fn read_word(&mut self, reg: u8) -> Result<u16, BusError>;
    /// `read_byte_data(addr, reg)`.
    fn read_byte(&mut self, reg: u8) -> Result<u8, BusError>;
    /// Time since the device was opened.
    fn now(&self) -> Duration;
    /// Waits `d` (a virtual device advances its clock instead).
    fn sleep(&mut self, d: Duration);
    /// The device and address, e.g. "i2c /dev/i2c-1 @ 0x15".
    fn describe(&self) -> String;
}

/// A [`Transport`] over an [`I2cBus`].
pub struct I2cTransport<D: I2cBus> {
    dev: D,
    decoder: Decoder,
    inbox: Vec<u8>,
}

impl<D: I2cBus> I2cTransport<D> {
    /// The transport over `dev`.
    pub fn new(dev: D) -> I2cTransport<D> {
        I2cTransport {
            dev,
            decoder: Decoder::commands(),
            inbox: Vec::new(),
        }
    }

    /// The device.
    pub fn device(&self) -> &D {
        &self.dev
    }

    /// Performs `cmd`'s transactions; returns the reply frame, if the command reads one.
    fn perform(&mut self, cmd: &Command) -> Result<Option<Frame>, BusError> {
        let mut value = 0u16;
        for t in cmd.to_i2c().as_slice() {
            match *t {
                Transaction::WriteBlock { reg, .. } => {
                    self.dev.write_block(reg, t.block_bytes())?
                }
                Transaction::WriteByte { reg, value } => self.dev.write_byte(reg, value)?,
                Transaction::Wait { us } => self.dev.sleep(Duration::from_micros(us as u64)),
                Transaction::ReadWord { reg } => value = self.dev.read_word(reg)?,
                Transaction::ReadByte { reg } => value = self.dev.read_byte(reg)? as u16,
            }
        }
        Ok(match i2c_reply(cmd, value) {
            Ok(reply) => reply.map(|r: Reply| r.to_frame()),
            // A byte the reply does not define goes up as sent: the driver names it.
            Err(ReplyError::BadValue { kind, value }) => Frame::new(kind, &[value]).ok(),
            Err(_) => None,
        })
    }
}

impl<D: I2cBus> Transport for I2cTransport<D> {
    fn write(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        let frames: Vec<_> = self.decoder.feed(bytes).collect();
        for frame in frames {
            let cmd = frame
                .map_err(|e| BusError::Refused(format!("i2c: not a command frame: {e}")))
                .and_then(|f| {
                    Command::parse(&f).map_err(|e| BusError::Refused(format!("i2c: {e}")))
                })?;
            if let Some(reply) = self.perform(&cmd)? {
                let mut buf = [0u8; MAX_FRAME];
                let n = reply
                    .encode(dofbot_protocol::Direction::ToHost, &mut buf)
                    .expect("replies fit MAX_FRAME");
                self.inbox.extend_from_slice(&buf[..n]);
            }
        }
        Ok(())
    }

    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, BusError> {
        if self.inbox.is_empty() {
            self.dev.sleep(timeout);
            return Ok(0);
        }
        let n = self.inbox.len().min(buf.len());
        buf[..n].copy_from_slice(&self.inbox[..n]);
        self.inbox.drain(..n);
        Ok(n)
    }

    fn clear_input(&mut self) -> Result<(), BusError> {
        self.inbox.clear();
        Ok(())
    }

    fn now(&self) -> Duration {
        self.dev.now()
    }

    fn sleep(&mut self, d: Duration) {
        self.dev.sleep(d);
    }

    fn describe(&self) -> String {
        self.dev.describe()
    }
}

/// Parses an I2C address given as `0x15` or `21`: a 7-bit address outside the reserved
/// ranges (0x03..=0x77).
pub fn parse_address(text: &str) -> Result<u16, String> {
    let t = text.trim();
    let parsed = match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(hex) => u16::from_str_radix(hex, 16),
        None => t.parse(),
    };
    match parsed {
        Ok(a) if (0x03..=0x77).contains(&a) => Ok(a),
        _ => Err(format!(
            "{text:?} is not a 7-bit I2C address 0x03..0x77 (the board's is 0x15)"
        )),
    }
}

#[cfg(target_os = "linux")]
pub use linux::LinuxI2c;

#[cfg(target_os = "linux")]
mod linux {
    use std::time::Duration;

    use i2cdev::core::I2CDevice;
    use i2cdev::linux::{LinuxI2CDevice, LinuxI2CError};

    use super::I2cBus;
    use crate::bus::error::BusError;
    use crate::bus::transport::RealClock;

    /// A board on a Linux i2c-dev bus (`/dev/i2c-1`), through the `i2cdev` crate.
    pub struct LinuxI2c {
        dev: LinuxI2CDevice,
        path: String,
        address: u16,
        clock: RealClock,
    }

    impl LinuxI2c {
        /// Opens `path` and selects the board at `address`.
        pub fn open(path: &str, address: u16) -> Result<LinuxI2c, BusError> {
            let dev = LinuxI2CDevice::new(path, address).map_err(|e| BusError::Open {
                port: path.to_string(),
                detail: e.to_string(),
            })?;
            Ok(LinuxI2c {
                dev,
                path: path.to_string(),
                address,
                clock: RealClock::new(),
            })
        }

        fn lost(&self, what: &str, reg: u8, e: LinuxI2CError) -> BusError {
            BusError::PortLost {
                detail: format!(
                    "{} @ 0x{:02X}: {what} register 0x{reg:02X}: {e}",
                    self.path, self.address
                ),
            }
        }
    }

    impl I2cBus for LinuxI2c {
        fn write_block(&mut self, reg: u8, data: &[u8]) -> Result<(), BusError> {
            self.dev
                .smbus_write_i2c_block_data(reg, data)
                .map_err(|e| self.lost("block write", reg, e))
        }

        fn write_byte(&mut self, reg: u8, value: u8) -> Result<(), BusError> {
            self.dev
                .smbus_write_byte_data(reg, value)
                .map_err(|e| self.lost("byte write", reg, e))
        }

        fn read_word(&mut self, reg: u8) -> Result<u16, BusError> {
            self.dev
                .smbus_read_word_data(reg)
                .map_err(|e| self.lost("word read", reg, e))
        }

        fn read_byte(&mut self, reg: u8) -> Result<u8, BusError> {
            self.dev
                .smbus_read_byte_data(reg)
                .map_err(|e| self.lost("byte read", reg, e))
        }

        fn now(&self) -> Duration {
            self.clock.now()
        }

        fn sleep(&mut self, d: Duration) {
            std::thread::sleep(d);
        }

        fn describe(&self) -> String {
            format!("i2c {} @ 0x{:02X}", self.path, self.address)
        }
    }
}

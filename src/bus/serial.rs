//! Serial-port back-end: 115200 baud, 8N1, no flow control, input flushed at open. Works on
//! the real board's USB-serial port and on the mock's pseudo-terminal alike.
use std::io::{ErrorKind, Read, Write};
use std::time::Duration;

use serialport::{ClearBuffer, DataBits, FlowControl, Parity, SerialPort, StopBits};

use super::error::BusError;
use super::transport::{RealClock, Transport};

/// DOFBOT.md: the board's UART speed.
pub const BAUD: u32 = 115_200;

/// A serial port opened for the DOFBOT board.
pub struct SerialTransport {
    port: Box<dyn SerialPort>,
    path: String,
    clock: RealClock,
}

impl SerialTransport {
    /// Opens `path` at 115200 8N1 and flushes stale input (the USB bridge can hold some).
    pub fn open(path: &str) -> Result<SerialTransport, BusError> {
        let open_err = |e: serialport::Error| BusError::Open {
            port: path.to_string(),
            detail: e.to_string(),
        };
        let port = serialport::new(path, BAUD)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            .timeout(Duration::from_millis(10))
            .open()
            .map_err(open_err)?;
        let mut t = SerialTransport {
            port,
            path: path.to_string(),
            clock: RealClock::new(),
        };
        t.clear_input()?;
        Ok(t)
    }
}

fn lost(e: impl std::fmt::Display) -> BusError {
    BusError::PortLost {
        detail: e.to_string(),
    }
}

impl Transport for SerialTransport {
    fn write(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        self.port.write_all(bytes).map_err(lost)?;
        self.port.flush().map_err(lost)
    }

    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, BusError> {
        self.port
            .set_timeout(timeout.max(Duration::from_micros(1)))
            .map_err(lost)?;
        match self.port.read(buf) {
            Ok(0) => Err(lost("end of file on the port")),
            Ok(n) => Ok(n),
            Err(e) if e.kind() == ErrorKind::TimedOut => Ok(0),
            Err(e) if e.kind() == ErrorKind::Interrupted => Ok(0),
            Err(e) => Err(lost(e)),
        }
    }

    fn clear_input(&mut self) -> Result<(), BusError> {
        self.port.clear(ClearBuffer::Input).map_err(lost)
    }

    fn now(&self) -> Duration {
        self.clock.now()
    }

    fn sleep(&mut self, d: Duration) {
        std::thread::sleep(d);
    }

    fn describe(&self) -> String {
        self.path.clone()
    }
}

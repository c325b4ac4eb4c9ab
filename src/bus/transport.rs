//! The byte pipe under the driver, and its clock. Back-ends: a serial port (real arm, or the
//! Python mock on a pseudo-terminal) and the in-process simulated arm.
use std::time::{Duration, Instant};

use super::error::BusError;

/// A bidirectional byte link with its own clock (the simulator's may be virtual).
pub trait Transport: Send {
    /// Writes every byte; a failure means the port is lost.
    fn write(&mut self, bytes: &[u8]) -> Result<(), BusError>;
    /// Reads what is available, waiting at most `timeout`; `Ok(0)` when nothing came.
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, BusError>;
    /// Discards bytes received and not yet read.
    fn clear_input(&mut self) -> Result<(), BusError>;
    /// Time since the transport was opened.
    fn now(&self) -> Duration;
    /// Waits `d` (virtual transports advance their clock instead).
    fn sleep(&mut self, d: Duration);
    /// Human-readable name of the link (port path, "sim").
    fn describe(&self) -> String;
}

/// A boxed transport is a transport (the CLI picks the back-end at run time).
impl<T: Transport + ?Sized> Transport for Box<T> {
    fn write(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        (**self).write(bytes)
    }
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, BusError> {
        (**self).read(buf, timeout)
    }
    fn clear_input(&mut self) -> Result<(), BusError> {
        (**self).clear_input()
    }
    fn now(&self) -> Duration {
        (**self).now()
    }
    fn sleep(&mut self, d: Duration) {
        (**self).sleep(d)
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
}

/// Wall-clock time since a start instant.
#[derive(Debug, Clone, Copy)]
pub struct RealClock {
    start: Instant,
}

impl RealClock {
    /// A clock starting now.
    pub fn new() -> RealClock {
        RealClock {
            start: Instant::now(),
        }
    }

    /// Time since the start.
    pub fn now(&self) -> Duration {
        self.start.elapsed()
    }
}

impl Default for RealClock {
    fn default() -> Self {
        RealClock::new()
    }
}

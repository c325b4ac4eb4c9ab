//! Which servos answer, and on what evidence. A servo is alive when its position reads back
//! (a valid raw position of its own). Pings are extra evidence only: Yahboom's serial
//! `Arm_ping_servo` writes 0x38 and never reads a reply, and no published code fixes a serial
//! ping reply frame, so a board that sends none is reported, not refused. A servo that answers
//! neither a ping nor a read is an error.
use std::time::Duration;

use serde::Serialize;

use dofbot_protocol::replies::PING_ALIVE;
use dofbot_protocol::servo::ServoId;
use dofbot_protocol::{BusId, Command, Reply};

use super::driver::Bus;
use super::error::BusError;
use super::journal::EntryKind;
use super::transport::Transport;

/// What one servo answered.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ServoAnswer {
    /// Servo id 1..6.
    pub id: u8,
    /// Status byte of its ping reply (0xDA alive), `None` when no ping reply came.
    pub ping_status: Option<u8>,
    /// Its raw position, `None` when the read failed.
    pub raw: Option<u16>,
    /// The read's error, when it failed.
    pub read_error: Option<String>,
    /// The same error, typed.
    #[serde(skip)]
    pub read_failure: Option<BusError>,
}

impl ServoAnswer {
    /// Alive: the position read back.
    pub fn alive(&self) -> bool {
        self.raw.is_some()
    }
}

/// The answers of all six servos and the evidence they give.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Liveness {
    /// One per servo, 1..6.
    pub servos: Vec<ServoAnswer>,
}

impl Liveness {
    /// One line saying which evidence the verdict rests on.
    pub fn evidence(&self) -> String {
        let pings = self
            .servos
            .iter()
            .filter(|s| s.ping_status.is_some())
            .count();
        let reads = self.servos.iter().filter(|s| s.alive()).count();
        let n = self.servos.len();
        match (pings, reads) {
            (0, r) if r == n => format!("no ping replies; all {} servos answered reads", words(n)),
            (p, r) if p == n && r == n => {
                format!(
                    "ping replies and reads: all {} servos answered both",
                    words(n)
                )
            }
            (p, r) => format!("{p} of {n} servos answered pings, {r} of {n} answered reads"),
        }
    }

    /// The first servo whose position did not read back, with the error that says why:
    /// [`BusError::NotAnswering`] when its read got no reply and its ping said it is not
    /// there, else its read's error.
    pub fn first_failure(&self) -> Option<BusError> {
        let s = self.servos.iter().find(|s| !s.alive())?;
        let read = s.read_failure.clone()?;
        Some(verdict(s.id, read, s.ping_status))
    }
}

/// The error of servo `servo` whose read failed with `read`: when the read got no reply and a
/// ping reply says the servo is not there (a status other than 0xDA), it is not answering;
/// otherwise the read's own error stands (with no ping reply at all, the read's timeout).
fn verdict(servo: u8, read: BusError, ping_status: Option<u8>) -> BusError {
    match (&read, ping_status) {
        (BusError::Timeout { .. }, Some(status)) if status != PING_ALIVE => {
            BusError::NotAnswering {
                servo,
                detail: format!("ping status 0x{status:02X} and its read got no reply ({read})"),
            }
        }
        _ => read,
    }
}

impl<T: Transport> Bus<T> {
    /// Pings bus servo `id` once: the status byte of its reply (0xDA alive), or `None` when no
    /// ping reply came within the read timeout (boards may send none). Not retried: a board
    /// that never answers pings would only cost time.
    pub fn ping(&mut self, id: u8) -> Result<Option<u8>, BusError> {
        let bus_id = BusId::new(id).map_err(|e| BusError::Refused(e.to_string()))?;
        let cmd = Command::Ping(bus_id);
        let timeout = Duration::from_secs_f64(self.config().read_timeout_ms.max(0.0) / 1000.0);
        let what = format!("{} (0x{:02X})", cmd.name(), cmd.func());
        self.begin_request(&cmd)?;
        let got = self.await_reply(&what, 1, timeout, &|r: &Reply, _| match *r {
            Reply::Ping { id: got, status } if got.is_none_or(|g| g == id) => Some(Ok(status)),
            _ => None,
        });
        match got {
            Ok(status) => Ok(Some(status)),
            Err(BusError::Timeout { .. } | BusError::BadChecksum { .. }) => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Pings and reads every servo (`ping`: also ping each first) and reports what each
    /// answered. Only a lost link is an error here.
    pub fn liveness(&mut self, ping: bool) -> Result<Liveness, BusError> {
        let mut servos = Vec::new();
        for id in ServoId::ALL {
            let ping_status = if ping { self.ping(id.get())? } else { None };
            let (raw, read_error) = match self.read_raw(id) {
                Ok(raw) => (Some(raw), None),
                Err(e @ BusError::PortLost { .. }) => return Err(e),
                Err(e) => (None, Some(e)),
            };
            servos.push(ServoAnswer {
                id: id.get(),
                ping_status,
                raw,
                read_error: read_error.as_ref().map(|e| e.to_string()),
                read_failure: read_error,
            });
        }
        Ok(Liveness { servos })
    }

    /// Checks at connect that all six servos answer: each is read, and pinged only when its
    /// read got no reply. A servo whose ping then says it is not there is
    /// [`BusError::NotAnswering`]; any other failed read keeps its own error.
    pub fn check_servos(&mut self) -> Result<(), BusError> {
        for id in ServoId::ALL {
            let err = match self.read_raw(id) {
                Ok(_) => continue,
                Err(e @ BusError::Timeout { .. }) => e,
                Err(e) => return Err(e),
            };
            let status = self.ping(id.get())?;
            let e = verdict(id.get(), err, status);
            self.log_error(&e, None, EntryKind::Error)?;
            return Err(e);
        }
        Ok(())
    }
}

/// "six" for the whole arm, else the number.
fn words(n: usize) -> String {
    match n {
        6 => "six".into(),
        n => n.to_string(),
    }
}

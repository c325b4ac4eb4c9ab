//! Typed bus errors, each displayed as one line.
use thiserror::Error;

/// What can go wrong on the bus.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum BusError {
    /// The port could not be opened.
    #[error("cannot open {port}: {detail}")]
    Open {
        /// Port path.
        port: String,
        /// OS message.
        detail: String,
    },
    /// The port vanished or failed while in use (unplugged, device closed).
    #[error("port lost: {detail}")]
    PortLost {
        /// OS message.
        detail: String,
    },
    /// No (valid) reply within the timeout, after every retry.
    #[error("timeout: no reply to {what} within {ms} ms after {attempts} attempts")]
    Timeout {
        /// The request.
        what: String,
        /// Timeout per attempt, ms.
        ms: u64,
        /// Attempts made.
        attempts: u32,
    },
    /// Replies arrived but failed their checksum or length, after every retry.
    #[error("bad checksum: {detail} (reply to {what}, {attempts} attempts)")]
    BadChecksum {
        /// The request.
        what: String,
        /// Decoder message.
        detail: String,
        /// Attempts made.
        attempts: u32,
    },
    /// A servo answered neither a read nor a ping.
    #[error("servo {servo} not answering: {detail}")]
    NotAnswering {
        /// Servo id.
        servo: u8,
        /// What was tried.
        detail: String,
    },
    /// A position read returned 0 or a value outside the servo's range, after every retry.
    #[error("read failure: servo {servo} returned raw {raw} (outside {min}..{max}) after {attempts} attempts")]
    ReadFailure {
        /// Servo id.
        servo: u8,
        /// Last raw value read.
        raw: u16,
        /// Lowest valid raw.
        min: u16,
        /// Highest valid raw.
        max: u16,
        /// Attempts made.
        attempts: u32,
    },
    /// After a move, a servo is not where it was sent.
    #[error("read-back mismatch: servo {servo} at raw {got}, commanded {expected} (tolerance {tolerance})")]
    ReadBackMismatch {
        /// Servo id.
        servo: u8,
        /// Commanded raw.
        expected: u16,
        /// Read raw.
        got: u16,
        /// Allowed difference in counts.
        tolerance: u16,
    },
    /// Motion refused before anything was sent (joint limit, servo range, speed).
    #[error("refused: {0}")]
    Refused(String),
    /// Stopped by the operator (Ctrl-C): no further motion frames.
    #[error("stopped by the operator: no further motion sent")]
    Stopped,
    /// The journal could not be written or read.
    #[error("journal {path}: {detail}")]
    Journal {
        /// Journal path.
        path: String,
        /// What went wrong.
        detail: String,
    },
}

impl From<crate::robot::MapRefused> for BusError {
    fn from(e: crate::robot::MapRefused) -> Self {
        BusError::Refused(e.0)
    }
}

impl BusError {
    /// Short stable code of the error kind, as written in the journal.
    pub fn code(&self) -> &'static str {
        match self {
            BusError::Open { .. } => "open",
            BusError::PortLost { .. } => "port_lost",
            BusError::Timeout { .. } => "timeout",
            BusError::BadChecksum { .. } => "bad_checksum",
            BusError::NotAnswering { .. } => "not_answering",
            BusError::ReadFailure { .. } => "read_failure",
            BusError::ReadBackMismatch { .. } => "read_back_mismatch",
            BusError::Refused(_) => "refused",
            BusError::Stopped => "stopped",
            BusError::Journal { .. } => "journal",
        }
    }
}

//! `journal.jsonl`: one JSON object per line for every frame sent, every reply received,
//! every error and each verified pose, flushed line by line so that a crash or a lost port
//! leaves a consistent file. Format: `docs/FORMATS.md`. [`ResumePoint`] reads one back.
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use super::error::BusError;

/// Kind of a journal line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EntryKind {
    /// The bus was opened on a port.
    Open,
    /// A frame was written (after the write succeeded).
    Tx,
    /// A frame (or, for bad frames, the error) was received.
    Rx,
    /// An error, transient (retried) or final.
    Error,
    /// A read-back confirmed a motion.
    Verified,
    /// Motion stopped (operator, fault); nothing more was sent.
    Stop,
    /// The plan stops for the operator (code: `refixture`, later `tool_change`): the part of
    /// the plan before it is done, the run continues with `run --resume` at `setup`.
    OperatorStop,
}

/// One line of the journal.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// Line number in this run, from 0.
    pub seq: u64,
    /// Seconds since the bus was opened (the transport's clock).
    pub t: f64,
    /// Wall-clock time, ms since the Unix epoch.
    pub unix_ms: u64,
    /// What happened.
    pub kind: EntryKind,
    /// Frame bytes as uppercase hex pairs separated by spaces (tx, rx).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<String>,
    /// Command or reply name (tx, rx).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Motion index of a motion frame (tx, error while sending one, verified, stop).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<u64>,
    /// Error code (`BusError::code`) of an error or stop line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code: Option<String>,
    /// One-line message (error, stop) or port description (open).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    /// Raw positions of servos 1..6 (verified).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw: Option<Vec<u16>>,
    /// SHA-256 (lowercase hex) of the plan file this run streams (open lines of `run`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan_sha256: Option<String>,
    /// The plan's setup streamed (open lines of setup 2 on) or to continue with (operator
    /// stops); absent: setup 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setup: Option<u64>,
}

impl Entry {
    /// An entry of `kind` with every optional field empty (seq, t and time set by the
    /// journal).
    pub fn new(kind: EntryKind) -> Entry {
        Entry {
            seq: 0,
            t: 0.0,
            unix_ms: 0,
            kind,
            frame: None,
            name: None,
            motion: None,
            code: None,
            message: None,
            raw: None,
            plan_sha256: None,
            setup: None,
        }
    }
}

/// Hex form of frame bytes used in the journal: `FF FC 07 11 ...`.
pub fn hex(bytes: &[u8]) -> String {
    dofbot_protocol::Hex(bytes).to_string()
}

/// Appends entries to a journal file (or discards them when there is none).
pub struct Journal {
    file: Option<(File, PathBuf)>,
    seq: u64,
    plan_sha256: Option<String>,
    setup: Option<u64>,
}

impl Journal {
    /// No journal.
    pub fn none() -> Journal {
        Journal {
            file: None,
            seq: 0,
            plan_sha256: None,
            setup: None,
        }
    }

    /// Appends to `path` (created if missing; a resumed run continues the same file).
    pub fn append(path: &Path) -> Result<Journal, BusError> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| journal_err(path, e))?;
        Ok(Journal {
            file: Some((file, path.to_path_buf())),
            seq: 0,
            plan_sha256: None,
            setup: None,
        })
    }

    /// Ties the journal to a plan: every open line it writes records `sha256` (the plan
    /// file's SHA-256, lowercase hex), which `run --resume` compares with the plan it is given.
    pub fn for_plan(mut self, sha256: &str) -> Journal {
        self.plan_sha256 = Some(sha256.to_string());
        self
    }

    /// Marks the run as streaming the plan's setup `setup` (2 on): every open line records it,
    /// and `run --resume` counts the frames of each setup apart.
    pub fn for_setup(mut self, setup: u64) -> Journal {
        self.setup = (setup > 1).then_some(setup);
        self
    }

    /// Writes one entry stamped with `t` (s), flushed at once.
    pub fn write(&mut self, mut entry: Entry, t: f64) -> Result<(), BusError> {
        let Some((file, path)) = self.file.as_mut() else {
            return Ok(());
        };
        entry.seq = self.seq;
        entry.t = t;
        if entry.kind == EntryKind::Open {
            entry.plan_sha256.clone_from(&self.plan_sha256);
            entry.setup = self.setup;
        }
        entry.unix_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_millis() as u64)
            .unwrap_or(0);
        self.seq += 1;
        let mut line = serde_json::to_string(&entry).map_err(|e| journal_err(path, e))?;
        line.push('\n');
        file.write_all(line.as_bytes())
            .and_then(|_| file.flush())
            .map_err(|e| journal_err(path, e))
    }
}

fn journal_err(path: &Path, e: impl std::fmt::Display) -> BusError {
    BusError::Journal {
        path: path.display().to_string(),
        detail: e.to_string(),
    }
}

/// Where a run stood according to its journal.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ResumePoint {
    /// Highest motion index whose frame was written.
    pub last_sent: Option<u64>,
    /// Highest motion index whose write failed: the bytes may still have reached the board
    /// (a write that times out on a loaded machine may have been delivered), so a resume
    /// starts no earlier than it.
    pub last_failed_write: Option<u64>,
    /// Highest motion index confirmed by a read-back.
    pub last_verified: Option<u64>,
    /// Code and message of the last error or stop line, if any.
    pub last_error: Option<(String, String)>,
    /// Lines read.
    pub lines: usize,
    /// The plan SHA-256 of every open line that has one, in file order, repeats removed.
    pub plan_sha256: Vec<String>,
    /// The setup the last open line streamed (1 when none says): the motion indices above
    /// count within it (an open line of another setup starts them afresh).
    pub setup: u64,
    /// The last operator stop not yet followed by a run of the setup it names: its code
    /// (`refixture`) and that setup.
    pub operator_stop: Option<(String, u64)>,
}

impl ResumePoint {
    /// Reads a journal. A last line cut short by a crash (no newline after it) is ignored;
    /// any other unreadable line, a file that is not a regular file, and a file without one
    /// journal line are errors naming the file (and the line).
    pub fn from_journal(path: &Path) -> Result<ResumePoint, BusError> {
        let meta = std::fs::metadata(path).map_err(|e| journal_err(path, e))?;
        if !meta.is_file() {
            return Err(journal_err(path, "not a regular file"));
        }
        let mut bytes = Vec::new();
        File::open(path)
            .and_then(|f| f.take(meta.len()).read_to_end(&mut bytes))
            .map_err(|e| journal_err(path, e))?;
        ResumePoint::parse(path, &bytes)
    }

    /// Reads a journal's bytes; `path` names it in errors. The rules of
    /// [`ResumePoint::from_journal`] (which reads the file and calls this).
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<ResumePoint, BusError> {
        let complete = bytes.ends_with(b"\n");
        let lines: Vec<&[u8]> = bytes.split(|&b| b == b'\n').collect();
        let mut rp = ResumePoint {
            setup: 1,
            ..ResumePoint::default()
        };
        for (i, line) in lines.iter().enumerate() {
            let last = i + 1 == lines.len();
            let at = |e: &dyn std::fmt::Display| journal_err(path, format!("line {}: {e}", i + 1));
            let entry = match std::str::from_utf8(line) {
                Ok(text) if text.trim().is_empty() => continue,
                Ok(text) => serde_json::from_str::<Entry>(text),
                Err(_) if last && !complete => break,
                Err(e) => return Err(at(&e)),
            };
            let entry = match entry {
                Ok(e) => e,
                Err(_) if last && !complete => break,
                Err(e) => return Err(at(&e)),
            };
            rp.take(entry);
        }
        if rp.lines == 0 {
            return Err(journal_err(path, "no journal line in the file"));
        }
        Ok(rp)
    }

    fn take(&mut self, entry: Entry) {
        self.lines += 1;
        match entry.kind {
            EntryKind::Tx => self.last_sent = self.last_sent.max(entry.motion),
            EntryKind::Verified => self.last_verified = self.last_verified.max(entry.motion),
            EntryKind::Error | EntryKind::Stop => {
                if entry.kind == EntryKind::Error {
                    self.last_failed_write = self.last_failed_write.max(entry.motion);
                }
                self.last_error = Some((
                    entry.code.unwrap_or_default(),
                    entry.message.unwrap_or_default(),
                ))
            }
            EntryKind::OperatorStop => {
                self.operator_stop = Some((
                    entry.code.unwrap_or_default(),
                    entry.setup.unwrap_or(self.setup),
                ))
            }
            EntryKind::Open => {
                let setup = entry.setup.unwrap_or(1);
                if setup != self.setup {
                    // a run of another setup: its frames count from 0
                    self.setup = setup;
                    self.last_sent = None;
                    self.last_failed_write = None;
                    self.last_verified = None;
                    self.last_error = None;
                }
                if self.operator_stop.as_ref().is_some_and(|s| s.1 == setup) {
                    self.operator_stop = None;
                }
                if let Some(h) = entry.plan_sha256 {
                    if !self.plan_sha256.contains(&h) {
                        self.plan_sha256.push(h);
                    }
                }
            }
            EntryKind::Rx => {}
        }
    }

    /// First motion index to send when resuming: the last one written or whose write failed
    /// (re-sent, since motion frames carry absolute targets and the interrupted one may or may
    /// not have arrived), or 0. Starting earlier would drive the arm back along its path.
    pub fn resume_from(&self) -> u64 {
        self.last_sent.max(self.last_failed_write).unwrap_or(0)
    }
}

//! An in-process fake of the board's I2C interface with the simulated arm behind it: it takes
//! the SMBus transactions of Yahboom's smbus `Arm_Lib.py` (see `dofbot_protocol::i2c`), hands
//! the command they make up to the simulator and serves its answer from the register it was
//! asked on, and records every transaction (optionally also to a JSON-lines file). Tests use
//! it to check the transactions byte for byte and to run `arm`, `run` and `calibrate` end to
//! end over I2C (`POLISHBOT_TEST_FAKE_I2C`, test-only).
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::json;

use dofbot_protocol::i2c::{Transaction, REG_MOVE_ALL_TIME};
use dofbot_protocol::servo::SERVO_COUNT;
use dofbot_protocol::{Command, Frame, OffsetState, Reply};

use super::arm::SimArm;
use crate::bus::error::BusError;
use crate::bus::i2c::I2cBus;

/// One transaction the fake device took: when (s, sim clock), which, and the value it read.
#[derive(Debug, Clone, PartialEq)]
pub struct I2cRecord {
    /// Sim clock, seconds.
    pub t: f64,
    /// The transaction (reads as requested).
    pub op: Transaction,
    /// Value returned by a read.
    pub value: Option<u16>,
}

impl I2cRecord {
    /// The record as one JSON object: `{"t", "op", "reg", "data" | "value"}`.
    pub fn to_json(&self) -> serde_json::Value {
        let (op, reg) = match self.op {
            Transaction::WriteBlock { reg, .. } => ("write_block", reg),
            Transaction::WriteByte { reg, .. } => ("write_byte", reg),
            Transaction::ReadWord { reg } => ("read_word", reg),
            Transaction::ReadByte { reg } => ("read_byte", reg),
            Transaction::Wait { .. } => ("wait", 0),
        };
        let data: Vec<u8> = match self.op {
            Transaction::WriteByte { value, .. } => vec![value],
            _ => self.op.block_bytes().to_vec(),
        };
        json!({"t": self.t, "op": op, "reg": reg, "data": data, "value": self.value})
    }
}

/// The fake board on I2C (see the module doc).
pub struct FakeI2c {
    arm: SimArm,
    address: u16,
    move_time: [u8; 2],
    registers: HashMap<u8, u16>,
    records: Arc<Mutex<Vec<I2cRecord>>>,
    log: Option<BufWriter<File>>,
}

impl FakeI2c {
    /// A fake board at `address` in front of `arm`.
    pub fn new(arm: SimArm, address: u16) -> FakeI2c {
        FakeI2c {
            arm,
            address,
            move_time: [0, 0],
            registers: HashMap::new(),
            records: Arc::new(Mutex::new(Vec::new())),
            log: None,
        }
    }

    /// The same, also writing every record as a JSON line to `path` (created or truncated).
    pub fn logging_to(mut self, path: &Path) -> Result<FakeI2c, BusError> {
        let file = File::create(path).map_err(|e| BusError::Open {
            port: path.display().to_string(),
            detail: e.to_string(),
        })?;
        self.log = Some(BufWriter::new(file));
        Ok(self)
    }

    /// Every transaction so far (a handle that stays valid after the device is dropped).
    pub fn records(&self) -> Arc<Mutex<Vec<I2cRecord>>> {
        self.records.clone()
    }

    /// The arm behind the device.
    pub fn arm(&self) -> &SimArm {
        &self.arm
    }

    fn record(&mut self, op: Transaction, value: Option<u16>) -> Result<(), BusError> {
        let rec = I2cRecord {
            t: self.arm.time(),
            op,
            value,
        };
        if let Some(log) = &mut self.log {
            writeln!(log, "{}", rec.to_json()).map_err(|e| BusError::PortLost {
                detail: format!("fake i2c log: {e}"),
            })?;
        }
        self.records
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(rec);
        if self.arm.disconnected() {
            return Err(BusError::PortLost {
                detail: "fake i2c board disconnected".into(),
            });
        }
        Ok(())
    }

    /// Runs the command `func`/`payload` make up on the simulator and keeps its answer in
    /// register `func` as the bus would deliver it (a position word little-endian). A frame
    /// that is no valid command is ignored, as the board ignores it; no answer reads as 0.
    fn execute(&mut self, func: u8, payload: &[u8]) {
        let cmd = Frame::new(func, payload)
            .ok()
            .and_then(|f| Command::parse(&f).ok());
        let answer = cmd.and_then(|c| self.arm.command(&c));
        let value = match answer {
            Some(Reply::Position { raw, .. } | Reply::AnyPosition { raw }) => raw.swap_bytes(),
            Some(Reply::Ping { status, .. }) => status as u16,
            Some(Reply::OffsetState(s)) => match s {
                OffsetState::NotFound => 0,
                OffsetState::Ok => 1,
                OffsetState::Failed => 2,
            },
            Some(Reply::Version(v) | Reply::ActionCount(v)) => v as u16,
            None => 0,
        };
        self.registers.insert(func, value);
    }
}

impl I2cBus for FakeI2c {
    fn write_block(&mut self, reg: u8, data: &[u8]) -> Result<(), BusError> {
        self.record(Transaction::block(reg, data), None)?;
        match (reg, data.len()) {
            (REG_MOVE_ALL_TIME, 2) => self.move_time = [data[0], data[1]],
            (dofbot_protocol::commands::FUNC_MOVE_ALL, n) if n == 2 * SERVO_COUNT => {
                let mut payload = data.to_vec();
                payload.extend_from_slice(&self.move_time);
                self.execute(reg, &payload);
            }
            _ => self.execute(reg, data),
        }
        Ok(())
    }

    fn write_byte(&mut self, reg: u8, value: u8) -> Result<(), BusError> {
        self.record(Transaction::WriteByte { reg, value }, None)?;
        use dofbot_protocol::commands::{FUNC_OFFSET_STATE, FUNC_VERSION};
        match reg {
            // Requests whose serial frame has no payload: the byte only triggers them.
            0x31..=0x36 | FUNC_OFFSET_STATE | FUNC_VERSION => self.execute(reg, &[]),
            _ => self.execute(reg, &[value]),
        }
        Ok(())
    }

    fn read_word(&mut self, reg: u8) -> Result<u16, BusError> {
        let v = self.registers.get(&reg).copied().unwrap_or(0);
        self.record(Transaction::ReadWord { reg }, Some(v))?;
        Ok(v)
    }

    fn read_byte(&mut self, reg: u8) -> Result<u8, BusError> {
        let v = self.registers.get(&reg).copied().unwrap_or(0) as u8;
        self.record(Transaction::ReadByte { reg }, Some(v as u16))?;
        Ok(v)
    }

    fn now(&self) -> Duration {
        Duration::from_secs_f64(self.arm.time())
    }

    fn sleep(&mut self, d: Duration) {
        self.arm.advance(d);
    }

    fn describe(&self) -> String {
        format!("i2c fake @ 0x{:02X}", self.address)
    }
}

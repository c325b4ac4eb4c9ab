//! An independent DOFBOT board for the turntable tests, written from Yahboom's serial
//! `Arm_Lib.py` and DOFBOT.md, not from polishbot's bus model: it frames bytes itself
//! (`FF FC LEN FUNC payload CHK`, CHK = `sum(cmd, 5) & 0xff` as Arm_Lib computes it), moves
//! the six arm servos on 0x1D (`Arm_serial_servo_write6`), serves one extra bus servo (the
//! turntable) on 0x19 (`Arm_serial_servo_write_any`: `[0x19, id, posH, posL, timeH, timeL]`)
//! and 0x37 (`Arm_serial_servo_read_any`: the reply's two position bytes low byte first,
//! which the library swaps), answers 0x31..0x36 reads as `__parse_data` reads them
//! (`servo_H, servo_L, 0x30+id`) and pings with 0xDA. Servos reach a target at once. Every
//! 0x19 frame is judged as it arrives against the table's numbers from servos.toml: id, raw
//! range, and the raw step against the velocity limit over the frame's time.
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use polishbot::bus::{BusError, Transport};

/// What the board knows of its table servo (from the cell's servos.toml `[turntable]`).
#[derive(Debug, Clone, Copy)]
pub struct TableServo {
    /// Bus id.
    pub id: u8,
    /// Raw range.
    pub raw_range: [u16; 2],
    /// Counts per radian of table angle.
    pub counts_per_rad: f64,
    /// Velocity limit, rad/s.
    pub velocity: f64,
}

/// A 0x19 frame the board took.
#[derive(Debug, Clone, PartialEq)]
pub struct AnyFrame {
    /// Board clock at arrival, s.
    pub t: f64,
    /// Bus id.
    pub id: u8,
    /// Raw target.
    pub raw: u16,
    /// Move time, ms.
    pub time_ms: u16,
}

/// The board's state, shared with the test.
#[derive(Debug, Default)]
pub struct State {
    /// Arm servo positions 1..6.
    pub arm: [u16; 6],
    /// Table servo position.
    pub table: u16,
    /// Every 0x19 frame.
    pub any_frames: Vec<AnyFrame>,
    /// Every complaint about a frame.
    pub faults: Vec<String>,
    clock: Duration,
    input: Vec<u8>,
    output: VecDeque<u8>,
}

/// The board behind a [`Transport`].
#[derive(Clone)]
pub struct Board {
    table: TableServo,
    /// The shared state.
    pub state: Arc<Mutex<State>>,
}

/// Slack on the velocity judgement: one count of rounding plus 1 % (the planner's finite
/// difference slack).
const STEP_SLACK: f64 = 0.01;

fn reply(kind: u8, data: &[u8]) -> Vec<u8> {
    let len = data.len() as u8 + 3;
    let sum = data
        .iter()
        .fold(len as u32 + kind as u32, |s, b| s + *b as u32);
    let mut out = vec![0xFF, 0xFB, len, kind];
    out.extend_from_slice(data);
    out.push((sum % 256) as u8);
    out
}

impl Board {
    /// A board whose arm rests at `arm` and table at `table_raw`.
    pub fn new(table: TableServo, arm: [u16; 6], table_raw: u16) -> Board {
        let state = State {
            arm,
            table: table_raw,
            ..State::default()
        };
        Board {
            table,
            state: Arc::new(Mutex::new(state)),
        }
    }

    fn take(&self, s: &mut State, cmd: &[u8]) {
        let func = cmd[3];
        let p = &cmd[4..cmd.len() - 1];
        let word = |i: usize| u16::from(p[i]) << 8 | u16::from(p[i + 1]);
        match (func, p.len()) {
            (0x1D, 14) => {
                for i in 0..6 {
                    s.arm[i] = word(2 * i);
                }
            }
            (0x19, 5) => {
                let f = AnyFrame {
                    t: s.clock.as_secs_f64(),
                    id: p[0],
                    raw: word(1),
                    time_ms: word(3),
                };
                self.judge(s, &f);
                if f.id == self.table.id {
                    s.table = f.raw;
                }
                s.any_frames.push(f);
            }
            (0x31..=0x36, 0) => {
                let pos = s.arm[(func - 0x31) as usize];
                let out = reply(0x0A, &[(pos >> 8) as u8, pos as u8, func]);
                s.output.extend(out);
            }
            (0x37, 1) if p[0] == self.table.id => {
                let pos = s.table;
                let out = reply(0x0A, &[pos as u8, (pos >> 8) as u8, 0x37]);
                s.output.extend(out);
            }
            (0x38, 1) => {
                let alive = (1..=6).contains(&p[0]) || p[0] == self.table.id;
                s.output
                    .extend(reply(0x38, &[if alive { 0xDA } else { 0 }]));
            }
            (0x01, 0) => s.output.extend(reply(0x01, &[1])),
            _ => {}
        }
    }

    fn judge(&self, s: &mut State, f: &AnyFrame) {
        let t = &self.table;
        if f.id != t.id {
            s.faults
                .push(format!("0x19 for id {} at {:.3} s", f.id, f.t));
            return;
        }
        if f.raw < t.raw_range[0] || f.raw > t.raw_range[1] {
            s.faults
                .push(format!("0x19 raw {} outside {:?}", f.raw, t.raw_range));
        }
        let most = t.velocity * f64::from(f.time_ms) / 1000.0 * t.counts_per_rad;
        let step = f64::from(f.raw.abs_diff(s.table));
        if step > most * (1.0 + STEP_SLACK) + 1.0 {
            s.faults.push(format!(
                "0x19 step {step} counts in {} ms, the velocity limit allows {most:.1}",
                f.time_ms
            ));
        }
    }
}

impl Transport for Board {
    fn write(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        let mut s = self.state.lock().unwrap();
        s.input.extend_from_slice(bytes);
        while let Some(at) = s.input.windows(2).position(|w| w == [0xFF, 0xFC]) {
            s.input.drain(..at);
            if s.input.len() < 3 || s.input.len() < s.input[2] as usize + 2 {
                break;
            }
            let n = s.input[2] as usize + 2;
            let cmd: Vec<u8> = s.input.drain(..n).collect();
            // Arm_Lib: checksum = sum(cmd, 5) & 0xff over FF FC LEN FUNC payload
            let sum = cmd[..n - 1].iter().fold(5u32, |a, b| a + *b as u32);
            if (sum & 0xFF) as u8 != cmd[n - 1] {
                s.faults.push(format!("bad checksum in {cmd:02X?}"));
                continue;
            }
            self.take(&mut s, &cmd);
        }
        Ok(())
    }

    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, BusError> {
        let mut s = self.state.lock().unwrap();
        if s.output.is_empty() {
            s.clock += timeout;
            return Ok(0);
        }
        let n = s.output.len().min(buf.len());
        for b in buf.iter_mut().take(n) {
            *b = s.output.pop_front().unwrap();
        }
        Ok(n)
    }

    fn clear_input(&mut self) -> Result<(), BusError> {
        self.state.lock().unwrap().output.clear();
        Ok(())
    }

    fn now(&self) -> Duration {
        self.state.lock().unwrap().clock
    }

    fn sleep(&mut self, d: Duration) {
        self.state.lock().unwrap().clock += d;
    }

    fn describe(&self) -> String {
        "turntable test board".into()
    }
}

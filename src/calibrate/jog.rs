//! Touches for the routines: [`Scripted`] moves the arm to listed joint targets (tests, repeat
//! runs); [`JogTerminal`] lets the operator jog joint by joint from the keyboard (raw terminal
//! mode through [`RawTerminal`]) and record a touch with a key. Both read the pose back
//! several times and give the tool tip by forward kinematics.
use std::io::{Read, Write};

use nalgebra::Vector3;

use super::config::{CalibError, CalibrationConfig};
use super::read::{joints_of, read_mean};
use crate::bus::{Bus, BusError, ServoMap, Transport, JOINT_COUNT};
use crate::robot::units::mm;
use crate::robot::Robot;

/// The cell a routine works in: the robot model, the bus's servo map, the gripper's hold angle
/// and the settings.
pub struct Cell<'a> {
    /// Robot model (URDF, tool, servos).
    pub robot: &'a Robot,
    /// The bus's servo map (from the same servos.toml).
    pub map: &'a ServoMap,
    /// Gripper angle held during every move, degrees.
    pub gripper_deg: f64,
    /// Settings.
    pub cfg: &'a CalibrationConfig,
}

/// One recorded touch.
#[derive(Debug, Clone, PartialEq)]
pub struct Touch {
    /// What was touched (`pivot 3`, a fiducial's name).
    pub label: String,
    /// Read-back joint angles (mean of several reads), rad.
    pub joints: [f64; JOINT_COUNT],
    /// Tool tip by forward kinematics of `joints`, robot base frame, metres.
    pub tip: [f64; 3],
}

impl Touch {
    /// The tool tip as a vector, metres.
    pub fn tip(&self) -> Vector3<f64> {
        Vector3::from(self.tip)
    }
}

/// Reads the pose back `cfg.touch_reads` times and records a touch there.
pub fn record<T: Transport>(
    bus: &mut Bus<T>,
    cell: &Cell,
    label: &str,
) -> Result<Touch, CalibError> {
    let read = read_mean(bus, cell.cfg.touch_reads, cell.cfg.max_spread_counts)?;
    let joints = joints_of(cell.map, &read)?;
    let tip = cell.robot.fk(&joints).position;
    Ok(Touch {
        label: label.to_string(),
        joints,
        tip: [tip.x, tip.y, tip.z],
    })
}

/// Where touches come from.
pub trait TouchSource<T: Transport> {
    /// Collects the touch labelled `label`; `None` when there are no more (the script ended
    /// or the operator pressed "done").
    fn touch(
        &mut self,
        bus: &mut Bus<T>,
        cell: &Cell,
        label: &str,
    ) -> Result<Option<Touch>, CalibError>;
}

/// Touches at listed joint targets: each call moves to the next target, waits, reads back.
pub struct Scripted {
    targets: std::vec::IntoIter<[f64; JOINT_COUNT]>,
}

impl Scripted {
    /// A script of joint targets (rad), visited in order.
    pub fn new(targets: Vec<[f64; JOINT_COUNT]>) -> Scripted {
        Scripted {
            targets: targets.into_iter(),
        }
    }
}

impl<T: Transport> TouchSource<T> for Scripted {
    fn touch(
        &mut self,
        bus: &mut Bus<T>,
        cell: &Cell,
        label: &str,
    ) -> Result<Option<Touch>, CalibError> {
        let Some(q) = self.targets.next() else {
            return Ok(None);
        };
        bus.move_joints(&q, cell.gripper_deg, None)?;
        record(bus, cell, label).map(Some)
    }
}

/// Keys of the jog terminal.
pub const JOG_KEYS: &str = "1-5 joint, + / - step it, [ / ] step size, t or space touch, \
                            q done, Esc or Ctrl-C abort";

/// Smallest and largest jog step, degrees.
const STEP_RANGE_DEG: (f64, f64) = (0.05, 20.0);

/// Interactive jogging: keys select a joint and step it, the current joints and the tool tip
/// are shown after every step, a key records a touch. Reads keys from `input` (a raw-mode
/// terminal, or any byte stream) and writes the screen to `output`.
pub struct JogTerminal<R: Read, W: Write> {
    input: R,
    output: W,
    joint: usize,
    step_deg: f64,
    /// Commanded joints (set at the first touch from a read-back).
    q: Option<[f64; JOINT_COUNT]>,
    /// Joints last read back (what the screen shows).
    seen: [f64; JOINT_COUNT],
    touches: usize,
}

/// What a key asks for.
enum Key {
    Select(usize),
    Step(f64),
    Scale(f64),
    Touch,
    Done,
    Abort,
    Other,
}

fn key(b: u8) -> Key {
    match b {
        b'1'..=b'5' => Key::Select((b - b'1') as usize),
        b'+' | b'=' => Key::Step(1.0),
        b'-' | b'_' => Key::Step(-1.0),
        b']' => Key::Scale(2.0),
        b'[' => Key::Scale(0.5),
        b't' | b' ' => Key::Touch,
        b'q' => Key::Done,
        0x03 | 0x04 | 0x1b => Key::Abort,
        _ => Key::Other,
    }
}

impl<R: Read, W: Write> JogTerminal<R, W> {
    /// A jog terminal starting on joint 1 with `step_deg` steps.
    pub fn new(input: R, output: W, step_deg: f64) -> Self {
        JogTerminal {
            input,
            output,
            joint: 0,
            step_deg: step_deg.clamp(STEP_RANGE_DEG.0, STEP_RANGE_DEG.1),
            q: None,
            seen: [0.0; JOINT_COUNT],
            touches: 0,
        }
    }

    fn say(&mut self, line: &str) -> Result<(), CalibError> {
        writeln!(self.output, "{line}")
            .and_then(|_| self.output.flush())
            .map_err(|e| CalibError::file(std::path::Path::new("terminal"), e))
    }

    /// The next byte of input; `None` at its end.
    fn read_byte(&mut self) -> Result<Option<u8>, CalibError> {
        let mut b = [0u8; 1];
        loop {
            match self.input.read(&mut b) {
                Ok(0) => return Ok(None),
                Ok(_) => return Ok(Some(b[0])),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(CalibError::file(std::path::Path::new("terminal"), e)),
            }
        }
    }

    /// The next key; the end of input aborts.
    fn next_key(&mut self) -> Result<Key, CalibError> {
        Ok(self.read_byte()?.map_or(Key::Abort, key))
    }

    /// Shows `text` and waits for Enter, t or space (Esc, Ctrl-C or end of input abort).
    pub fn confirm(&mut self, text: &str) -> Result<(), CalibError> {
        self.say(&format!("{text} [Enter to go on, Esc to abort]"))?;
        loop {
            match self.read_byte()? {
                None => return Err(CalibError::Aborted),
                Some(b'\r' | b'\n' | b't' | b' ') => return Ok(()),
                Some(b) if matches!(key(b), Key::Abort) => return Err(CalibError::Aborted),
                Some(_) => {}
            }
        }
    }

    fn status(&mut self, cell: &Cell) -> Result<(), CalibError> {
        let q = self.seen;
        let tip = mm(cell.robot.fk(&q).position);
        let deg: Vec<String> = q
            .iter()
            .map(|v| format!("{:+.2}", v.to_degrees()))
            .collect();
        let line = format!(
            "jog: joint {} | step {:.2} deg | q [deg] {} | tip [mm] {:.1} {:.1} {:.1} | touches {}",
            self.joint + 1,
            self.step_deg,
            deg.join(" "),
            tip.x,
            tip.y,
            tip.z,
            self.touches
        );
        self.say(&line)
    }

    fn step<T: Transport>(
        &mut self,
        bus: &mut Bus<T>,
        cell: &Cell,
        sign: f64,
    ) -> Result<(), CalibError> {
        let mut q = self.q.expect("jog pose read at the first touch");
        q[self.joint] += sign * self.step_deg.to_radians();
        if let Err(e) = cell.map.joint_raw(self.joint, q[self.joint]) {
            return self.say(&format!("jog: not moved: {e}"));
        }
        match bus.move_joints(&q, cell.gripper_deg, None) {
            Ok(state) => {
                self.q = Some(q);
                self.seen = state.joints;
                self.status(cell)
            }
            Err(e @ BusError::Refused(_)) => self.say(&format!("jog: not moved: {e}")),
            Err(e) => Err(e.into()),
        }
    }
}

impl<T: Transport, R: Read, W: Write> TouchSource<T> for JogTerminal<R, W> {
    fn touch(
        &mut self,
        bus: &mut Bus<T>,
        cell: &Cell,
        label: &str,
    ) -> Result<Option<Touch>, CalibError> {
        if self.q.is_none() {
            self.seen = bus.read_joints()?.joints;
            self.q = Some(self.seen);
        }
        self.say(&format!(
            "jog: move the tool tip onto {label}; keys: {JOG_KEYS}"
        ))?;
        self.status(cell)?;
        loop {
            match self.next_key()? {
                Key::Select(j) => {
                    self.joint = j;
                    self.status(cell)?;
                }
                Key::Step(sign) => self.step(bus, cell, sign)?,
                Key::Scale(f) => {
                    self.step_deg = (self.step_deg * f).clamp(STEP_RANGE_DEG.0, STEP_RANGE_DEG.1);
                    self.status(cell)?;
                }
                Key::Touch => {
                    let t = record(bus, cell, label)?;
                    self.touches += 1;
                    let p = mm(t.tip());
                    self.say(&format!(
                        "touch {} recorded ({label}): tip [mm] {:.2} {:.2} {:.2}",
                        self.touches, p.x, p.y, p.z
                    ))?;
                    return Ok(Some(t));
                }
                Key::Done => return Ok(None),
                Key::Abort => return Err(CalibError::Aborted),
                Key::Other => {}
            }
        }
    }
}

/// Standard input switched to raw mode (no line buffering, no echo, Ctrl-C as a key) while
/// this value lives; restored on drop.
pub struct RawTerminal {
    saved: libc::termios,
}

impl RawTerminal {
    /// Raw mode on standard input when it is a terminal; `None` when it is not (a pipe or a
    /// file: keys are then read as they come).
    pub fn enable() -> Option<RawTerminal> {
        // SAFETY: isatty/tcgetattr/tcsetattr on fd 0 with a zeroed, then filled termios.
        unsafe {
            if libc::isatty(0) != 1 {
                return None;
            }
            let mut saved: libc::termios = std::mem::zeroed();
            if libc::tcgetattr(0, &mut saved) != 0 {
                return None;
            }
            let mut raw = saved;
            raw.c_lflag &= !(libc::ICANON | libc::ECHO | libc::ISIG);
            raw.c_cc[libc::VMIN] = 1;
            raw.c_cc[libc::VTIME] = 0;
            if libc::tcsetattr(0, libc::TCSANOW, &raw) != 0 {
                return None;
            }
            Some(RawTerminal { saved })
        }
    }
}

impl Drop for RawTerminal {
    fn drop(&mut self) {
        // SAFETY: restores the attributes read in `enable` on the same fd.
        unsafe {
            libc::tcsetattr(0, libc::TCSANOW, &self.saved);
        }
    }
}

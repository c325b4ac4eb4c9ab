//! The bus driver: paced frames, requests with timeout and retries, the servo check at connect
//! (see [`super::alive`]), torque, motion frames that stop on Ctrl-C, read-back verification,
//! and the journal.
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use dofbot_protocol::frame::MAX_FRAME;
use dofbot_protocol::servo::{ServoId, ServoScale, SERVO_COUNT};
use dofbot_protocol::{BusId, Command, Decoder, OffsetState, Pose, Reply};

use super::config::{BusConfig, JointState, JOINT_COUNT};
use super::error::BusError;
use super::journal::{hex, Entry, EntryKind, Journal};
use super::transport::Transport;

/// Shortest move time the driver sends for a joint move when none is given, s.
const MIN_MOVE_S: f64 = 0.2;
/// Longest single wait while the stop flag is clear: a Ctrl-C ends any wait of the driver
/// within this (issue 34 asks for 100 ms; reads wait at most their 50 ms timeout per read).
const STOP_POLL: Duration = Duration::from_millis(20);

/// A connected DOFBOT board over some [`Transport`].
pub struct Bus<T: Transport> {
    link: T,
    config: BusConfig,
    decoder: Decoder,
    journal: Journal,
    last_write: Option<Duration>,
    stop: Arc<AtomicBool>,
    next_motion: u64,
}

/// How one reply attempt ended when it did not succeed.
type Attempt<R> = Result<R, BusError>;

impl<T: Transport> Bus<T> {
    /// Opens the bus: checks the servo map, flushes input, journals the opening and, unless
    /// the config says otherwise, checks that all six servos answer ([`Bus::check_servos`]).
    pub fn connect(link: T, config: BusConfig, journal: Journal) -> Result<Bus<T>, BusError> {
        config.servo_map.validate()?;
        let mut bus = Bus {
            link,
            config,
            decoder: Decoder::replies(),
            journal,
            last_write: None,
            stop: Arc::new(AtomicBool::new(false)),
            next_motion: 0,
        };
        bus.link.clear_input()?;
        let mut open = Entry::new(EntryKind::Open);
        open.message = Some(bus.link.describe());
        bus.log(open)?;
        if bus.config.ping_at_connect {
            bus.check_servos()?;
        }
        Ok(bus)
    }

    /// The flag that stops motion (set it from a Ctrl-C handler).
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Replaces the stop flag (e.g. by one a signal handler already holds).
    pub fn set_stop_flag(&mut self, flag: Arc<AtomicBool>) {
        self.stop = flag;
    }

    /// The settings in use.
    pub fn config(&self) -> &BusConfig {
        &self.config
    }

    /// The transport.
    pub fn transport(&self) -> &T {
        &self.link
    }

    /// Index the next [`Bus::move_joints`] gives its motion frame.
    pub fn set_next_motion(&mut self, index: u64) {
        self.next_motion = index;
    }

    /// Waits `d` on the transport's clock, in steps of at most 20 ms; returns early once the
    /// stop flag is set (the next motion frame is then refused).
    pub fn sleep(&mut self, d: Duration) {
        let end = self.link.now() + d;
        while !self.stopped() {
            let now = self.link.now();
            if now >= end {
                break;
            }
            self.link.sleep((end - now).min(STOP_POLL));
        }
    }

    /// True once the stop flag is set (Ctrl-C).
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }

    /// Journals an operator stop: the run did its part of the plan and stops for the operator
    /// (`code`: `refixture`; `setup`: the setup `run --resume` continues with).
    pub fn operator_stop(&mut self, code: &str, setup: u64, message: &str) -> Result<(), BusError> {
        let mut e = Entry::new(EntryKind::OperatorStop);
        e.code = Some(code.to_string());
        e.setup = Some(setup);
        e.message = Some(message.to_string());
        self.log(e)
    }

    pub(super) fn log(&mut self, entry: Entry) -> Result<(), BusError> {
        let t = self.link.now().as_secs_f64();
        self.journal.write(entry, t)
    }

    pub(super) fn log_error(
        &mut self,
        err: &BusError,
        motion: Option<u64>,
        kind: EntryKind,
    ) -> Result<(), BusError> {
        let mut e = Entry::new(kind);
        e.code = Some(err.code().into());
        e.message = Some(err.to_string());
        e.motion = motion;
        self.log(e)
    }

    pub(super) fn write_frame(
        &mut self,
        cmd: &Command,
        motion: Option<u64>,
    ) -> Result<(), BusError> {
        let gap = Duration::from_secs_f64(self.config.frame_gap_ms.max(0.0) / 1000.0);
        if let Some(last) = self.last_write {
            let now = self.link.now();
            if now < last + gap {
                self.link.sleep(last + gap - now);
            }
        }
        let mut buf = [0u8; MAX_FRAME];
        let n = cmd.encode(&mut buf).expect("commands fit MAX_FRAME");
        if let Err(e) = self.link.write(&buf[..n]) {
            self.log_error(&e, motion, EntryKind::Error)?;
            return Err(e);
        }
        self.last_write = Some(self.link.now());
        let mut tx = Entry::new(EntryKind::Tx);
        tx.frame = Some(hex(&buf[..n]));
        tx.name = Some(cmd.name().into());
        tx.motion = motion;
        self.log(tx)
    }

    /// Sends `cmd` and waits for the reply `accept` recognises (`None`: not for us, keep
    /// waiting; `Some(Err)`: a failed attempt, retried), up to `config.attempts` times.
    pub(super) fn request<R>(
        &mut self,
        cmd: Command,
        accept: impl Fn(&Reply, u32) -> Option<Attempt<R>>,
    ) -> Result<R, BusError> {
        let attempts = self.config.attempts.max(1);
        let timeout = Duration::from_secs_f64(self.config.read_timeout_ms.max(0.0) / 1000.0);
        let what = format!("{} (0x{:02X})", cmd.name(), cmd.func());
        let mut last = None;
        for attempt in 1..=attempts {
            self.begin_request(&cmd)?;
            let outcome = self.await_reply(&what, attempt, timeout, &accept);
            match outcome {
                Ok(v) => return Ok(v),
                Err(e @ (BusError::PortLost { .. } | BusError::Stopped)) => {
                    self.log_error(&e, None, EntryKind::Error)?;
                    return Err(e);
                }
                Err(e) => {
                    self.log_error(&e, None, EntryKind::Error)?;
                    last = Some(e);
                }
            }
        }
        Err(last.expect("at least one attempt"))
    }

    /// Drops unread input and any partial reply, then sends `cmd`.
    pub(super) fn begin_request(&mut self, cmd: &Command) -> Result<(), BusError> {
        self.link.clear_input()?;
        self.decoder.reset();
        self.write_frame(cmd, None)
    }

    pub(super) fn await_reply<R>(
        &mut self,
        what: &str,
        attempt: u32,
        timeout: Duration,
        accept: &impl Fn(&Reply, u32) -> Option<Attempt<R>>,
    ) -> Attempt<R> {
        let deadline = self.link.now() + timeout;
        let mut buf = [0u8; 64];
        loop {
            if self.stopped() {
                return Err(BusError::Stopped);
            }
            let now = self.link.now();
            if now >= deadline {
                return Err(BusError::Timeout {
                    what: what.into(),
                    ms: timeout.as_millis() as u64,
                    attempts: attempt,
                });
            }
            let n = self.link.read(&mut buf, deadline - now)?;
            let events: Vec<_> = self.decoder.feed(&buf[..n]).collect();
            for ev in events {
                let mut rx = Entry::new(EntryKind::Rx);
                match ev {
                    Ok(frame) => {
                        let mut bytes = [0u8; MAX_FRAME];
                        let len = frame
                            .encode(dofbot_protocol::Direction::ToHost, &mut bytes)
                            .expect("fits");
                        rx.frame = Some(hex(&bytes[..len]));
                        let reply = Reply::parse(&frame);
                        rx.name = Some(match &reply {
                            Ok(r) => reply_name(r).into(),
                            Err(e) => e.to_string(),
                        });
                        self.log(rx)?;
                        if let Ok(r) = reply {
                            if let Some(outcome) = accept(&r, attempt) {
                                return outcome;
                            }
                        }
                    }
                    Err(fe) => {
                        rx.code = Some("bad_checksum".into());
                        rx.message = Some(fe.to_string());
                        self.log(rx)?;
                        return Err(BusError::BadChecksum {
                            what: what.into(),
                            detail: fe.to_string(),
                            attempts: attempt,
                        });
                    }
                }
            }
        }
    }

    /// The board's hardware version.
    pub fn version(&mut self) -> Result<u8, BusError> {
        self.request(Command::Version, |r, _| match *r {
            Reply::Version(v) => Some(Ok(v)),
            _ => None,
        })
    }

    /// Stores servo `id`'s current position as its mid position (0x1C); check the result
    /// with [`Bus::offset_state`].
    pub fn store_mid_offset(&mut self, id: ServoId) -> Result<(), BusError> {
        let bus_id = BusId::new(id.get()).map_err(|e| BusError::Refused(e.to_string()))?;
        self.write_frame(&Command::StoreMidOffset(Some(bus_id)), None)
    }

    /// The board's mid-offset state (0x1B) after a [`Bus::store_mid_offset`].
    pub fn offset_state(&mut self) -> Result<OffsetState, BusError> {
        self.request(Command::ReadOffsetState, |r, _| match *r {
            Reply::OffsetState(s) => Some(Ok(s)),
            _ => None,
        })
    }

    /// Torque on or off for all servos (off: the arm can be moved by hand).
    pub fn torque(&mut self, on: bool) -> Result<(), BusError> {
        self.write_frame(&Command::Torque(on), None)
    }

    fn scale(&self, id: ServoId) -> Result<ServoScale, BusError> {
        let map = &self.config.servo_map;
        if id.index() < JOINT_COUNT {
            Ok(map.joints[id.index()].servo_scale()?)
        } else {
            Ok(map.gripper.servo_scale()?)
        }
    }

    /// Reads one servo's raw position; 0 or out-of-range values are retried, then a
    /// [`BusError::ReadFailure`]. A reply whose echo names another servo is stale (an answer
    /// to an earlier request): it is journalled and passed over while the wait goes on, as
    /// Arm_Lib's `Arm_serial_servo_read` passes over a reply whose echo is not 0x30+id.
    pub fn read_raw(&mut self, id: ServoId) -> Result<u16, BusError> {
        let scale = self.scale(id)?;
        self.request(Command::ReadPosition(id), |r, attempt| match *r {
            Reply::Position { servo, raw } if servo.is_none_or(|s| s == id) => Some(
                scale
                    .check_raw(raw)
                    .map(|_| raw)
                    .map_err(|_| BusError::ReadFailure {
                        servo: id.get(),
                        raw,
                        min: scale.raw_min,
                        max: scale.raw_max,
                        attempts: attempt,
                    }),
            ),
            _ => None,
        })
    }

    /// Raw positions of all six servos, read one by one.
    pub fn read_pose_raw(&mut self) -> Result<[u16; SERVO_COUNT], BusError> {
        let mut raw = [0u16; SERVO_COUNT];
        for id in ServoId::ALL {
            raw[id.index()] = self.read_raw(id)?;
        }
        Ok(raw)
    }

    /// Joint angles (rad, URDF) and gripper angle read from the servos.
    pub fn read_joints(&mut self) -> Result<JointState, BusError> {
        let raw = self.read_pose_raw()?;
        Ok(self.config.servo_map.state_from_raw(raw)?)
    }

    /// Sends motion frame `index` (a 0x1D frame: all six servos, `time_ms`). Refused once the
    /// stop flag is set; a failed write stops motion. Both leave a stop line in the journal.
    pub fn send_motion(&mut self, index: u64, pose: Pose, time_ms: u16) -> Result<(), BusError> {
        self.send_motion_command(index, &Command::MoveAll { pose, time_ms })
    }

    /// Sends motion command `cmd` as motion frame `index`: refused once the stop flag is set; a
    /// failed write stops motion; both leave a stop line in the journal.
    pub(super) fn send_motion_command(
        &mut self,
        index: u64,
        cmd: &Command,
    ) -> Result<(), BusError> {
        if self.stopped() {
            let e = BusError::Stopped;
            self.log_error(&e, Some(index), EntryKind::Stop)?;
            return Err(e);
        }
        self.write_frame(cmd, Some(index)).inspect_err(|e| {
            let _ = self.log_error(e, Some(index), EntryKind::Stop);
        })
    }

    /// Reads the pose back and checks every servo against `expected` within the configured
    /// tolerance; journals a `verified` line for motion `index` or a stop line.
    pub fn verify(
        &mut self,
        index: u64,
        expected: [u16; SERVO_COUNT],
    ) -> Result<JointState, BusError> {
        let raw = self.read_pose_raw().inspect_err(|e| {
            let _ = self.log_error(e, Some(index), EntryKind::Stop);
        })?;
        let tol = self.config.verify_tolerance_counts;
        for id in ServoId::ALL {
            let (got, want) = (raw[id.index()], expected[id.index()]);
            if got.abs_diff(want) > tol {
                let e = BusError::ReadBackMismatch {
                    servo: id.get(),
                    expected: want,
                    got,
                    tolerance: tol,
                };
                self.log_error(&e, Some(index), EntryKind::Stop)?;
                return Err(e);
            }
        }
        let mut v = Entry::new(EntryKind::Verified);
        v.motion = Some(index);
        v.raw = Some(raw.to_vec());
        self.log(v)?;
        Ok(self.config.servo_map.state_from_raw(raw)?)
    }

    /// Reads servo `id` back during motion `index` and checks it against `expected` within
    /// `tolerance` counts; journals a stop line on a mismatch or a failed read.
    pub fn verify_servo(
        &mut self,
        index: u64,
        id: ServoId,
        expected: u16,
        tolerance: u16,
    ) -> Result<u16, BusError> {
        let got = self.read_raw(id).inspect_err(|e| {
            let _ = self.log_error(e, Some(index), EntryKind::Stop);
        })?;
        self.check_read_back(index, id.get(), expected, got, tolerance)?;
        Ok(got)
    }

    /// A read-back `got` of servo `servo` at motion `index` against `expected` within
    /// `tolerance` counts: a mismatch is journalled as a stop line and returned.
    pub(super) fn check_read_back(
        &mut self,
        index: u64,
        servo: u8,
        expected: u16,
        got: u16,
        tolerance: u16,
    ) -> Result<(), BusError> {
        if got.abs_diff(expected) > tolerance {
            let e = BusError::ReadBackMismatch {
                servo,
                expected,
                got,
                tolerance,
            };
            self.log_error(&e, Some(index), EntryKind::Stop)?;
            return Err(e);
        }
        Ok(())
    }

    /// Moves to joints `q` (rad) and gripper angle (deg) in `time` (default: the fastest the
    /// joint velocity limits allow, at least 0.2 s), waits, reads back and verifies. Refused
    /// before anything moves if a target is outside a limit or `time` is too short.
    pub fn move_joints(
        &mut self,
        q: &[f64; JOINT_COUNT],
        gripper_deg: f64,
        time: Option<Duration>,
    ) -> Result<JointState, BusError> {
        let target = self.config.servo_map.pose_raw(q, gripper_deg)?;
        let pose = Pose::new(target).map_err(|e| BusError::Refused(e.to_string()))?;
        let now = self.read_joints()?;
        let needed = self
            .config
            .servo_map
            .joints
            .iter()
            .enumerate()
            .map(|(i, j)| (q[i] - now.joints[i]).abs() / j.max_velocity_rad_s)
            .fold(0.0, f64::max);
        let secs = match time {
            Some(t) if t.as_secs_f64() + 1e-9 < needed => {
                return Err(BusError::Refused(format!(
                    "move time {:.3} s is shorter than the {needed:.3} s the joint velocity limits allow",
                    t.as_secs_f64()
                )))
            }
            Some(t) => t.as_secs_f64(),
            None => needed.max(MIN_MOVE_S),
        };
        let time_ms = (secs * 1000.0).ceil();
        if time_ms > u16::MAX as f64 {
            return Err(BusError::Refused(format!(
                "move time {secs} s exceeds 65.535 s"
            )));
        }
        let index = self.next_motion;
        self.send_motion(index, pose, time_ms as u16)?;
        self.next_motion += 1;
        let settle = self.config.settle_ms.max(0.0) / 1000.0;
        self.sleep(Duration::from_secs_f64(time_ms / 1000.0 + settle));
        self.verify(index, target)
    }
}

fn reply_name(r: &Reply) -> &'static str {
    match r {
        Reply::Position { .. } => "position",
        Reply::AnyPosition { .. } => "any_position",
        Reply::Ping { .. } => "ping",
        Reply::OffsetState(_) => "offset_state",
        Reply::Version(_) => "version",
        Reply::ActionCount(_) => "action_count",
    }
}

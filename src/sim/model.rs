//! The simulated board: six servos moving at bounded speed, replies with the board's latency,
//! and fault injection. `mocks/dofbot_mock.py` mirrors this model line for line, so the
//! in-process simulator and the pseudo-terminal mock behave alike.
//!
//! Servo model: a move to `target` in `time_ms` starting at time `t` from the current position
//! `p` lasts `max(time_ms/1000, |target - p| / max_speed)` seconds, linear in between; a
//! read returns the position at the read's arrival, rounded to the nearest count. Torque off
//! freezes every servo where it is and ignores moves; a stalled servo ignores moves.
//!
//! Hidden mechanics ([`Mechanics`], all off by default) give the calibration routines a truth
//! to find: a servo mounted `mount_offset_deg` off reads (and moves to) the raw position of
//! servo angle `physical + offset`, so the physical joint differs from the commanded one; reads
//! add seeded integer noise; and the arm can start held by hand at a physical pose, torque off.
//!
//! Bus servos beyond the arm's six ([`ExtraServo`], e.g. the part turntable's id 7) move like
//! the arm's servos on 0x19 frames (Arm_Lib's `Arm_serial_servo_write_any`), answer a 0x37
//! read (`Arm_serial_servo_read_any`, position low byte first) and a ping; a 0x19 or 0x37 for
//! an id nobody has goes unanswered, as on a bus where no servo listens to it.
use serde::{Deserialize, Serialize};

use dofbot_protocol::frame::Frame;
use dofbot_protocol::replies::PING_ALIVE;
use dofbot_protocol::servo::{ServoId, SERVO_COUNT};
use dofbot_protocol::{Command, OffsetState, Reply};

/// Board timing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimTiming {
    /// Line speed, baud (10 bit times per byte, 8N1). Default 115200.
    pub baud: f64,
    /// Time from a read request's last byte to the reply's first byte, ms. Default 3
    /// (Yahboom's library waits about 3 ms).
    pub reply_latency_ms: f64,
    /// Servo speed bound, raw counts per second. Default 3000 (about 250 deg/s at 12.2
    /// counts per degree, DOFBOT.md's no-load speed).
    pub max_speed_counts_s: f64,
}

impl Default for SimTiming {
    fn default() -> Self {
        SimTiming {
            baud: 115_200.0,
            reply_latency_ms: 3.0,
            max_speed_counts_s: 3000.0,
        }
    }
}

impl SimTiming {
    /// Seconds one byte takes on the line.
    pub fn byte_time(&self) -> f64 {
        10.0 / self.baud
    }
}

/// What the board answers a ping (0x38) with. Yahboom's serial library never reads a ping
/// reply and none is published, so a real board may send any of these.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PingReply {
    /// No reply at all.
    None,
    /// TYPE 0x38 with one status byte (0xDA alive, 0 not), as the I2C library reads it.
    #[default]
    Status,
    /// TYPE 0x38 with the pinged id, then the status byte.
    IdStatus,
}

/// Faults to inject; all off by default. Counters are 1-based: `every = 3` hits the 3rd, 6th ...
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Faults {
    /// Corrupt the checksum of every k-th reply (0 = never).
    pub corrupt_every: u32,
    /// Drop every k-th reply (0 = never).
    pub drop_every: u32,
    /// Extra delay on every reply, ms.
    pub delay_ms: f64,
    /// Reads of this servo return raw 0.
    pub fail_read_servo: Option<u8>,
    /// Every k-th read (any servo) returns raw 0 (0 = never).
    pub fail_read_every: u32,
    /// Drop the link after this many frames.
    pub disconnect_after: Option<u64>,
    /// This servo ignores moves (stalled).
    pub stall_servo: Option<u8>,
    /// This servo is absent: its ping says no answer, its reads get no reply.
    pub absent_servo: Option<u8>,
    /// Every k-th read's reply comes after a stale one: the position reply of the next servo
    /// (id mod 6 + 1), as an answer to an earlier request would (0 = never).
    pub stale_echo_every: u32,
}

/// The physical truth of the simulated arm that the host does not know (for calibration tests).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Mechanics {
    /// Per-servo mounting offset, degrees (servos 1..6): the servo reads and moves to the raw
    /// position of servo angle `physical + offset`. Default 0.
    pub mount_offset_deg: [f64; SERVO_COUNT],
    /// Read-back noise, counts: every read adds a uniform integer in `-n..=n`. Default
    /// [`DEFAULT_READ_NOISE_COUNTS`] (0; the documented arm's is 1).
    pub read_noise_counts: u16,
    /// Seed of the noise generator (splitmix64). Default 0.
    pub noise_seed: u64,
    /// Start with the arm held by hand at these physical servo angles (degrees, 90 = joint
    /// zero), torque off. Default none (home pose, torque on).
    pub start_physical_deg: Option<[f64; SERVO_COUNT]>,
}

/// Default read-back noise, counts: 0. shared/DOFBOT.md measured "read-back noise 1 count
/// (0.082 deg)" on the bus servos (2 on servo 5); `read_noise_counts = 1` simulates it. It is
/// not the default yet: the link, plan and CLI tests compare read-backs with the frames sent
/// byte for byte (Arm_Lib's transactions), and moving them to a one-count tolerance is left
/// for a later change (issue 50).
pub const DEFAULT_READ_NOISE_COUNTS: u16 = 0;

impl Default for Mechanics {
    fn default() -> Self {
        Mechanics {
            mount_offset_deg: [0.0; SERVO_COUNT],
            read_noise_counts: DEFAULT_READ_NOISE_COUNTS,
            noise_seed: 0,
            start_physical_deg: None,
        }
    }
}

/// A bus servo beyond the arm's six: its id and where it rests at start.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtraServo {
    /// Bus id, 7..=250.
    pub id: u8,
    /// Raw position at start.
    pub start_raw: u16,
}

/// One step of splitmix64 (Steele, Lea, Flood 2014): the noise generator the mock mirrors.
pub fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Raw position (not rounded) of servo `index` (0-based) at servo angle `deg`, DOFBOT.md's
/// scales, not clamped.
pub fn raw_at_deg(index: usize, deg: f64) -> f64 {
    let s = ServoId::ALL[index].scale();
    let a = if s.inverted { s.deg_max - deg } else { deg };
    s.raw_min as f64 + (s.raw_max - s.raw_min) as f64 * a / s.deg_max
}

/// Servo angle of servo `index` (0-based) at raw position `raw` (the inverse of
/// [`raw_at_deg`]).
pub fn deg_at_raw(index: usize, raw: f64) -> f64 {
    let s = ServoId::ALL[index].scale();
    let a = (raw - s.raw_min as f64) * s.deg_max / (s.raw_max - s.raw_min) as f64;
    if s.inverted {
        s.deg_max - a
    } else {
        a
    }
}

/// One servo's motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoModel {
    start: f64,
    target: f64,
    t0: f64,
    dur: f64,
}

impl ServoModel {
    /// A servo at rest at `raw`.
    pub fn at(raw: f64) -> ServoModel {
        ServoModel {
            start: raw,
            target: raw,
            t0: 0.0,
            dur: 0.0,
        }
    }

    /// Position (raw counts, not rounded) at time `t` seconds.
    pub fn position(&self, t: f64) -> f64 {
        if self.dur <= 0.0 || t >= self.t0 + self.dur {
            self.target
        } else if t <= self.t0 {
            self.start
        } else {
            self.start + (self.target - self.start) * (t - self.t0) / self.dur
        }
    }

    /// Starts a move to `target` at time `t` lasting `time_ms` or longer if the speed bound
    /// requires.
    pub fn command(&mut self, target: u16, time_ms: u16, t: f64, max_speed: f64) {
        let p = self.position(t);
        let target = target as f64;
        let dur = (time_ms as f64 / 1000.0).max((target - p).abs() / max_speed);
        *self = ServoModel {
            start: p,
            target,
            t0: t,
            dur,
        };
    }

    /// The current move's target.
    pub fn target(&self) -> f64 {
        self.target
    }
}

/// Rounds a non-negative raw position to the nearest count (as the Python mock does).
pub fn round_raw(x: f64) -> u16 {
    (x + 0.5).floor() as u16
}

/// A reply leaving the board: bytes and the delay after the request's last byte.
#[derive(Debug, Clone, PartialEq)]
pub struct Outgoing {
    /// The whole reply frame.
    pub bytes: Vec<u8>,
    /// Seconds after the request's last byte when the reply's last byte has arrived.
    pub delay: f64,
}

/// The simulated board.
#[derive(Debug, Clone)]
pub struct Board {
    servos: [ServoModel; SERVO_COUNT],
    extra: Vec<(u8, ServoModel)>,
    torque: bool,
    timing: SimTiming,
    faults: Faults,
    mechanics: Mechanics,
    noise_state: u64,
    frames: u64,
    replies: u64,
    reads: u64,
    disconnected: bool,
    ping_reply: PingReply,
}

/// Hardware version the simulated board reports.
pub const SIM_VERSION: u8 = 1;

impl Board {
    /// A board whose servos rest at `home` raw positions, torque on; or, when `mechanics`
    /// gives a start pose, held by hand there (raw of `physical + offset`), torque off.
    pub fn new(
        home: [u16; SERVO_COUNT],
        timing: SimTiming,
        faults: Faults,
        mechanics: Mechanics,
    ) -> Board {
        let mut servos = home.map(|r| ServoModel::at(r as f64));
        let mut torque = true;
        if let Some(start) = mechanics.start_physical_deg {
            for (i, s) in servos.iter_mut().enumerate() {
                *s = ServoModel::at(raw_at_deg(i, start[i] + mechanics.mount_offset_deg[i]));
            }
            torque = false;
        }
        Board {
            servos,
            extra: Vec::new(),
            torque,
            timing,
            faults,
            noise_state: mechanics.noise_seed,
            mechanics,
            frames: 0,
            replies: 0,
            reads: 0,
            disconnected: false,
            ping_reply: PingReply::default(),
        }
    }

    /// The same board answering pings with `ping_reply`.
    pub fn with_ping_reply(mut self, ping_reply: PingReply) -> Board {
        self.ping_reply = ping_reply;
        self
    }

    /// The same board with `extra` bus servos beyond the arm's six (ids 1..=6 among them are
    /// ignored: those are the arm's).
    pub fn with_extra(mut self, extra: &[ExtraServo]) -> Board {
        self.extra = extra
            .iter()
            .filter(|e| e.id as usize > SERVO_COUNT)
            .map(|e| (e.id, ServoModel::at(e.start_raw as f64)))
            .collect();
        self
    }

    /// Handles a frame whose last byte arrived at time `t` (s); returns the reply, if any.
    pub fn handle(&mut self, frame: &Frame, t: f64) -> Option<Outgoing> {
        let reply = self.handle_command(Command::parse(frame).ok(), t)?;
        let mut out = self.send(reply)?;
        let k = self.faults.stale_echo_every as u64;
        if let Reply::Position {
            servo: Some(id), ..
        } = reply
        {
            if k > 0 && self.reads.is_multiple_of(k) {
                let other = ServoId::ALL[id.get() as usize % SERVO_COUNT];
                let stale = Reply::Position {
                    servo: Some(other),
                    raw: round_raw(self.servos[other.index()].position(t)),
                };
                let mut buf = [0u8; dofbot_protocol::frame::MAX_FRAME];
                let n = stale.encode(&mut buf).expect("reply fits");
                out.bytes.splice(0..0, buf[..n].iter().copied());
                out.delay += n as f64 * self.timing.byte_time();
            }
        }
        Some(out)
    }

    /// Handles a command (`None`: a frame that is no valid command) that arrived at time `t`
    /// without a serial line in between (the fake I2C device's path); returns the answer.
    pub fn handle_command(&mut self, cmd: Option<Command>, t: f64) -> Option<Reply> {
        if self.disconnected {
            return None;
        }
        self.frames += 1;
        let reply = cmd.and_then(|c| self.execute(c, t));
        if self
            .faults
            .disconnect_after
            .is_some_and(|n| self.frames >= n)
        {
            self.disconnected = true;
            return None;
        }
        reply
    }

    fn execute(&mut self, cmd: Command, t: f64) -> Option<Reply> {
        match cmd {
            Command::MoveServo { target, time_ms } => {
                self.move_servo(target.id().get(), target.raw(), time_ms, t)
            }
            Command::MoveAll { pose, time_ms } => {
                for (i, raw) in pose.raw().iter().enumerate() {
                    self.move_servo(i as u8 + 1, *raw, time_ms, t);
                }
            }
            Command::MoveAny { target, time_ms } => {
                self.move_servo(target.id().get(), target.raw(), time_ms, t)
            }
            Command::MoveEvery { raw, time_ms } => {
                for id in 1..=SERVO_COUNT as u8 {
                    self.move_servo(id, raw.get(), time_ms, t);
                }
            }
            Command::ReadPosition(id) => return self.read(id, t),
            Command::ReadAny(id) => return self.read_any(id.get(), t),
            Command::Ping(id) => {
                let id = id.get();
                let present =
                    (1..=SERVO_COUNT as u8).contains(&id) || self.extra_index(id).is_some();
                let alive = present && self.faults.absent_servo != Some(id);
                let status = if alive { PING_ALIVE } else { 0 };
                return match self.ping_reply {
                    PingReply::None => None,
                    PingReply::Status => Some(Reply::Ping { id: None, status }),
                    PingReply::IdStatus => Some(Reply::Ping {
                        id: Some(id),
                        status,
                    }),
                };
            }
            Command::Torque(on) => {
                if !on {
                    let extra = self.extra.iter_mut().map(|(_, s)| s);
                    for s in self.servos.iter_mut().chain(extra) {
                        *s = ServoModel::at(s.position(t));
                    }
                }
                self.torque = on;
            }
            Command::ReadOffsetState => return Some(Reply::OffsetState(OffsetState::Ok)),
            Command::Version => return Some(Reply::Version(SIM_VERSION)),
            _ => {}
        }
        None
    }

    fn move_servo(&mut self, id: u8, raw: u16, time_ms: u16, t: f64) {
        let idx = id as usize;
        if !self.torque || self.faults.stall_servo == Some(id) {
            return;
        }
        let speed = self.timing.max_speed_counts_s;
        if (1..=SERVO_COUNT).contains(&idx) {
            self.servos[idx - 1].command(raw, time_ms, t, speed);
        } else if let Some(k) = self.extra_index(id) {
            self.extra[k].1.command(raw, time_ms, t, speed);
        }
    }

    fn extra_index(&self, id: u8) -> Option<usize> {
        self.extra.iter().position(|(i, _)| *i == id)
    }

    /// A 0x37 read: an arm servo reads as on 0x30+id, an extra one by its model; an id nobody
    /// has, or an absent servo, gives no reply.
    fn read_any(&mut self, id: u8, t: f64) -> Option<Reply> {
        if let Ok(arm) = ServoId::new(id) {
            return match self.read(arm, t)? {
                Reply::Position { raw, .. } => Some(Reply::AnyPosition { raw }),
                other => Some(other),
            };
        }
        let k = self.extra_index(id)?;
        if self.faults.absent_servo == Some(id) {
            return None;
        }
        self.reads += 1;
        let noise = self.noise();
        let raw = (round_raw(self.extra[k].1.position(t)) as i64 + noise).max(0) as u16;
        Some(Reply::AnyPosition { raw })
    }

    /// Raw position (rounded) of extra bus servo `id` at time `t`, if there is one.
    pub fn extra_position(&self, id: u8, t: f64) -> Option<u16> {
        let k = self.extra_index(id)?;
        Some(round_raw(self.extra[k].1.position(t)))
    }

    fn read(&mut self, id: ServoId, t: f64) -> Option<Reply> {
        if self.faults.absent_servo == Some(id.get()) {
            return None;
        }
        self.reads += 1;
        let k = self.faults.fail_read_every;
        let fail = self.faults.fail_read_servo == Some(id.get())
            || (k > 0 && self.reads.is_multiple_of(k as u64));
        let raw = if fail {
            0
        } else {
            let noise = self.noise();
            (round_raw(self.servos[id.index()].position(t)) as i64 + noise).max(0) as u16
        };
        Some(Reply::Position {
            servo: Some(id),
            raw,
        })
    }

    /// The next read's noise, counts (the generator advances only when noise is on).
    fn noise(&mut self) -> i64 {
        let n = self.mechanics.read_noise_counts as u64;
        if n == 0 {
            return 0;
        }
        (splitmix64(&mut self.noise_state) % (2 * n + 1)) as i64 - n as i64
    }

    /// Physical servo angles at time `t`, degrees (90 = joint zero): the servo angle of each
    /// raw position minus its mounting offset.
    pub fn physical_deg(&self, t: f64) -> [f64; SERVO_COUNT] {
        std::array::from_fn(|i| {
            deg_at_raw(i, self.servos[i].position(t)) - self.mechanics.mount_offset_deg[i]
        })
    }

    fn send(&mut self, reply: Reply) -> Option<Outgoing> {
        self.replies += 1;
        let hit = |k: u32| k > 0 && self.replies.is_multiple_of(k as u64);
        if hit(self.faults.drop_every) {
            return None;
        }
        let mut buf = [0u8; dofbot_protocol::frame::MAX_FRAME];
        let n = reply.encode(&mut buf).expect("reply fits");
        let mut bytes = buf[..n].to_vec();
        if hit(self.faults.corrupt_every) {
            bytes[n - 1] ^= 0xFF;
        }
        let delay = (self.timing.reply_latency_ms + self.faults.delay_ms) / 1000.0
            + n as f64 * self.timing.byte_time();
        Some(Outgoing { bytes, delay })
    }

    /// Raw positions (rounded) at time `t`.
    pub fn positions(&self, t: f64) -> [u16; SERVO_COUNT] {
        self.servos.map(|s| round_raw(s.position(t)))
    }

    /// Current move targets.
    pub fn targets(&self) -> [u16; SERVO_COUNT] {
        self.servos.map(|s| round_raw(s.target()))
    }

    /// Frames received so far (valid framing; commands that did not parse included).
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// True once the injected disconnect happened.
    pub fn disconnected(&self) -> bool {
        self.disconnected
    }

    /// Torque state.
    pub fn torque(&self) -> bool {
        self.torque
    }

    /// Line timing.
    pub fn timing(&self) -> &SimTiming {
        &self.timing
    }
}

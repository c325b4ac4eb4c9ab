//! In-process simulated arm (`--sim`): the [`Board`] model behind a [`Transport`], with a
//! virtual clock by default (moves "take" their time without waiting) or real time.
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use dofbot_protocol::servo::SERVO_COUNT;
use dofbot_protocol::{Command, Decoder, Reply};

use super::model::{Board, ExtraServo, Faults, Mechanics, PingReply, SimTiming};
use crate::bus::config::ServoMap;
use crate::bus::error::BusError;
use crate::bus::transport::{RealClock, Transport};

/// Settings of the simulated arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimOptions {
    /// Run on the wall clock instead of a virtual one. Default false (tests and demo run
    /// as fast as the CPU allows, with the same timing arithmetic).
    pub realtime: bool,
    /// Gripper angle at start, degrees (joints start at zero). Default 90.
    pub home_gripper_deg: f64,
    /// Board timing.
    pub timing: SimTiming,
    /// Injected faults.
    pub faults: Faults,
    /// Hidden mechanics (mounting offsets, read noise, a start pose held by hand).
    pub mechanics: Mechanics,
    /// What the board answers a ping with: "none", "status" (default) or "id-status".
    pub ping_reply: PingReply,
    /// The virtual part's grinding (`run --part`): the true removal law and mounting.
    pub grinding: super::grinding::GrindConfig,
    /// Bus servos beyond the arm's six (e.g. the part turntable, id 7). Default none; `run`,
    /// `arm` and `calibrate` with `--sim` add the cell's turntable at table angle 0 when it is
    /// not listed here.
    pub extra_servos: Vec<ExtraServo>,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            realtime: false,
            home_gripper_deg: 90.0,
            timing: SimTiming::default(),
            faults: Faults::default(),
            mechanics: Mechanics::default(),
            ping_reply: PingReply::default(),
            grinding: super::grinding::GrindConfig::default(),
            extra_servos: Vec::new(),
        }
    }
}

/// A frame the simulated board received: arrival time (s) and bytes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReceivedFrame {
    /// Arrival of the last byte, seconds on the sim clock.
    pub t: f64,
    /// The frame's FUNC byte.
    pub func: u8,
    /// The frame's payload.
    pub payload: Vec<u8>,
}

struct Inner {
    board: Board,
    clock: Duration,
    decoder: Decoder,
    link_free_at: f64,
    outbox: VecDeque<(f64, Vec<u8>)>,
    received: Vec<ReceivedFrame>,
}

/// Handle on a simulated arm: make its transport, inspect its state (also after the bus is
/// gone, e.g. to compare final poses).
#[derive(Clone)]
pub struct SimArm {
    inner: Arc<Mutex<Inner>>,
    realtime: Option<RealClock>,
}

impl SimArm {
    /// A simulated arm at its home pose (joint zero, gripper per options) under `map`.
    pub fn new(options: &SimOptions, map: &ServoMap) -> Result<SimArm, BusError> {
        let home = map.home_raw(options.home_gripper_deg)?;
        Ok(SimArm::with_home(options, home))
    }

    /// A simulated arm resting at `home` raw positions.
    pub fn with_home(options: &SimOptions, home: [u16; SERVO_COUNT]) -> SimArm {
        let inner = Inner {
            board: Board::new(
                home,
                options.timing.clone(),
                options.faults.clone(),
                options.mechanics.clone(),
            )
            .with_ping_reply(options.ping_reply)
            .with_extra(&options.extra_servos),
            clock: Duration::ZERO,
            decoder: Decoder::commands(),
            link_free_at: 0.0,
            outbox: VecDeque::new(),
            received: Vec::new(),
        };
        SimArm {
            inner: Arc::new(Mutex::new(inner)),
            realtime: options.realtime.then(RealClock::new),
        }
    }

    /// A transport talking to this arm.
    pub fn transport(&self) -> SimTransport {
        SimTransport { arm: self.clone() }
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn now(&self) -> Duration {
        match self.realtime {
            Some(c) => c.now(),
            None => self.lock().clock,
        }
    }

    /// Servo raw positions now.
    pub fn positions(&self) -> [u16; SERVO_COUNT] {
        let t = self.now().as_secs_f64();
        self.lock().board.positions(t)
    }

    /// Physical servo angles now, degrees (90 = joint zero): what the hidden mounting offsets
    /// make of the raw positions.
    pub fn physical_deg(&self) -> [f64; SERVO_COUNT] {
        let t = self.now().as_secs_f64();
        self.lock().board.physical_deg(t)
    }

    /// Raw position now of extra bus servo `id` (e.g. the turntable's 7), if the sim has one.
    pub fn extra_position(&self, id: u8) -> Option<u16> {
        let t = self.now().as_secs_f64();
        self.lock().board.extra_position(id, t)
    }

    /// Where the servos are heading (equal to [`SimArm::positions`] once moves are over).
    pub fn targets(&self) -> [u16; SERVO_COUNT] {
        self.lock().board.targets()
    }

    /// Every frame received so far.
    pub fn received(&self) -> Vec<ReceivedFrame> {
        self.lock().received.clone()
    }

    /// Sim clock, seconds.
    pub fn time(&self) -> f64 {
        self.now().as_secs_f64()
    }

    /// Waits `d`: on the wall clock, or by advancing the virtual one.
    pub fn advance(&self, d: Duration) {
        match self.realtime {
            Some(_) => std::thread::sleep(d),
            None => self.lock().clock += d,
        }
    }

    /// True once an injected disconnect happened.
    pub fn disconnected(&self) -> bool {
        self.lock().board.disconnected()
    }

    /// Hands `cmd` to the board as if its frame had just arrived, with no serial line in
    /// between (the fake I2C device's path), records it and returns the board's answer.
    pub fn command(&self, cmd: &Command) -> Option<Reply> {
        let t = self.time();
        let frame = cmd.to_frame();
        let mut g = self.lock();
        g.received.push(ReceivedFrame {
            t,
            func: frame.kind(),
            payload: frame.payload().to_vec(),
        });
        g.board.handle_command(Some(*cmd), t)
    }
}

/// Transport of a [`SimArm`].
pub struct SimTransport {
    arm: SimArm,
}

impl SimTransport {
    /// The arm behind this transport.
    pub fn arm(&self) -> &SimArm {
        &self.arm
    }
}

fn lost() -> BusError {
    BusError::PortLost {
        detail: "simulated link disconnected".into(),
    }
}

impl Transport for SimTransport {
    fn write(&mut self, bytes: &[u8]) -> Result<(), BusError> {
        let now = self.now().as_secs_f64();
        let mut g = self.arm.lock();
        if g.board.disconnected() {
            return Err(lost());
        }
        let bt = g.board.timing().byte_time();
        let start = now.max(g.link_free_at);
        g.link_free_at = start + bytes.len() as f64 * bt;
        let inner = &mut *g;
        for (k, b) in bytes.iter().enumerate() {
            let frames: Vec<_> = inner.decoder.feed(std::slice::from_ref(b)).collect();
            for frame in frames.into_iter().flatten() {
                let t = start + (k + 1) as f64 * bt;
                inner.received.push(ReceivedFrame {
                    t,
                    func: frame.kind(),
                    payload: frame.payload().to_vec(),
                });
                if let Some(out) = inner.board.handle(&frame, t) {
                    let due = t + out.delay;
                    let pos = inner.outbox.partition_point(|(d, _)| *d <= due);
                    inner.outbox.insert(pos, (due, out.bytes));
                }
                if inner.board.disconnected() {
                    inner.outbox.clear();
                }
            }
        }
        Ok(())
    }

    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, BusError> {
        let deadline = self.now() + timeout;
        let due = {
            let g = self.arm.lock();
            if g.board.disconnected() {
                return Err(lost());
            }
            g.outbox.front().map(|(d, _)| Duration::from_secs_f64(*d))
        };
        match due {
            Some(d) if d <= deadline => {
                let now = self.now();
                if d > now {
                    self.sleep(d - now);
                }
                let mut g = self.arm.lock();
                let (t, mut bytes) = g.outbox.pop_front().expect("front exists");
                let n = bytes.len().min(buf.len());
                buf[..n].copy_from_slice(&bytes[..n]);
                if n < bytes.len() {
                    g.outbox.push_front((t, bytes.split_off(n)));
                }
                Ok(n)
            }
            _ => {
                let now = self.now();
                self.sleep(deadline.saturating_sub(now));
                Ok(0)
            }
        }
    }

    fn clear_input(&mut self) -> Result<(), BusError> {
        let now = self.now().as_secs_f64();
        let mut g = self.arm.lock();
        g.outbox.retain(|(d, _)| *d > now);
        Ok(())
    }

    fn now(&self) -> Duration {
        self.arm.now()
    }

    fn sleep(&mut self, d: Duration) {
        self.arm.advance(d);
    }

    fn describe(&self) -> String {
        "sim".into()
    }
}

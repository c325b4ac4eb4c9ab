//! Where the simulated arm's servos physically were over virtual time: the frames the
//! simulated board received ([`crate::sim::SimArm::received`], with their arrival times)
//! replayed through a fresh copy of the same board model, so the servo speed bound, the raw
//! count quantisation of every target and the hidden mounting offsets all act as in the run,
//! without touching the simulator while it runs.
use dofbot_protocol::frame::Frame;
use dofbot_protocol::servo::SERVO_COUNT;
use dofbot_protocol::Command;

use crate::sim::arm::{ReceivedFrame, SimOptions};
use crate::sim::model::Board;

/// The board's state over time, queried at non-decreasing times.
#[derive(Clone)]
pub struct ServoTrace {
    board: Board,
    frames: Vec<ReceivedFrame>,
    next: usize,
}

impl ServoTrace {
    /// A replay of `frames` on a board that started at `home` raw positions with `options`
    /// (the same that made the run's [`crate::sim::SimArm`]).
    pub fn new(options: &SimOptions, home: [u16; SERVO_COUNT], frames: Vec<ReceivedFrame>) -> Self {
        let board = Board::new(
            home,
            options.timing.clone(),
            options.faults.clone(),
            options.mechanics.clone(),
        );
        ServoTrace {
            board,
            frames,
            next: 0,
        }
    }

    /// Physical servo angles at time `t` (s), degrees (90 = joint zero). Times must not go
    /// back: frames up to `t` are handed to the board once.
    pub fn physical_deg(&mut self, t: f64) -> [f64; SERVO_COUNT] {
        while let Some(f) = self.frames.get(self.next).filter(|f| f.t <= t) {
            let cmd = Frame::new(f.func, &f.payload)
                .ok()
                .and_then(|frame| Command::parse(&frame).ok());
            self.board.handle_command(cmd, f.t);
            self.next += 1;
        }
        self.board.physical_deg(t)
    }

    /// Arrival time of the last frame, s (0 without frames).
    pub fn last_frame_time(&self) -> f64 {
        self.frames.last().map_or(0.0, |f| f.t)
    }
}

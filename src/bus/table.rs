//! Bus servos beyond the arm's six on the driver (the part turntable, id 7): 0x19 motion
//! frames (Arm_Lib's `Arm_serial_servo_write_any`) and 0x37 read-backs
//! (`Arm_serial_servo_read_any`), journalled like the arm's.
use dofbot_protocol::{AnyTarget, BusId, Command, Reply};

use super::driver::Bus;
use super::error::BusError;
use super::journal::{Entry, EntryKind};
use super::transport::Transport;

impl<T: Transport> Bus<T> {
    /// Sends motion frame `index` to one bus servo (a 0x19 frame, `time_ms`). Refused once the
    /// stop flag is set; a failed write stops motion. Both leave a stop line in the journal.
    pub fn send_any(
        &mut self,
        index: u64,
        target: AnyTarget,
        time_ms: u16,
    ) -> Result<(), BusError> {
        self.send_motion_command(index, &Command::MoveAny { target, time_ms })
    }

    /// Reads bus servo `id`'s raw position (0x37); 0 or a value outside `range` (the servo's
    /// raw range) is retried, then a [`BusError::ReadFailure`].
    pub fn read_any_raw(&mut self, id: BusId, range: [u16; 2]) -> Result<u16, BusError> {
        self.request(Command::ReadAny(id), |r, attempt| match *r {
            Reply::AnyPosition { raw } => Some(if raw >= range[0] && raw <= range[1] {
                Ok(raw)
            } else {
                Err(BusError::ReadFailure {
                    servo: id.get(),
                    raw,
                    min: range[0],
                    max: range[1],
                    attempts: attempt,
                })
            }),
            _ => None,
        })
    }

    /// Reads bus servo `id` back at motion `index` and checks it against `expected` within
    /// `tolerance` counts; journals a `verified` line (name `servo ID`, raw `[position]`) or a
    /// stop line.
    pub fn verify_any(
        &mut self,
        index: u64,
        id: BusId,
        range: [u16; 2],
        expected: u16,
        tolerance: u16,
    ) -> Result<u16, BusError> {
        let got = self.read_any_raw(id, range).inspect_err(|e| {
            let _ = self.log_error(e, Some(index), EntryKind::Stop);
        })?;
        self.check_read_back(index, id.get(), expected, got, tolerance)?;
        let mut v = Entry::new(EntryKind::Verified);
        v.motion = Some(index);
        v.name = Some(format!("servo {}", id.get()));
        v.raw = Some(vec![got]);
        self.log(v)?;
        Ok(got)
    }
}

//! The DOFBOT bus: a [`Transport`] (serial port, the Python mock on a pseudo-terminal, the
//! board's I2C interface ([`I2cTransport`] over Linux i2c-dev or the simulator's
//! [`crate::sim::FakeI2c`]), or the in-process [`crate::sim::SimArm`]), the [`Bus`] driver over it
//! and the journal; the servo map is robot's ([`crate::robot::ServoMap`], re-exported here). Frames
//! come only from `dofbot-protocol`'s validated commands.
//!
//! ```no_run
//! use polishbot::bus::{Bus, BusConfig, Journal};
//! use polishbot::sim::{SimArm, SimOptions};
//! let config = BusConfig::default();
//! let arm = SimArm::new(&SimOptions::default(), &config.servo_map).unwrap();
//! let mut bus = Bus::connect(arm.transport(), config, Journal::none()).unwrap();
//! let state = bus.move_joints(&[0.1, 0.2, -0.3, 0.0, 0.5], 90.0, None).unwrap();
//! ```
pub mod alive;
pub mod config;
pub mod driver;
pub mod error;
pub mod i2c;
pub mod journal;
pub mod serial;
pub mod table;
pub mod transport;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

pub use alive::{Liveness, ServoAnswer};
pub use config::{BusConfig, GripperCalib, JointCalib, JointState, ServoMap, JOINT_COUNT};
pub use driver::Bus;
pub use error::BusError;
#[cfg(target_os = "linux")]
pub use i2c::LinuxI2c;
pub use i2c::{I2cBus, I2cTransport};
pub use journal::{Entry, EntryKind, Journal, ResumePoint};
pub use serial::SerialTransport;
pub use transport::Transport;

/// The flag the Ctrl-C handler sets: the last one given to [`install_ctrlc`].
static CTRLC_FLAG: std::sync::Mutex<Option<Arc<AtomicBool>>> = std::sync::Mutex::new(None);

/// Sets `flag` on Ctrl-C (SIGINT) so the bus sends no further motion frames. The handler is
/// installed once per process; a later call (the next run of `cycle`) points it at its flag.
pub fn install_ctrlc(flag: Arc<AtomicBool>) -> Result<(), BusError> {
    let first = {
        let mut current = CTRLC_FLAG.lock().unwrap_or_else(|e| e.into_inner());
        current.replace(flag).is_none()
    };
    if !first {
        return Ok(());
    }
    ctrlc::set_handler(|| {
        if let Some(f) = CTRLC_FLAG
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
        {
            f.store(true, Ordering::SeqCst);
        }
    })
    .map_err(|e| BusError::Refused(format!("cannot install the Ctrl-C handler: {e}")))
}

//! The validated values that commands carry: a raw position is checked against its servo's
//! range when the value is built, so every [`crate::Command`] that exists is safe to encode.
use crate::servo::{RangeError, ServoId, ServoScale, BUS_RAW_MAX, BUS_RAW_MIN, SERVO_COUNT};

/// One servo of the arm and a raw position inside its range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Target {
    pub(crate) id: ServoId,
    pub(crate) raw: u16,
}

impl Target {
    /// Servo `id` to `raw`, refused outside the servo's DOFBOT.md raw range.
    pub fn new(id: ServoId, raw: u16) -> Result<Target, RangeError> {
        id.scale().check_raw(raw)?;
        Ok(Target { id, raw })
    }

    /// The servo.
    pub fn id(&self) -> ServoId {
        self.id
    }

    /// The raw position.
    pub fn raw(&self) -> u16 {
        self.raw
    }
}

/// Raw positions of all six servos, each inside its range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pose {
    pub(crate) raw: [u16; SERVO_COUNT],
}

impl Pose {
    /// Refused if any servo's raw lies outside its DOFBOT.md range.
    pub fn new(raw: [u16; SERVO_COUNT]) -> Result<Pose, RangeError> {
        for id in ServoId::ALL {
            id.scale().check_raw(raw[id.index()])?;
        }
        Ok(Pose { raw })
    }

    /// Raw positions of servos 1..=6.
    pub fn raw(&self) -> [u16; SERVO_COUNT] {
        self.raw
    }
}

/// A bus servo id, 1..=250.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusId(u8);

impl BusId {
    /// Refused unless 1..=250.
    pub fn new(id: u8) -> Result<BusId, RangeError> {
        if (1..=250).contains(&id) {
            Ok(BusId(id))
        } else {
            Err(RangeError::BusId { id })
        }
    }

    /// The id.
    pub fn get(self) -> u8 {
        self.0
    }
}

/// Any bus servo and a raw position: for ids 1..=6 the arm servo's range, else 96..=4000.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnyTarget {
    pub(crate) id: BusId,
    pub(crate) raw: u16,
}

impl AnyTarget {
    /// Checked target for bus servo `id`.
    pub fn new(id: BusId, raw: u16) -> Result<AnyTarget, RangeError> {
        match ServoId::new(id.get()) {
            Ok(servo) => servo.scale().check_raw(raw)?,
            Err(_) => bus_scale(id.get()).check_raw(raw)?,
        }
        Ok(AnyTarget { id, raw })
    }

    /// The bus servo.
    pub fn id(&self) -> BusId {
        self.id
    }

    /// The raw position.
    pub fn raw(&self) -> u16 {
        self.raw
    }
}

fn bus_scale(id: u8) -> ServoScale {
    ServoScale {
        id,
        deg_max: 1.0,
        raw_min: BUS_RAW_MIN,
        raw_max: BUS_RAW_MAX,
        inverted: false,
    }
}

/// One raw position inside the range of every arm servo (for MoveEvery).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EveryRaw(pub(crate) u16);

impl EveryRaw {
    /// Refused unless inside all six servos' ranges.
    pub fn new(raw: u16) -> Result<EveryRaw, RangeError> {
        for id in ServoId::ALL {
            id.scale().check_raw(raw)?;
        }
        Ok(EveryRaw(raw))
    }

    /// The raw position.
    pub fn get(self) -> u16 {
        self.0
    }
}

/// Buzzer setting: off, on, or on for 1..=50 x 100 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Buzzer(pub(crate) u8);

impl Buzzer {
    /// Silent.
    pub const OFF: Buzzer = Buzzer(0);
    /// On until switched off.
    pub const ON: Buzzer = Buzzer(0xFF);

    /// On for `tenths` x 100 ms, 1..=50.
    pub fn for_tenths(tenths: u8) -> Result<Buzzer, RangeError> {
        if (1..=50).contains(&tenths) {
            Ok(Buzzer(tenths))
        } else {
            Err(RangeError::Buzzer { tenths })
        }
    }
}

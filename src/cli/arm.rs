//! `polishbot arm (ping | read | move | torque) (--port DEV | --i2c DEV | --sim)`: direct arm
//! commands.
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};
use serde::Deserialize;
use serde_json::json;

use crate::bus::{
    self, Bus, BusConfig, Journal, SerialTransport, ServoMap, Transport, JOINT_COUNT,
};
use crate::motion::frames;
use crate::robot::{Robot, RobotConfig, Turntable};
use crate::sim::{self, SimArm, SimOptions};

/// Arguments of `polishbot arm`.
#[derive(Debug, Args)]
pub struct ArmArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: ArmAction,
    /// Which arm, and the journal.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Cell folder: its dofbot.urdf, tool.toml, servos.toml and workcell.toml (a `[turntable]`
    /// lets `move --table` turn the table) [default: calibration/].
    #[arg(long, global = true, value_name = "DIR")]
    pub cell: Option<PathBuf>,
}

/// How a command reaches the arm (shared by `arm` and `calibrate`).
#[derive(Debug, Args)]
pub struct LinkArgs {
    /// Which arm.
    #[command(flatten)]
    pub device: DeviceArgs,
    /// Append every frame sent and reply received to this journal (JSON lines).
    #[arg(long, global = true, value_name = "FILE")]
    pub journal: Option<PathBuf>,
}

/// Which arm a command drives: a serial port, an I2C bus or the simulated arm (shared by
/// `arm`, `calibrate` and `run`).
#[derive(Debug, Clone, Default, Args)]
pub struct DeviceArgs {
    /// Serial device of the board (or the mock's pseudo-terminal), e.g. /dev/ttyUSB0.
    #[arg(long, global = true, value_name = "DEV", conflicts_with = "i2c")]
    pub port: Option<String>,
    /// I2C bus of the board (Linux i2c-dev), e.g. /dev/i2c-1 on the Jetson Nano and
    /// Raspberry Pi kits.
    #[arg(long, global = true, value_name = "DEV")]
    pub i2c: Option<String>,
    /// The board's I2C address (with --i2c).
    #[arg(long, global = true, value_name = "ADDR", default_value = "0x15", value_parser = bus::i2c::parse_address)]
    pub i2c_address: u16,
    /// Use the in-process simulated arm instead of a port.
    #[arg(long, global = true, conflicts_with_all = ["port", "i2c"])]
    pub sim: bool,
}

impl DeviceArgs {
    /// The simulated arm.
    pub fn sim() -> DeviceArgs {
        DeviceArgs {
            sim: true,
            i2c_address: u16::from(dofbot_protocol::I2C_ADDRESS),
            ..DeviceArgs::default()
        }
    }
}

/// Test-only: with `--i2c`, this variable names a file and the in-process fake I2C board
/// (the simulated arm behind Arm_Lib's register interface) replaces the device; every
/// transaction is written to the file as a JSON line.
pub const FAKE_I2C_ENV: &str = "POLISHBOT_TEST_FAKE_I2C";

impl LinkArgs {
    /// Opens the bus on the device or on a simulated arm (`sim` settings), journalling to
    /// `--journal` if given. `command` names the command in the "give --port, --i2c or --sim"
    /// error.
    pub fn connect(
        &self,
        command: &str,
        config: BusConfig,
        sim: &SimOptions,
    ) -> anyhow::Result<Bus<Box<dyn Transport>>> {
        let journal = match &self.journal {
            Some(p) => Journal::append(p)?,
            None => Journal::none(),
        };
        let link = open_link(&self.device, sim, &config.servo_map, command)?;
        Ok(Bus::connect(link, config, journal)?)
    }
}

/// The transport of a command that reaches the arm: the serial port, the I2C bus, or a
/// simulated arm (`options`, homed through `map`). `command` names the command in the
/// "give --port, --i2c or --sim" error.
pub fn open_link(
    device: &DeviceArgs,
    options: &SimOptions,
    map: &ServoMap,
    command: &str,
) -> anyhow::Result<Box<dyn Transport>> {
    Ok(if let Some(port) = &device.port {
        Box::new(SerialTransport::open(port)?)
    } else if let Some(dev) = &device.i2c {
        open_i2c(dev, device.i2c_address, options, map)?
    } else if device.sim {
        Box::new(SimArm::new(options, map)?.transport())
    } else {
        anyhow::bail!("{command}: give --port DEV, --i2c DEV or --sim")
    })
}

/// The simulator's settings with the cell's turntable servo on the bus (at table angle 0)
/// unless `[sim] extra_servos` already lists its id.
pub fn sim_with_table(
    options: &SimOptions,
    table: Option<&Turntable>,
) -> anyhow::Result<SimOptions> {
    let mut options = options.clone();
    if let Some(t) = table {
        if !options.extra_servos.iter().any(|e| e.id == t.servo.id) {
            let start_raw = t
                .raw(0.0)
                .map_err(|m| anyhow::anyhow!("turntable servo {}: {m}", t.servo.id))?;
            options.extra_servos.push(sim::ExtraServo {
                id: t.servo.id,
                start_raw,
            });
        }
    }
    Ok(options)
}

/// Longest move time, s: the board's move command carries the time in milliseconds as a
/// 16-bit count.
const MAX_MOVE_TIME_S: f64 = u16::MAX as f64 / 1000.0;

fn open_i2c(
    dev: &str,
    address: u16,
    options: &SimOptions,
    map: &ServoMap,
) -> anyhow::Result<Box<dyn Transport>> {
    if let Some(log) = std::env::var_os(FAKE_I2C_ENV) {
        // The I2C board always answers a ping with its status byte.
        let options = SimOptions {
            ping_reply: sim::PingReply::Status,
            ..options.clone()
        };
        let fake =
            sim::FakeI2c::new(SimArm::new(&options, map)?, address).logging_to(Path::new(&log))?;
        return Ok(Box::new(bus::I2cTransport::new(fake)));
    }
    #[cfg(target_os = "linux")]
    {
        Ok(Box::new(bus::I2cTransport::new(bus::LinuxI2c::open(
            dev, address,
        )?)))
    }
    #[cfg(not(target_os = "linux"))]
    anyhow::bail!("--i2c {dev}: I2C needs Linux i2c-dev")
}

/// The arm actions.
#[derive(Debug, Subcommand)]
pub enum ArmAction {
    /// Ping and read the six servos (alive: the position reads back; boards that do not
    /// answer pings are reported, not refused) and read the board version.
    Ping,
    /// Read the joints (rad, URDF convention), the gripper angle and the raw positions.
    Read,
    /// Move to joint angles, wait, read back and verify; or (`--table DEG`) turn the cell's
    /// turntable in one rest-to-rest move while the arm stays at its home pose.
    Move {
        /// Joint angles q1,..,q5 in radians (URDF convention: servo deg = q*180/pi + 90).
        #[arg(
            long,
            value_delimiter = ',',
            num_args = 1,
            allow_hyphen_values = true,
            required_unless_present = "table",
            conflicts_with = "table"
        )]
        joints: Vec<f64>,
        /// Turn the cell's turntable to this table angle, degrees (0: the calibrated
        /// placement), within its range and limits; the arm must be at its home pose.
        #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
        table: Option<f64>,
        /// Move time in seconds (default: the fastest the joint velocity limits allow).
        #[arg(long, value_name = "S")]
        time: Option<f64>,
        /// Gripper servo angle in degrees, 0 open .. 180 closed (default: keep).
        #[arg(long, value_name = "DEG")]
        gripper: Option<f64>,
    },
    /// Torque on or off for all servos (off: the arm can be moved by hand).
    Torque {
        /// on | off
        #[arg(value_parser = ["on", "off"])]
        state: String,
    },
}

/// `--config` TOML of `arm`: `[robot]` (the calibration files: the servo map always comes from
/// servos.toml, as for `run`), `[bus]` (driver timing) and `[sim]` (SimOptions).
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArmConfig {
    /// Robot description and calibration files.
    pub robot: RobotConfig,
    /// Driver settings.
    pub bus: BusConfig,
    /// Simulated arm settings (with `--sim`).
    pub sim: SimOptions,
}

/// Runs `polishbot arm`.
pub fn run(args: ArmArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: ArmConfig = file.parse()?;
    super::settings::check_link(&file, &cfg.bus, &cfg.sim)?;
    if let Some(dir) = &args.cell {
        cfg.robot.use_cell(dir);
    }
    let robot = Robot::load(&cfg.robot.urdf, &cfg.robot.tool, &cfg.robot.servos)?;
    let table = Turntable::load(&cfg.robot.servos, &cfg.robot.workcell)?;
    let sim = sim_with_table(&cfg.sim, table.as_ref())?;
    let mut bus_cfg = cfg.bus;
    bus_cfg.servo_map = frames::servo_map(&robot)?;
    // `arm ping` checks every servo itself instead of failing at the first silent one.
    if matches!(args.action, ArmAction::Ping) {
        bus_cfg.ping_at_connect = false;
    }
    if let ArmAction::Move {
        table: Some(deg), ..
    } = args.action
    {
        let table = table.ok_or_else(|| {
            anyhow::anyhow!(
                "--table: {} has no [turntable] (give --cell DIR of a cell with one)",
                cfg.robot.servos.display()
            )
        })?;
        let settle = bus_cfg.settle_ms;
        let mut bus = args.link.connect("arm", bus_cfg, &sim)?;
        bus::install_ctrlc(bus.stop_flag()).context("arm move --table")?;
        let out = super::table::turn(&mut bus, &table, deg, robot.servos.period, settle)?;
        println!("{out}");
        return Ok(());
    }
    act(args.link.connect("arm", bus_cfg, &sim)?, &args.action)
}

fn act<T: Transport>(mut bus: Bus<T>, action: &ArmAction) -> anyhow::Result<()> {
    let port = bus.transport().describe();
    let out = match action {
        ArmAction::Ping => {
            let live = bus.liveness(true)?;
            // Not every board answers the version request either: report it when it does.
            let version = match bus.version() {
                Ok(v) => Some(v),
                Err(bus::BusError::Timeout { .. }) => None,
                Err(e) => return Err(e.into()),
            };
            println!(
                "{}",
                json!({"port": port, "servos": live.servos, "evidence": live.evidence(), "version": version})
            );
            return match live.first_failure() {
                Some(e) => Err(e.into()),
                None => Ok(()),
            };
        }
        ArmAction::Read => serde_json::to_value(bus.read_joints()?)?,
        ArmAction::Move {
            joints,
            time,
            gripper,
            ..
        } => {
            let q: [f64; JOINT_COUNT] = joints.as_slice().try_into().map_err(|_| {
                anyhow::anyhow!("--joints: need {JOINT_COUNT} values, got {}", joints.len())
            })?;
            let time = match time {
                Some(t) if !(t.is_finite() && *t > 0.0 && *t <= MAX_MOVE_TIME_S) => {
                    anyhow::bail!("--time: {t:?} s is outside 0..={MAX_MOVE_TIME_S} s")
                }
                Some(t) => Some(Duration::from_secs_f64(*t)),
                None => None,
            };
            bus::install_ctrlc(bus.stop_flag()).context("arm move")?;
            let gripper = match gripper {
                Some(g) => *g,
                None => bus.read_joints()?.gripper_deg,
            };
            serde_json::to_value(bus.move_joints(&q, gripper, time)?)?
        }
        ArmAction::Torque { state } => {
            let on = state == "on";
            bus.torque(on)?;
            json!({"torque": on})
        }
    };
    println!("{out}");
    Ok(())
}

//! `polishbot arm (ping | read | move | torque) (--port DEV | --sim)`: direct arm commands.
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};
use serde::Deserialize;
use serde_json::json;

use crate::bus::{
    self, Bus, BusConfig, Journal, SerialTransport, ServoMap, SimArm, SimOptions, Transport,
    JOINT_COUNT,
};
use crate::plan::frames;
use crate::robot::{Robot, RobotConfig};

/// Arguments of `polishbot arm`.
#[derive(Debug, Args)]
pub struct ArmArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: ArmAction,
    /// Which arm, and the journal.
    #[command(flatten)]
    pub link: LinkArgs,
}

/// How a command reaches the arm (shared by `arm` and `calibrate`).
#[derive(Debug, Args)]
pub struct LinkArgs {
    /// Serial device of the board (or the mock's pseudo-terminal), e.g. /dev/ttyUSB0.
    #[arg(long, global = true, value_name = "DEV")]
    pub port: Option<String>,
    /// Use the in-process simulated arm instead of a port.
    #[arg(long, global = true, conflicts_with = "port")]
    pub sim: bool,
    /// Append every frame sent and reply received to this journal (JSON lines).
    #[arg(long, global = true, value_name = "FILE")]
    pub journal: Option<PathBuf>,
}

impl LinkArgs {
    /// Opens the bus on the port or on a simulated arm (`sim` settings), journalling to
    /// `--journal` if given. `command` names the command in the "give --port or --sim" error.
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
        let link = open_link(
            self.port.as_deref(),
            self.sim,
            sim,
            &config.servo_map,
            command,
        )?;
        Ok(Bus::connect(link, config, journal)?)
    }
}

/// The transport of a command that reaches the arm: the serial `port`, or with `sim` a
/// simulated arm (`options`, homed through `map`). `command` names the command in the
/// "give --port or --sim" error.
pub fn open_link(
    port: Option<&str>,
    sim: bool,
    options: &SimOptions,
    map: &ServoMap,
    command: &str,
) -> anyhow::Result<Box<dyn Transport>> {
    Ok(if let Some(port) = port {
        Box::new(SerialTransport::open(port)?)
    } else if sim {
        Box::new(SimArm::new(options, map)?.transport())
    } else {
        anyhow::bail!("{command}: give --port DEV or --sim")
    })
}

/// Longest move time, s: the board's move command carries the time in milliseconds as a
/// 16-bit count.
const MAX_MOVE_TIME_S: f64 = u16::MAX as f64 / 1000.0;

/// The arm actions.
#[derive(Debug, Subcommand)]
pub enum ArmAction {
    /// Ping the six servos and read the board version.
    Ping,
    /// Read the joints (rad, URDF convention), the gripper angle and the raw positions.
    Read,
    /// Move to joint angles, wait, read back and verify.
    Move {
        /// Joint angles q1,..,q5 in radians (URDF convention: servo deg = q*180/pi + 90).
        #[arg(
            long,
            value_delimiter = ',',
            num_args = 1,
            allow_hyphen_values = true,
            required = true
        )]
        joints: Vec<f64>,
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
    let cfg: ArmConfig = file.parse()?;
    super::settings::check_link(&file, &cfg.bus, &cfg.sim)?;
    let robot = Robot::load(&cfg.robot.urdf, &cfg.robot.tool, &cfg.robot.servos)?;
    let mut bus_cfg = cfg.bus;
    bus_cfg.servo_map = frames::servo_map(&robot)?;
    // `arm ping` reports every servo itself instead of failing at the first silent one.
    if matches!(args.action, ArmAction::Ping) {
        bus_cfg.ping_at_connect = false;
    }
    act(args.link.connect("arm", bus_cfg, &cfg.sim)?, &args.action)
}

fn act<T: Transport>(mut bus: Bus<T>, action: &ArmAction) -> anyhow::Result<()> {
    let port = bus.transport().describe();
    let out = match action {
        ArmAction::Ping => {
            let mut servos = Vec::new();
            for id in 1..=6u8 {
                servos.push(json!({"id": id, "alive": bus.ping(id)?}));
            }
            let version = bus.version()?;
            println!(
                "{}",
                json!({"port": port, "servos": servos, "version": version})
            );
            if let Some(dead) = servos.iter().find(|s| s["alive"] == false) {
                return Err(bus::BusError::NotAnswering {
                    servo: dead["id"].as_u64().unwrap_or(0) as u8,
                }
                .into());
            }
            return Ok(());
        }
        ArmAction::Read => serde_json::to_value(bus.read_joints()?)?,
        ArmAction::Move {
            joints,
            time,
            gripper,
        } => {
            let q: [f64; JOINT_COUNT] = joints.as_slice().try_into().map_err(|_| {
                anyhow::anyhow!("--joints: need {JOINT_COUNT} values, got {}", joints.len())
            })?;
            let time = match time {
                Some(t) if !(t.is_finite() && *t > 0.0 && *t <= MAX_MOVE_TIME_S) => {
                    anyhow::bail!("--time: {t} s is outside 0..={MAX_MOVE_TIME_S} s")
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

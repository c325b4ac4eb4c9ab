//! The robot: the DOFBOT's URDF chain (k), the calibration files of the cell (tool, servos,
//! workcell), forward kinematics, inverse kinematics (closed form for the DOFBOT, k's Jacobian
//! solver otherwise), the tool-tip error that servo resolution causes, and the joint <-> servo
//! map that plan and bus share.
//!
//! Front function: [`load`] with a [`RobotConfig`].
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

pub mod calibration;
pub mod cell_files;
pub mod compliance;
pub mod error;
pub mod ik;
pub mod model;
mod planar;
pub mod resolution;
pub mod servo_map;
pub mod tool_library;
pub mod turntable;
pub mod units;

pub use calibration::{FileText, Servo, Servos, Tool, ToolText, Workcell};
pub use cell_files::{sha256_hex, CellFiles};
pub use compliance::Compliance;
pub use error::RobotError;
pub use ik::{angle_between, IkConfig, IkSolution, IkTarget, Unreachable};
pub use model::{JointSpec, Robot, ToolPose};
pub use resolution::resolution_error;
pub use servo_map::{
    GripperCalib, JointCalib, JointState, MapRefused, ServoMap, ServoMapError, JOINT_COUNT,
};
pub use turntable::Turntable;

/// Where the robot description and the cell's calibration files are, and the IK settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotConfig {
    /// The URDF (default `calibration/dofbot.urdf`; every default path is under the working
    /// directory, see [`default_calibration`]).
    pub urdf: PathBuf,
    /// The tool file (default `calibration/tool.toml`).
    pub tool: PathBuf,
    /// The servo file (default `calibration/servos.toml`).
    pub servos: PathBuf,
    /// The workcell file (default `calibration/workcell.toml`).
    pub workcell: PathBuf,
    /// Inverse-kinematics settings.
    pub ik: IkConfig,
}

/// `calibration/NAME` under the working directory: the cell's files are named explicitly
/// (`--config` with `[robot]` paths) or found in `./calibration/`, never taken from the source
/// tree the binary was built from (that would run one cell with another's calibration).
pub fn default_calibration(name: &str) -> PathBuf {
    PathBuf::from("calibration").join(name)
}

impl Default for RobotConfig {
    fn default() -> Self {
        RobotConfig {
            urdf: default_calibration("dofbot.urdf"),
            tool: default_calibration("tool.toml"),
            servos: default_calibration("servos.toml"),
            workcell: default_calibration("workcell.toml"),
            ik: IkConfig::default(),
        }
    }
}

impl RobotConfig {
    /// Takes the urdf, tool, servos and workcell files from the cell folder `dir` (the layout
    /// of `calibration/`, e.g. `calibration/turntable/`).
    pub fn use_cell(&mut self, dir: &std::path::Path) {
        self.urdf = dir.join("dofbot.urdf");
        self.tool = dir.join("tool.toml");
        self.servos = dir.join("servos.toml");
        self.workcell = dir.join("workcell.toml");
    }

    /// solids.toml beside the workcell file (the cell's fixed solids, when it exists).
    pub fn solids(&self) -> PathBuf {
        self.workcell.with_file_name("solids.toml")
    }

    /// Reads the cell's files this config names, once (solids.toml when it exists), to hand
    /// on in memory.
    pub fn read_cell(&self) -> Result<CellFiles, RobotError> {
        let solids = self.solids();
        Ok(CellFiles {
            urdf: FileText::read(&self.urdf)?,
            tool: FileText::read(&self.tool)?,
            servos: FileText::read(&self.servos)?,
            workcell: FileText::read(&self.workcell)?,
            solids: solids
                .exists()
                .then(|| FileText::read(&solids))
                .transpose()?,
            tools: tool_library::read_further(&self.tool)?,
        })
    }
}

/// Loads the robot model (URDF + tool + servos) and the workcell named by `config`.
pub fn load(config: &RobotConfig) -> Result<(Robot, Workcell), RobotError> {
    let tool = Tool::load(&config.tool)?;
    let robot = Robot::with_tool(&config.urdf, tool, &config.servos)?;
    let workcell = Workcell::load(&config.workcell)?;
    Ok((robot, workcell))
}

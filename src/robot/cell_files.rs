//! A cell's files held in memory ([`CellFiles`]): the URDF, tool.toml, servos.toml,
//! workcell.toml and solids.toml, read once where a command starts (`RobotConfig::read_cell`)
//! or given by the caller (the demo's built-in cell), then parsed from memory by the plan, the
//! run and the loop: no stage reads a cell file back.
use super::calibration::{FileText, ToolText, Workcell};
use super::error::RobotError;
use super::model::Robot;
use super::turntable::Turntable;

/// The cell's files, held: each file's path (named in errors and recorded in provenance) and
/// text.
#[derive(Debug, Clone, PartialEq)]
pub struct CellFiles {
    /// The robot description (URDF).
    pub urdf: FileText,
    /// tool.toml.
    pub tool: ToolText,
    /// servos.toml.
    pub servos: FileText,
    /// workcell.toml.
    pub workcell: FileText,
    /// solids.toml beside the workcell file, when the cell has one.
    pub solids: Option<FileText>,
    /// The tool library's further tools (`tools/NAME.toml` beside tool.toml, by name; empty:
    /// tool.toml is the library, [`super::tool_library`]).
    pub tools: Vec<ToolText>,
}

impl CellFiles {
    /// The same cell with the tool file `tool` (the loop's refitted tool).
    pub fn with_tool(&self, tool: &ToolText) -> CellFiles {
        CellFiles {
            tool: tool.clone(),
            ..self.clone()
        }
    }

    /// The tool library: tool.toml, then the further tools (each with its library name).
    pub fn library(&self) -> Vec<(String, &ToolText)> {
        let mut all = vec![(super::tool_library::DEFAULT_TOOL.to_string(), &self.tool)];
        all.extend((self.tools.iter()).map(|t| (super::tool_library::tool_name(t), t)));
        all
    }

    /// The library's tool `name` (tool.toml: [`super::tool_library::DEFAULT_TOOL`]).
    pub fn library_tool(&self, name: &str) -> Option<&ToolText> {
        self.library()
            .into_iter()
            .find(|(n, _)| n == name)
            .map(|t| t.1)
    }

    /// The arm: the URDF chain with the tool and the servos ([`Robot::from_texts`]).
    pub fn robot(&self) -> Result<Robot, RobotError> {
        Robot::from_texts(&self.urdf, self.tool.tool()?, &self.servos)
    }

    /// The part's placement ([`Workcell::parse`]).
    pub fn workcell(&self) -> Result<Workcell, RobotError> {
        Workcell::parse(&self.workcell.path, &self.workcell.text)
    }

    /// The cell's turntable, if it has one ([`Turntable::parse`]).
    pub fn turntable(&self) -> Result<Option<Turntable>, RobotError> {
        Turntable::parse(&self.servos, &self.workcell)
    }

    /// The arm and the part's placement.
    pub fn load(&self) -> Result<(Robot, Workcell), RobotError> {
        Ok((self.robot()?, self.workcell()?))
    }

    /// The files by the role plan.json's provenance names them with (`cycle::plan_inputs`);
    /// solids.toml only when the cell has one.
    pub fn by_role(&self) -> Vec<(&'static str, &FileText)> {
        let mut files = vec![
            ("robot description", &self.urdf),
            ("tool", &self.tool),
            ("servo calibration", &self.servos),
            ("workcell", &self.workcell),
        ];
        files.extend(self.solids.iter().map(|s| ("solids", s)));
        files
    }
}

/// SHA-256 of `bytes`, lowercase hex: how plan.json names the cell's files and a setup's
/// placement, so that `run` can tell the cell a plan was made for.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    let digest = sha2::Sha256::digest(bytes);
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

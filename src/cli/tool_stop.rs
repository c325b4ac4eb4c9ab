//! The tool change of `run` (issue 51): a plan made with a cell's tool library grinds each
//! setup's regions grouped by tool, largest ball first; between two tools the run ends with
//! an operator stop of kind `tool_change` (the one path of `super::setup_stop`: journaled,
//! exit 5, one line naming the tool to mount), and `run --resume` streams the next tool's
//! plan only when the cell's file of that tool is the one the plan was made with (its
//! SHA-256, plan.json `tools[].tool_sha256`). On the simulated arm the operator is simulated:
//! `run --sim` mounts the tool asked for and resumes by itself
//! (`super::setup_stop::simulated_operator`).
use crate::motion::file::ToolPart;
use crate::robot::{sha256_hex, CellFiles, Robot};

/// The operator stop's kind of a tool change (journal `code`).
pub const TOOL_CHANGE: &str = "tool_change";

/// What the operator mounts: the tool `now` (the tool mounted before: `was`), one clause.
pub fn message(now: Option<&ToolPart>, was: Option<&ToolPart>) -> String {
    let Some(t) = now else {
        return "keep the tool".into();
    };
    let before = was.map_or(String::new(), |w| format!(" in place of `{}`", w.tool));
    format!(
        "mount tool `{}` (ball {:.1} mm radius, shank {:.1} mm; {}){before}",
        t.tool, t.ball_radius_mm, t.shank_length_mm, t.file
    )
}

/// The arm with the tool `tool` of the cell's library on it (None: the cell's tool.toml), after
/// checking that the cell's file of that tool is the one the plan was made with.
pub fn robot_for(cell: &CellFiles, tool: Option<&ToolPart>) -> anyhow::Result<Robot> {
    let Some(t) = tool else {
        return Ok(cell.robot()?);
    };
    let text = cell.library_tool(&t.tool).ok_or_else(|| {
        anyhow::anyhow!(
            "{}: refused: the plan grinds with tool `{}` ({}), which the cell's tool library does not hold",
            cell.tool.path.display(),
            t.tool,
            t.file
        )
    })?;
    let now = sha256_hex(text.text.as_bytes());
    anyhow::ensure!(
        now == t.tool_sha256,
        "{}: refused: tool `{}` is not the one the plan was made with (SHA-256 {}, the plan's {}): mount and calibrate that tool, or re-plan",
        text.path.display(),
        t.tool,
        &now[..12],
        &t.tool_sha256[..t.tool_sha256.len().min(12)]
    );
    Ok(cell.with_tool(text).robot()?)
}

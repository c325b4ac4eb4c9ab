//! A cell's tool library (issue 51): tool.toml is the mounted-by-default tool, and a folder
//! `tools/` beside it may hold further tools, `tools/NAME.toml`, each a complete tool file
//! (tip offset, ball and shank, its own `[removal]` calibration). A cell with tool.toml alone
//! is the library of one tool. The planner picks per region the largest ball that fits and
//! reaches; a planned tool change stops the run for the operator (`cli::setup_stop`).
//!
//! Front function: [`read_further`] (the library's tools besides tool.toml, read once where a
//! command starts).
use std::path::{Path, PathBuf};

use super::calibration::{FileText, ToolText};
use super::error::RobotError;

/// The library's folder beside tool.toml.
pub const TOOLS_DIR: &str = "tools";

/// The name tool.toml goes by in the library and in plan.json (`tools[].tool`).
pub const DEFAULT_TOOL: &str = "tool";

/// Most tools read from a library: a small cell's tool rack holds a handful.
const MAX_TOOLS: usize = 16;

/// The tool's name in the library: its file's stem (`tools/small.toml`: `small`;
/// tool.toml: [`DEFAULT_TOOL`]).
pub fn tool_name(tool: &ToolText) -> String {
    let stem = tool.path.file_stem().and_then(|s| s.to_str());
    stem.unwrap_or(DEFAULT_TOOL).to_string()
}

/// The library folder of the cell whose tool file is `tool_file`.
pub fn tools_dir(tool_file: &Path) -> PathBuf {
    let dir = tool_file.parent().unwrap_or(Path::new("."));
    dir.join(TOOLS_DIR)
}

/// The library's tools besides `tool_file` (tool.toml): `tools/*.toml` beside it, by name,
/// each read and checked as a tool file; empty when there is no `tools/` folder.
pub fn read_further(tool_file: &Path) -> Result<Vec<ToolText>, RobotError> {
    let dir = tools_dir(tool_file);
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let entries = std::fs::read_dir(&dir).map_err(|e| RobotError::Io {
        file: dir.clone(),
        message: e.to_string(),
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    if files.len() > MAX_TOOLS {
        let msg = format!("{} tool files, at most {MAX_TOOLS}", files.len());
        return Err(RobotError::bad(&dir, "folder", msg));
    }
    let tools = files
        .iter()
        .map(|f| FileText::read(f))
        .collect::<Result<Vec<_>, _>>()?;
    for t in &tools {
        t.tool()?;
        if tool_name(t) == DEFAULT_TOOL {
            let msg = format!("`{DEFAULT_TOOL}` is tool.toml's name in the library; rename it");
            return Err(RobotError::bad(&t.path, "file name", msg));
        }
    }
    Ok(tools)
}

/// The tool file `name_or_file` names for the cell whose tool file is `tool_file`: a library
/// tool's name (`small`: `tools/small.toml`; [`DEFAULT_TOOL`]: `tool_file`) when such a tool
/// exists, else the path as given.
pub fn resolve(tool_file: &Path, name_or_file: &Path) -> PathBuf {
    let Some(name) = name_or_file.to_str() else {
        return name_or_file.to_path_buf();
    };
    if name == DEFAULT_TOOL {
        return tool_file.to_path_buf();
    }
    let file = tools_dir(tool_file).join(format!("{name}.toml"));
    let plain = !name.contains(['/', '\\', '.']);
    if plain && file.is_file() {
        file
    } else {
        name_or_file.to_path_buf()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cell folder with the shipped tool.toml and `tools/` holding `names`.
    fn cell(names: &[&str]) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/calibration/tool.toml");
        let text = std::fs::read_to_string(shipped).unwrap();
        let tool = dir.path().join("tool.toml");
        std::fs::write(&tool, &text).unwrap();
        std::fs::create_dir_all(dir.path().join(TOOLS_DIR)).unwrap();
        for n in names {
            std::fs::write(tools_dir(&tool).join(format!("{n}.toml")), &text).unwrap();
        }
        (dir, tool)
    }

    #[test]
    fn the_library_is_tool_toml_and_the_tools_folder_by_name() {
        let (_dir, tool) = cell(&["small", "fine"]);
        let names: Vec<String> = read_further(&tool).unwrap().iter().map(tool_name).collect();
        assert_eq!(names, ["fine", "small"]);
        let small = tools_dir(&tool).join("small.toml");
        assert_eq!(resolve(&tool, Path::new("small")), small);
        assert_eq!(resolve(&tool, Path::new(DEFAULT_TOOL)), tool);
        // not a library name: the path as given
        assert_eq!(resolve(&tool, Path::new("other")), Path::new("other"));
        assert_eq!(resolve(&tool, Path::new("a/b.toml")), Path::new("a/b.toml"));
    }

    #[test]
    fn a_cell_without_a_tools_folder_is_the_library_of_one_tool() {
        let dir = tempfile::tempdir().unwrap();
        assert!(read_further(&dir.path().join("tool.toml"))
            .unwrap()
            .is_empty());
    }

    #[test]
    fn a_library_file_named_tool_or_not_a_tool_file_is_refused_with_its_path() {
        let (_dir, tool) = cell(&[DEFAULT_TOOL]);
        let e = read_further(&tool).unwrap_err().to_string();
        assert!(e.contains("tools/tool.toml") && e.contains("rename"), "{e}");
        let (_dir, tool) = cell(&[]);
        std::fs::write(tools_dir(&tool).join("bad.toml"), "radius = \"x\"\n").unwrap();
        let e = read_further(&tool).unwrap_err().to_string();
        assert!(e.contains("tools/bad.toml"), "{e}");
    }
}

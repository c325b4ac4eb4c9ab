//! Errors of the robot model: every one names the file and the place.
use std::path::{Path, PathBuf};

/// A fault in the robot description or its calibration files.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// A file could not be read.
    #[error("{}: {message}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// What failed.
        message: String,
    },
    /// A file could not be parsed, or a key holds a bad value.
    #[error("{}: {place}: {message}", file.display())]
    Bad {
        /// The file.
        file: PathBuf,
        /// The key (`servo[2].velocity`) or line (`line 12`) at fault.
        place: String,
        /// What is wrong.
        message: String,
    },
}

impl RobotError {
    /// A bad value at `place` (a key path or a line) of `file`.
    pub fn bad(file: &Path, place: impl Into<String>, message: impl Into<String>) -> Self {
        RobotError::Bad {
            file: file.to_path_buf(),
            place: place.into(),
            message: message.into(),
        }
    }
}

/// Reads a TOML file into `T`; parse errors name the line and quote it.
pub fn read_toml<T: serde::de::DeserializeOwned>(file: &Path) -> Result<T, RobotError> {
    parse_toml(file, &read_text(file)?)
}

/// Reads `file` as text; the error names it.
pub fn read_text(file: &Path) -> Result<String, RobotError> {
    std::fs::read_to_string(file).map_err(|e| RobotError::Io {
        file: file.to_path_buf(),
        message: e.to_string(),
    })
}

/// Parses `text` (the file `file`, named in errors) into `T`; parse errors name the line and
/// quote it.
pub fn parse_toml<T: serde::de::DeserializeOwned>(
    file: &Path,
    text: &str,
) -> Result<T, RobotError> {
    toml::from_str(text).map_err(|e| {
        let place = match e.span() {
            Some(span) => {
                let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
                let quoted = text.lines().nth(line - 1).unwrap_or("").trim();
                format!("line {line} (`{quoted}`)")
            }
            None => "file".to_string(),
        };
        RobotError::bad(file, place, e.message().replace('\n', " "))
    })
}

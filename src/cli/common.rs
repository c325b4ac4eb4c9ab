//! What several subcommands share: the geometry input options, the settings file reader and
//! the one-line error form and the reader of the JSON files the tool wrote.
use std::path::Path;

use anyhow::Context;
use clap::Args;

use super::settings;
use crate::cloud::{Format, Units};

/// Options every command that reads geometry takes.
#[derive(Debug, Clone, Args, Default)]
pub struct GeometryInput {
    /// Length unit of the input files (m or mm). Required when a file looks like metres.
    #[arg(long, value_enum)]
    pub units: Option<Units>,
    /// File format, overriding the file's extension.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
}

/// Loads a reference file: a cloud as is, a mesh sampled with facet normals (`samples`
/// points, seed `seed`).
pub fn load_reference(
    path: &Path,
    input: &GeometryInput,
    samples: usize,
    seed: u64,
) -> anyhow::Result<crate::cloud::PointCloud> {
    use crate::cloud::{self, Geometry};
    let loaded = cloud::load(path, input.format, input.units)?;
    Ok(match loaded.geometry {
        Geometry::Cloud(c) => c,
        Geometry::Mesh { mesh, .. } => {
            cloud::sample_mesh(&mesh, samples, seed)
                .with_context(|| path.display().to_string())?
                .cloud
        }
    })
}

pub use crate::cycle::one_line;

/// Reads an optional TOML config file into `T` (missing file argument: `T::default()`);
/// errors name the file and the line.
pub fn load_config<T: serde::de::DeserializeOwned + Default>(
    path: Option<&std::path::Path>,
) -> anyhow::Result<T> {
    settings::ConfigFile::read(path)?.parse()
}

/// Reads a JSON file the tool wrote (an inspection's registration.json or regions.json);
/// errors name the file and the line.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: line {}: {e}", path.display(), e.line()))
}

/// Prints one line of a calibration routine's report (flushed at once: the jog terminal runs
/// raw).
pub fn say(line: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

//! The inspection's settings ([`InspectConfig`], one section per stage) and its inputs.
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::cloud::{Format, Units};
use crate::compare::{CompareConfig, CoreConfig};
use crate::preprocess::SorConfig;
use crate::regions::RegionConfig;
use crate::register::RegisterConfig;

/// Settings of an inspection (TOML `--config` of `inspect`), one section per stage.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InspectConfig {
    /// Points sampled on a mesh reference (default [`DEFAULT_REFERENCE_POINTS`] when 0).
    pub reference_points: usize,
    /// Core points.
    pub core: CoreConfig,
    /// Comparison.
    pub compare: CompareConfig,
    /// Regions.
    pub regions: RegionConfig,
    /// Statistical outlier filter of the scan.
    pub filter: SorConfig,
    /// Registration (skipped when a pose is given).
    pub register: RegisterConfig,
    /// The cell the suggested views are for (printed with an incomplete verdict).
    pub suggest: super::suggest::SuggestConfig,
}

/// Points sampled on a mesh reference when `reference_points` is 0: about 0.07 mm apart on a
/// femoral component, denser than the scans the comparison meets.
pub const DEFAULT_REFERENCE_POINTS: usize = 400_000;

/// Most points sampled on a mesh reference (`reference_points`): 5 million points and normals
/// are 240 MB, far denser than any scan the comparison meets.
pub const MAX_REFERENCE_POINTS: usize = 5_000_000;

/// How the input files are read.
#[derive(Debug, Clone, Copy, Default)]
pub struct FileInput {
    /// File format (default: from the extension).
    pub format: Option<Format>,
    /// Length unit (required when a file looks like metres).
    pub units: Option<Units>,
}

/// What an inspection measures: the files and the choices that are not settings.
#[derive(Debug, Clone)]
pub struct Inputs {
    /// Reference: a mesh (sampled with its facet normals) or a cloud (with or without normals).
    pub reference: PathBuf,
    /// Scan point cloud.
    pub scan: PathBuf,
    /// Further scans of the same part (other setups), each registered to the reference on its
    /// own and measured jointly with `scan` (default none).
    pub more_scans: Vec<PathBuf>,
    /// Format and units of every input file.
    pub files: FileInput,
    /// Skip registration: `scan_to_reference` from this registration.json or truth.json.
    pub pose: Option<PathBuf>,
    /// Core points with outward unit normals, instead of a sample of the reference.
    pub core: Option<PathBuf>,
    /// The area to inspect (reference frame); default the whole reference.
    pub inspect_area: Option<PathBuf>,
    /// Registration error of the level of detection, mm (default the registration's own).
    pub registration_error: Option<f64>,
}

//! The inspection's settings ([`InspectConfig`], one section per stage) and its inputs.
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::cloud::{self, Format, Geometry, PointCloud, Units};
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
    pub reference: Source,
    /// Scan point cloud.
    pub scan: Source,
    /// Further scans of the same part (other setups), each registered to the reference on its
    /// own and measured jointly with `scan` (default none).
    pub more_scans: Vec<Source>,
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
    /// Radius of a second, classic reading of every core point, mm (`Findings::fine`; None:
    /// none is made). The closed loop reads its inspections at the tool's footprint this way
    /// when `cycle --footprint-radius` is given (`cycle::planner_input`).
    pub fine_radius: Option<f64>,
}

/// An input geometry: a file to read, or a file this process wrote with what it wrote still
/// held (the closed loop's rescan, the demo's synthetic part), used instead of reading the
/// file back. Either way the file's path names it in messages and in the provenance.
#[derive(Debug, Clone)]
pub struct Source {
    path: PathBuf,
    held: Option<Arc<Held>>,
}

/// What this process wrote to a [`Source`]'s file.
#[derive(Debug)]
struct Held {
    /// The geometry, millimetres, as reading the file in millimetres gives it.
    geometry: Geometry,
    /// The bytes written (the provenance's size and SHA-256).
    bytes: Vec<u8>,
}

impl Source {
    /// The file `path`, read when loaded.
    pub fn file(path: impl Into<PathBuf>) -> Source {
        Source {
            path: path.into(),
            held: None,
        }
    }

    /// The file `path` this process wrote as `bytes`, whose geometry (millimetres) is
    /// `geometry`: loading it reads nothing (the file's units and format are those written).
    pub fn held(path: impl Into<PathBuf>, geometry: Geometry, bytes: Vec<u8>) -> Source {
        Source {
            path: path.into(),
            held: Some(Arc::new(Held { geometry, bytes })),
        }
    }

    /// The file.
    pub fn as_path(&self) -> &Path {
        &self.path
    }

    /// The bytes written to the file, when this process holds them.
    pub fn held_bytes(&self) -> Option<&[u8]> {
        self.held.as_deref().map(|h| h.bytes.as_slice())
    }

    /// The held geometry's points and attributes (a mesh's vertices), when held.
    pub fn held_cloud(&self) -> Option<&PointCloud> {
        self.held.as_deref().map(|h| match &h.geometry {
            Geometry::Cloud(c) => c,
            Geometry::Mesh { attributes, .. } => attributes,
        })
    }

    /// The geometry in millimetres: the held one, else the file read as `files` says
    /// ([`cloud::load`]).
    pub fn load(&self, files: FileInput) -> anyhow::Result<Geometry> {
        match &self.held {
            Some(h) => Ok(h.geometry.clone()),
            None => Ok(cloud::load(&self.path, files.format, files.units)?.geometry),
        }
    }

    /// The points (a mesh's vertices with their attributes), as [`cloud::load_cloud`].
    pub fn load_cloud(&self, files: FileInput) -> anyhow::Result<PointCloud> {
        match self.held_cloud() {
            Some(c) => Ok(c.clone()),
            None => cloud::load_cloud(&self.path, files.format, files.units),
        }
    }
}

//! File-level loading and writing: format by extension, unit scaling to millimetres, and
//! errors that name the file.
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::ply::{write_ply_bytes, PlyPrecision};
use super::types::{Aabb, Geometry, PointCloud};

/// Geometry file formats the readers understand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Stanford PLY (ascii or binary).
    Ply,
    /// STL (binary or ascii).
    Stl,
    /// Wavefront OBJ.
    Obj,
    /// Object File Format.
    Off,
    /// Point Cloud Library PCD.
    Pcd,
    /// Delimited text: .xyz, .csv, .txt, .asc, .pts.
    Xyz,
}

impl Format {
    /// The format a file name implies.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "ply" => Format::Ply,
            "stl" => Format::Stl,
            "obj" => Format::Obj,
            "off" => Format::Off,
            "pcd" => Format::Pcd,
            "xyz" | "csv" | "txt" | "asc" | "pts" => Format::Xyz,
            _ => return None,
        })
    }
}

/// Length unit of a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Units {
    /// Metres (scaled by 1000 on reading).
    M,
    /// Millimetres (the internal unit).
    Mm,
}

impl Units {
    /// Factor from this unit to millimetres.
    pub fn to_mm(self) -> f64 {
        match self {
            Units::M => 1000.0,
            Units::Mm => 1.0,
        }
    }
}

/// A loaded file, in millimetres.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The geometry, scaled to millimetres.
    pub geometry: Geometry,
    /// The unit the file was read in.
    pub units: Units,
    /// True when the unit was not stated and millimetres were assumed (box of 1 unit or more).
    pub units_assumed: bool,
}

/// Reads a whole file, with one-line errors for missing files, directories and empty files.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let meta = std::fs::metadata(path).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    if meta.is_dir() {
        bail!("{}: is a directory, not a file", path.display());
    }
    let bytes = std::fs::read(path).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    if bytes.is_empty() {
        bail!("{}: byte 0: empty file", path.display());
    }
    Ok(bytes)
}

/// Loads a geometry file into millimetres. `format` overrides the extension. Without `units`,
/// a file whose bounding box is under 1 unit across is refused with a hint (it looks like
/// metres); otherwise millimetres are assumed and `units_assumed` says so.
pub fn load(path: &Path, format: Option<Format>, units: Option<Units>) -> Result<Loaded> {
    let spinner = crate::progress::spinner(&format!("reading {}", path.display()));
    let bytes = read_bytes(path)?;
    let format = match format.or_else(|| Format::from_path(path)) {
        Some(f) => f,
        None => bail!(
            "{}: unknown file extension; state the format with --format",
            path.display()
        ),
    };
    let parsed = super::parse(&bytes, format);
    spinner.finish_and_clear();
    let mut geometry = parsed.map_err(|e| anyhow!("{}: {}", path.display(), e))?;
    if geometry.points().is_empty() {
        bail!("{}: file: no points", path.display());
    }
    let (units, assumed) = match units {
        Some(u) => (u, false),
        None => {
            let across = Aabb::of(geometry.points()).map_or(0.0, |b| b.extent().max());
            if across < 1.0 {
                bail!(
                    "{}: bounding box is {across:.4} units across, which looks like metres; state the unit with --units m (or --units mm)",
                    path.display()
                );
            }
            (Units::Mm, true)
        }
    };
    geometry.scale(units.to_mm());
    Ok(Loaded {
        geometry,
        units,
        units_assumed: assumed,
    })
}

/// Loads a file that must be a point cloud (a mesh's vertices are taken with its vertex
/// attributes).
pub fn load_cloud(path: &Path, format: Option<Format>, units: Option<Units>) -> Result<PointCloud> {
    Ok(match load(path, format, units)?.geometry {
        Geometry::Cloud(c) => c,
        Geometry::Mesh { attributes, .. } => attributes,
    })
}

/// Writes a cloud (and optional triangles) as binary PLY.
pub fn write_ply(
    path: &Path,
    cloud: &PointCloud,
    faces: Option<&[[u32; 3]]>,
    precision: PlyPrecision,
) -> Result<()> {
    std::fs::write(path, write_ply_bytes(cloud, faces, precision))
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// Writes a cloud as CSV: header `x,y,z[,nx,ny,nz][,field...]`, shortest round-trip numbers.
pub fn write_csv(path: &Path, cloud: &PointCloud) -> Result<()> {
    use std::fmt::Write as _;
    let mut s = String::from("x,y,z");
    if cloud.normals.is_some() {
        s += ",nx,ny,nz";
    }
    for f in &cloud.fields {
        s += ",";
        s += &f.name;
    }
    s.push('\n');
    // Rows are formatted in parallel blocks (shortest round-trip numbers are the cost) and
    // joined in order.
    const BLOCK: usize = 8192;
    let blocks: Vec<String> = (0..cloud.len().div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let mut s = String::new();
            for i in b * BLOCK..((b + 1) * BLOCK).min(cloud.len()) {
                let p = &cloud.points[i];
                let _ = write!(s, "{},{},{}", p.x, p.y, p.z);
                if let Some(n) = &cloud.normals {
                    let _ = write!(s, ",{},{},{}", n[i].x, n[i].y, n[i].z);
                }
                for f in &cloud.fields {
                    let _ = write!(s, ",{}", f.values[i]);
                }
                s.push('\n');
            }
            s
        })
        .collect();
    s.extend(blocks);
    std::fs::write(path, s).with_context(|| format!("{}: cannot write", path.display()))
}

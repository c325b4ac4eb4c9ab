//! File-level loading and writing: format by extension, unit scaling to millimetres, and
//! errors that name the file.
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::error::{ParseError, Place};
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

/// Reads a whole regular file, with one-line errors for missing files, directories, empty
/// files and anything that is not a regular file (a FIFO, a device such as `/dev/zero`, a
/// socket): those are refused from their metadata, before a byte is read. The file is opened
/// non-blocking so that opening a FIFO cannot wait for a writer, and at most the size the
/// metadata gives is read (a file that grows meanwhile is read as it was).
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let fail = |e: std::io::Error| anyhow!("{}: {}", path.display(), e);
    let mut file = open_nonblocking(path).map_err(fail)?;
    let meta = file.metadata().map_err(fail)?;
    if meta.is_dir() {
        bail!("{}: is a directory, not a file", path.display());
    }
    if !meta.is_file() {
        bail!(
            "{}: not a regular file ({}); geometry is read from regular files only",
            path.display(),
            file_kind(&meta)
        );
    }
    let size = usize::try_from(meta.len())
        .map_err(|_| anyhow!("{}: too large for this machine", path.display()))?;
    let mut bytes = Vec::with_capacity(size);
    (&mut file)
        .take(meta.len())
        .read_to_end(&mut bytes)
        .map_err(fail)?;
    if bytes.is_empty() {
        bail!("{}: byte 0: empty file", path.display());
    }
    Ok(bytes)
}

/// Opens for reading without waiting: on Unix with `O_NONBLOCK`, which returns at once for a
/// FIFO without a writer (and changes nothing for a regular file).
fn open_nonblocking(path: &Path) -> std::io::Result<std::fs::File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    options.open(path)
}

/// What a non-regular file is, for the message.
fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    let _ = meta;
    "neither a file nor a directory"
}

/// Largest coordinate magnitude accepted, mm, after units: a kilometre. The largest thing
/// polishbot measures or reaches is a workcell under a metre across, so a larger coordinate is
/// a wrong unit or a broken file; within it a coordinate keeps a resolution of 1.2e-10 mm in
/// f64, squared distances cannot overflow and grid and voxel indices stay far from integer
/// limits (coordinates near 1e300 made them saturate or panic).
pub const MAX_COORD_MM: f64 = 1e6;

/// The first point with a coordinate beyond ±[`MAX_COORD_MM`], as an error naming it.
fn check_range(points: &[nalgebra::Point3<f64>]) -> Result<(), ParseError> {
    match points
        .iter()
        .position(|p| p.coords.iter().any(|c| c.abs() > MAX_COORD_MM))
    {
        None => Ok(()),
        Some(i) => {
            let p = points[i];
            Err(ParseError::new(
                Place::Point(i),
                format!(
                    "coordinate ({:e}, {:e}, {:e}) mm is beyond ±{MAX_COORD_MM:e} mm (wrong --units or a broken file?)",
                    p.x, p.y, p.z
                ),
            ))
        }
    }
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
    check_range(geometry.points()).map_err(|e| anyhow!("{}: {}", path.display(), e))?;
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

/// Writes a cloud as CSV ([`csv_text`]).
pub fn write_csv(path: &Path, cloud: &PointCloud) -> Result<()> {
    std::fs::write(path, csv_text(cloud))
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// A cloud as CSV: header `x,y,z[,nx,ny,nz][,field...]`, shortest round-trip numbers.
pub fn csv_text(cloud: &PointCloud) -> String {
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
    s
}

//! `polishbot info FILE`: one JSON object describing a geometry file.
use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use super::common::GeometryInput;
use crate::cloud::{self, Aabb, Geometry};

/// Arguments of `info`.
#[derive(Debug, Args)]
pub struct InfoArgs {
    /// The geometry file.
    pub file: PathBuf,
    #[command(flatten)]
    /// Units and format.
    pub input: GeometryInput,
}

/// Prints points, faces, bounding box (mm) and units as one JSON line.
pub fn run(args: InfoArgs, _config: Option<&std::path::Path>) -> anyhow::Result<()> {
    let loaded = cloud::load(&args.file, args.input.format, args.input.units)?;
    let g = &loaded.geometry;
    let bbox = Aabb::of(g.points()).expect("load refuses empty files");
    let (kind, points_are) = match g {
        Geometry::Cloud(_) => ("cloud", "points"),
        Geometry::Mesh { .. } => ("mesh", "unique vertices"),
    };
    let (has_normals, fields) = match g {
        Geometry::Cloud(c) | Geometry::Mesh { attributes: c, .. } => (
            c.normals.is_some(),
            c.fields.iter().map(|f| f.name.clone()).collect::<Vec<_>>(),
        ),
    };
    let units = if loaded.units_assumed {
        "mm (assumed)".to_string()
    } else {
        format!("{:?}", loaded.units).to_lowercase()
    };
    let extent = bbox.extent();
    let out = json!({
        "file": args.file.display().to_string(),
        "kind": kind,
        "points": g.points().len(),
        "points_are": points_are,
        "faces": g.face_count(),
        "normals": has_normals,
        "fields": fields,
        "bbox_min": [bbox.min.x, bbox.min.y, bbox.min.z],
        "bbox_max": [bbox.max.x, bbox.max.y, bbox.max.z],
        "extent": [extent.x, extent.y, extent.z],
        "units": units,
        "internal_units": "mm",
    });
    println!("{out}");
    Ok(())
}

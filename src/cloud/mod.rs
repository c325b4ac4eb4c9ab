//! Point clouds and triangle meshes: types, readers, writers, units and mesh sampling.
//!
//! Everything inside is millimetres. Readers parse bytes (no I/O) and report the place of any
//! fault; [`load`] adds the file name and the unit scale.
mod columns;
mod error;
mod io;
mod obj;
mod off;
mod pcd;
mod ply;
mod sample;
mod stl;
mod text;
pub mod transform;
mod types;
mod xyz;

pub use error::{ParseError, Place};
pub use io::{
    csv_text, load, load_cloud, read_bytes, write_csv, write_ply, Format, Loaded, Units,
    MAX_COORD_MM,
};
pub use ply::{write_ply_bytes, PlyPrecision};
pub use sample::{sample_mesh, MeshSample};
pub use types::{Aabb, Geometry, Mesh, PointCloud, ScalarField};

/// Parses bytes as the given format (no file access): the entry point of the fuzz and property
/// tests. Coordinates are returned as stored (no unit scaling).
pub fn parse(bytes: &[u8], format: Format) -> Result<Geometry, ParseError> {
    match format {
        Format::Ply => ply::read(bytes),
        Format::Stl => stl::read(bytes),
        Format::Obj => obj::read(bytes),
        Format::Off => off::read(bytes),
        Format::Pcd => pcd::read(bytes),
        Format::Xyz => xyz::read(bytes),
    }
}

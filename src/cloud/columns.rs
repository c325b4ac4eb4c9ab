//! Maps named columns (PCD fields, CSV headers) onto positions, normals and scalar fields.
use nalgebra::{Point3, Vector3};

use super::error::{fail, ParseError, Place};
use super::types::{PointCloud, ScalarField};

/// Which column holds what.
#[derive(Debug, Clone)]
pub struct Columns {
    xyz: [usize; 3],
    normal: Option<[usize; 3]>,
    fields: Vec<(usize, String)>,
    /// Number of columns a row must have.
    pub width: usize,
}

impl Columns {
    /// Finds x/y/z and normals by (case-insensitive) name; every other column is a field.
    pub fn from_names(names: &[String], place: Place) -> Result<Columns, ParseError> {
        let find = |alts: &[&str]| {
            names
                .iter()
                .position(|n| alts.iter().any(|a| n.eq_ignore_ascii_case(a)))
        };
        let Some((xyz, normal)) = locate_xyz_normal(find) else {
            return fail(place, "columns must include x, y and z");
        };
        let fields = names
            .iter()
            .enumerate()
            .filter(|(i, _)| !is_located(xyz, normal, *i))
            .map(|(i, n)| (i, n.clone()))
            .collect();
        Ok(Columns {
            xyz,
            normal,
            fields,
            width: names.len(),
        })
    }

    /// Positional layout for unnamed columns: x y z [nx ny nz] [fields...]; 4 or 5 columns are
    /// x y z plus fields.
    pub fn positional(width: usize, place: Place) -> Result<Columns, ParseError> {
        if width < 3 {
            return fail(
                place,
                format!("a row needs at least 3 numbers, found {width}"),
            );
        }
        let names: Vec<String> = (0..width)
            .map(|i| match (i, width >= 6) {
                (0, _) => "x".into(),
                (1, _) => "y".into(),
                (2, _) => "z".into(),
                (3, true) => "nx".into(),
                (4, true) => "ny".into(),
                (5, true) => "nz".into(),
                _ => format!("scalar{i}"),
            })
            .collect();
        Columns::from_names(&names, place)
    }

    /// An empty cloud with this layout's fields.
    pub fn empty_cloud(&self, capacity: usize) -> PointCloud {
        PointCloud {
            points: Vec::with_capacity(capacity),
            normals: self.normal.map(|_| Vec::with_capacity(capacity)),
            fields: self
                .fields
                .iter()
                .map(|(_, n)| ScalarField {
                    name: n.clone(),
                    values: Vec::new(),
                })
                .collect(),
        }
    }

    /// Appends one row of `width` values.
    pub fn push(&self, cloud: &mut PointCloud, row: &[f64]) {
        let [x, y, z] = self.xyz;
        cloud.points.push(Point3::new(row[x], row[y], row[z]));
        if let (Some([a, b, c]), Some(n)) = (self.normal, cloud.normals.as_mut()) {
            n.push(Vector3::new(row[a], row[b], row[c]));
        }
        for (f, (i, _)) in cloud.fields.iter_mut().zip(&self.fields) {
            f.values.push(row[*i]);
        }
    }
}

/// Finds the x, y, z columns and, when all three are present, the normal columns (nx/normal_x,
/// ...). `find` returns the index of the first column with one of the given names.
pub(super) fn locate_xyz_normal(
    find: impl Fn(&[&str]) -> Option<usize>,
) -> Option<([usize; 3], Option<[usize; 3]>)> {
    let (Some(x), Some(y), Some(z)) = (find(&["x"]), find(&["y"]), find(&["z"])) else {
        return None;
    };
    let normal = match (
        find(&["nx", "normal_x"]),
        find(&["ny", "normal_y"]),
        find(&["nz", "normal_z"]),
    ) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    Some(([x, y, z], normal))
}

/// Whether column `i` is one that [`locate_xyz_normal`] assigned to the position or the normal.
pub(super) fn is_located(xyz: [usize; 3], normal: Option<[usize; 3]>, i: usize) -> bool {
    xyz.contains(&i) || normal.is_some_and(|n| n.contains(&i))
}

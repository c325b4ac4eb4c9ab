//! The geometry types every stage shares.
use nalgebra::{Point3, Vector3};

use super::error::{fail, ParseError, Place};

/// A named per-point scalar (e.g. intensity, distance).
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarField {
    /// Property name as written to files.
    pub name: String,
    /// One value per point.
    pub values: Vec<f64>,
}

/// Points with optional unit normals and optional named scalar fields (millimetres).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// Positions.
    pub points: Vec<Point3<f64>>,
    /// Unit normals, one per point, when known.
    pub normals: Option<Vec<Vector3<f64>>>,
    /// Extra per-point scalars.
    pub fields: Vec<ScalarField>,
}

/// A triangle mesh (polygons are fan-triangulated on reading).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as vertex indices, counter-clockwise seen from outside.
    pub faces: Vec<[u32; 3]>,
}

/// What a reader returns: a mesh when the file has faces, else a cloud.
#[derive(Debug, Clone, PartialEq)]
pub enum Geometry {
    /// Points without faces.
    Cloud(PointCloud),
    /// A triangle mesh; `normals` are vertex normals from the file, if any.
    Mesh {
        /// The mesh.
        mesh: Mesh,
        /// The file's vertex attributes (normals, scalar fields); points equal `mesh.vertices`.
        attributes: PointCloud,
    },
}

/// Axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Point3<f64>,
    /// Largest corner.
    pub max: Point3<f64>,
}

impl Aabb {
    /// The box around `points` (None when empty).
    pub fn of(points: &[Point3<f64>]) -> Option<Aabb> {
        let first = *points.first()?;
        let (mut min, mut max) = (first, first);
        for p in points {
            for i in 0..3 {
                min[i] = min[i].min(p[i]);
                max[i] = max[i].max(p[i]);
            }
        }
        Some(Aabb { min, max })
    }

    /// Edge lengths.
    pub fn extent(&self) -> Vector3<f64> {
        self.max - self.min
    }

    /// Centre point.
    pub fn centre(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }
}

impl PointCloud {
    /// A cloud of bare points.
    pub fn from_points(points: Vec<Point3<f64>>) -> Self {
        PointCloud {
            points,
            normals: None,
            fields: Vec::new(),
        }
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The scalar field called `name`, if present.
    pub fn field(&self, name: &str) -> Option<&[f64]> {
        self.fields
            .iter()
            .find(|f| f.name == name)
            .map(|f| f.values.as_slice())
    }

    /// Adds or replaces a scalar field.
    pub fn set_field(&mut self, name: &str, values: Vec<f64>) {
        debug_assert_eq!(values.len(), self.points.len());
        match self.fields.iter_mut().find(|f| f.name == name) {
            Some(f) => f.values = values,
            None => self.fields.push(ScalarField {
                name: name.to_string(),
                values,
            }),
        }
    }

    /// A new cloud holding the points at `indices`, with their normals and fields.
    pub fn select(&self, indices: &[usize]) -> PointCloud {
        PointCloud {
            points: indices.iter().map(|&i| self.points[i]).collect(),
            normals: self
                .normals
                .as_ref()
                .map(|n| indices.iter().map(|&i| n[i]).collect()),
            fields: self
                .fields
                .iter()
                .map(|f| ScalarField {
                    name: f.name.clone(),
                    values: indices.iter().map(|&i| f.values[i]).collect(),
                })
                .collect(),
        }
    }

    /// Multiplies positions by `factor` (unit change); normals are unchanged.
    pub fn scale(&mut self, factor: f64) {
        if factor != 1.0 {
            self.points.iter_mut().for_each(|p| *p *= factor);
        }
    }

    /// Applies a rigid transform to points and normals.
    pub fn transform(&mut self, a_from_b: &nalgebra::Isometry3<f64>) {
        self.points.iter_mut().for_each(|p| *p = a_from_b * *p);
        if let Some(normals) = &mut self.normals {
            normals.iter_mut().for_each(|n| *n = a_from_b.rotation * *n);
        }
    }

    /// Rejects NaN or infinite coordinates and normals, naming the first bad point.
    pub fn check_finite(&self) -> Result<(), ParseError> {
        if let Some(i) = self
            .points
            .iter()
            .position(|p| !p.coords.iter().all(|c| c.is_finite()))
        {
            return fail(Place::Point(i), "coordinate is NaN or infinite");
        }
        if let Some(normals) = &self.normals {
            if let Some(i) = normals
                .iter()
                .position(|n| !n.iter().all(|c| c.is_finite()))
            {
                return fail(Place::Point(i), "normal is NaN or infinite");
            }
        }
        Ok(())
    }
}

impl Mesh {
    /// Rejects faces whose indices are out of range, naming the first bad face.
    pub fn check_faces(&self) -> Result<(), ParseError> {
        let n = self.vertices.len();
        for (i, f) in self.faces.iter().enumerate() {
            if let Some(&bad) = f.iter().find(|&&v| v as usize >= n) {
                return fail(
                    Place::Face(i),
                    format!("vertex index {bad} out of range (mesh has {n} vertices)"),
                );
            }
        }
        Ok(())
    }

    /// Unit normal and area of face `i` (zero normal for a degenerate face).
    pub fn face_normal_area(&self, i: usize) -> (Vector3<f64>, f64) {
        let [a, b, c] = self.faces[i].map(|v| self.vertices[v as usize]);
        let cross = (b - a).cross(&(c - a));
        let norm = cross.norm();
        if norm > 0.0 {
            (cross / norm, 0.5 * norm)
        } else {
            (Vector3::zeros(), 0.0)
        }
    }

    /// Flips every face when the mesh's signed volume is negative (inward winding), so that
    /// facet normals point outward on a closed mesh.
    pub fn orient_outward(&mut self) {
        let volume: f64 = self
            .faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| self.vertices[v as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum();
        if volume < 0.0 {
            self.faces.iter_mut().for_each(|f| f.swap(1, 2));
        }
    }

    /// Multiplies positions by `factor`.
    pub fn scale(&mut self, factor: f64) {
        if factor != 1.0 {
            self.vertices.iter_mut().for_each(|p| *p *= factor);
        }
    }
}

impl Geometry {
    /// Vertex or point positions.
    pub fn points(&self) -> &[Point3<f64>] {
        match self {
            Geometry::Cloud(c) => &c.points,
            Geometry::Mesh { mesh, .. } => &mesh.vertices,
        }
    }

    /// Number of faces (0 for a cloud).
    pub fn face_count(&self) -> usize {
        match self {
            Geometry::Cloud(_) => 0,
            Geometry::Mesh { mesh, .. } => mesh.faces.len(),
        }
    }

    /// Checks finiteness of all coordinates and face index ranges.
    pub fn validate(&self) -> Result<(), ParseError> {
        match self {
            Geometry::Cloud(c) => c.check_finite(),
            Geometry::Mesh { mesh, attributes } => {
                attributes.check_finite()?;
                mesh.check_faces()
            }
        }
    }

    /// Multiplies every position by `factor`.
    pub fn scale(&mut self, factor: f64) {
        match self {
            Geometry::Cloud(c) => c.scale(factor),
            Geometry::Mesh { mesh, attributes } => {
                mesh.scale(factor);
                attributes.scale(factor);
            }
        }
    }
}

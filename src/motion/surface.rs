//! The reference surface as the inspection's core points with normals: projection of a point
//! onto it (local plane of the nearest core points), for raster points between core points.
use nalgebra::{Point3, Vector3};

use crate::repair::SurfacePoint;
use crate::spatial::Neighbours;

/// Core points and their k-d tree (reference frame, mm).
pub struct Surface<'a> {
    points: &'a [SurfacePoint],
    index: Neighbours,
    /// Neighbours averaged per projection.
    k: usize,
}

impl<'a> Surface<'a> {
    /// Indexes `points`.
    pub fn new(points: &'a [SurfacePoint]) -> Self {
        let pos: Vec<Point3<f64>> = points.iter().map(|p| p.position).collect();
        Surface {
            points,
            index: Neighbours::new(&pos),
            k: 8,
        }
    }

    /// `q` projected onto the surface: twice, onto the plane through the inverse-distance
    /// weighted mean of its `k` nearest core points with their weighted mean normal. Returns
    /// the surface point and its unit outward normal.
    pub fn project(&self, q: &Point3<f64>) -> (Point3<f64>, Vector3<f64>) {
        let mut p = *q;
        let mut normal = Vector3::z();
        for _ in 0..2 {
            let nb = self.index.knn(&p, self.k);
            let mut c = Vector3::zeros();
            let mut n = Vector3::zeros();
            let mut wsum = 0.0;
            for b in &nb {
                let w = 1.0 / (b.dist2.sqrt() + 1e-6);
                let sp = &self.points[b.index];
                c += sp.position.coords * w;
                n += sp.normal * w;
                wsum += w;
            }
            if wsum == 0.0 || n.norm() < 1e-12 {
                break;
            }
            let c = Point3::from(c / wsum);
            normal = n.normalize();
            p = q - normal * (q - c).dot(&normal);
        }
        (p, normal)
    }

    /// Distance (mm) from `q` to the nearest core point.
    pub fn gap(&self, q: &Point3<f64>) -> f64 {
        self.index
            .nearest(q)
            .map_or(f64::INFINITY, |n| n.dist2.sqrt())
    }
}

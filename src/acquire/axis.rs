//! Turntable axis and centre from the refined view poses.
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Point3, Unit, Vector3};
use serde::{Deserialize, Serialize};

/// The table axis that best explains the view poses.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AxisEstimate {
    /// Unit axis direction (first view's frame), signed like the nominal axis.
    pub axis: [f64; 3],
    /// The point of the axis closest to the nominal centre's foot (least squares), mm.
    pub centre: [f64; 3],
    /// Largest angle between one view's own rotation axis and the estimate, degrees.
    pub axis_spread_deg: f64,
    /// RMS of the pose translations not explained by a rotation about the axis, mm.
    pub residual_mm: f64,
}

impl AxisEstimate {
    /// Table angle (degrees) of a view-to-first `pose`, taken as the rotation by -angle about
    /// the axis, in the turn closest to `near` degrees.
    pub fn angle_of(&self, pose: &Isometry3<f64>, near: f64) -> f64 {
        let a = -pose
            .rotation
            .scaled_axis()
            .dot(&Vector3::from(self.axis))
            .to_degrees();
        a + 360.0 * ((near - a) / 360.0).round()
    }
}

/// Estimates the axis and centre from view-to-first `poses` (rotations of less than 1 degree
/// say nothing about the axis and are left out); None when no pose turns enough.
pub fn estimate_axis(
    poses: &[Isometry3<f64>],
    nominal_axis: &Unit<Vector3<f64>>,
    nominal_centre: &Point3<f64>,
) -> Option<AxisEstimate> {
    let turning: Vec<&Isometry3<f64>> = poses
        .iter()
        .filter(|p| p.rotation.angle() > 1f64.to_radians())
        .collect();
    if turning.is_empty() {
        return None;
    }
    let dirs: Vec<Vector3<f64>> = turning
        .iter()
        .map(|p| {
            let u = p.rotation.axis().map_or(Vector3::z(), |a| a.into_inner());
            if u.dot(nominal_axis) < 0.0 {
                -u
            } else {
                u
            }
        })
        .collect();
    let sum: Vector3<f64> = turning
        .iter()
        .zip(&dirs)
        .map(|(p, u)| u * p.rotation.angle().sin().abs().max(1e-3))
        .sum();
    let axis = sum.normalize();
    let spread = dirs
        .iter()
        .map(|u| u.dot(&axis).clamp(-1.0, 1.0).acos().to_degrees())
        .fold(0.0, f64::max);
    // (I - R) c = t for every pose, plus axis . c = axis . nominal centre.
    let n = turning.len();
    let mut a = DMatrix::zeros(3 * n + 1, 3);
    let mut b = DVector::zeros(3 * n + 1);
    for (k, p) in turning.iter().enumerate() {
        let m = Matrix3::identity() - p.rotation.to_rotation_matrix().into_inner();
        a.slice_mut((3 * k, 0), (3, 3)).copy_from(&m);
        b.rows_mut(3 * k, 3).copy_from(&p.translation.vector);
    }
    a.row_mut(3 * n).copy_from(&axis.transpose());
    b[3 * n] = axis.dot(&nominal_centre.coords);
    let svd = a.clone().svd(true, true);
    let c = svd.solve(&b, 1e-12).ok()?;
    let r = &a * &c - &b;
    let residual = (r.rows(0, 3 * n).norm_squared() / n as f64).sqrt();
    Some(AxisEstimate {
        axis: axis.into(),
        centre: [c[0], c[1], c[2]],
        axis_spread_deg: spread,
        residual_mm: residual,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acquire::table_rotation;

    #[test]
    fn recovers_axis_and_centre_of_exact_rotations() {
        let axis = Unit::new_normalize(Vector3::new(0.1, -0.2, 1.0));
        let centre = Point3::new(4.0, -3.0, 2.0);
        let poses: Vec<_> = (0..6)
            .map(|i| table_rotation(&axis, &centre, -(i as f64) * 60.0 - 1.3))
            .collect();
        let est = estimate_axis(
            &poses,
            &Unit::new_normalize(Vector3::z()),
            &Point3::origin(),
        )
        .expect("estimate");
        assert!((Vector3::from(est.axis) - axis.into_inner()).norm() < 1e-9);
        // The estimated centre lies on the true axis.
        let d = Vector3::from(est.centre) - centre.coords;
        assert!((d - axis.into_inner() * d.dot(&axis)).norm() < 1e-9, "{d}");
        assert!((est.angle_of(&poses[4], 240.0) - 241.3).abs() < 1e-9);
        assert!(est.residual_mm < 1e-9);
    }
}

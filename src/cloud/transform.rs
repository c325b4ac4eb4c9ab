//! Rigid transforms as the 4x4 row-major rows the file contracts use.
use anyhow::{bail, Result};
use nalgebra::{Isometry3, Matrix3, Matrix4, Rotation3, Translation3, UnitQuaternion};

/// The 4x4 homogeneous matrix of `iso` as rows.
pub fn isometry_to_rows(iso: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m: Matrix4<f64> = iso.to_homogeneous();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// A rigid transform from 4x4 rows; refuses matrices that are not rigid (rotation part not
/// orthonormal within 1e-6, determinant not +1, last row not 0 0 0 1).
pub fn isometry_from_rows(rows: &[[f64; 4]; 4]) -> Result<Isometry3<f64>> {
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        bail!("transform has NaN or infinite entries");
    }
    if rows[3] != [0.0, 0.0, 0.0, 1.0] {
        bail!("transform's last row must be 0 0 0 1, found {:?}", rows[3]);
    }
    let r = Matrix3::from_fn(|i, j| rows[i][j]);
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    if err > 1e-6 || r.determinant() < 0.0 {
        bail!("transform's rotation part is not a rotation (orthonormality error {err:.2e}, det {:.6})", r.determinant());
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Isometry3::from_parts(
        Translation3::new(rows[0][3], rows[1][3], rows[2][3]),
        rot,
    ))
}

/// Rotation angle (degrees) and translation distance between two poses: how far `a` is from `b`.
pub fn pose_difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let d = a.inverse() * b;
    (
        d.rotation.angle().to_degrees(),
        (a.translation.vector - b.translation.vector).norm(),
    )
}

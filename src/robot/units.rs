//! Millimetres and metres in one place: the arm's model (URDF, calibration files, FK, IK) is in
//! metres, the part, the inspection and the plan's lengths on the surface in millimetres.
//! [`mm`] and [`metres`] take a number, a vector, a point or a matrix (anything scaled by an
//! `f64`); each is one multiplication, so that a value converted here is bit for bit what the
//! same product written in place gives.
use std::ops::Mul;

/// Millimetres in a metre.
pub const MM_PER_M: f64 = 1e3;

/// Metres in a millimetre (`1e-3`: a product by it, not a division by [`MM_PER_M`], which
/// differs in the last bit for some values).
pub const M_PER_MM: f64 = 1e-3;

/// `metres` in millimetres (a length, a speed in m/s to mm/s, a point or a vector).
pub fn mm<T: Mul<f64, Output = T>>(metres: T) -> T {
    metres * MM_PER_M
}

/// `millimetres` in metres (a length, a speed in mm/s to m/s, a point or a vector).
pub fn metres<T: Mul<f64, Output = T>>(millimetres: T) -> T {
    millimetres * M_PER_MM
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Point3, Vector3};

    #[test]
    fn a_burr_of_three_millimetres_is_three_thousandths_of_a_metre() {
        assert_eq!(mm(0.003), 3.0);
        assert_eq!(metres(3.0), 0.003);
        assert_eq!(metres(mm(0.0015)), 0.0015);
    }

    #[test]
    fn points_and_vectors_convert_as_their_coordinates_do() {
        let p = Point3::new(0.25, -0.0625, 0.3);
        assert_eq!(mm(p), Point3::new(250.0, -62.5, 300.0));
        let v = Vector3::new(12.5, -3.3, 0.7);
        let each = Vector3::new(metres(12.5), metres(-3.3), metres(0.7));
        assert_eq!(metres(v), each);
        // the product by 1e-3, as the code it replaced wrote it (not a division by 1e3)
        assert_eq!(metres(0.7), 0.7 * 1e-3);
    }
}

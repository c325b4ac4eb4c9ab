//! Millimetres and metres in one place: the arm's model (URDF, calibration files, FK, IK) is in
//! metres, the part, the inspection and the plan's lengths on the surface in millimetres.

/// Millimetres in a metre.
pub const MM_PER_M: f64 = 1e3;

/// `metres` in millimetres.
pub fn mm(metres: f64) -> f64 {
    metres * MM_PER_M
}

/// `millimetres` in metres.
pub fn metres(millimetres: f64) -> f64 {
    millimetres / MM_PER_M
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_burr_of_three_millimetres_is_three_thousandths_of_a_metre() {
        assert_eq!(mm(0.003), 3.0);
        assert_eq!(metres(3.0), 0.003);
        assert_eq!(metres(mm(0.0015)), 0.0015);
    }
}

//! Bounds shared by the synthetic case's settings and the turntable's.

/// Most points in reference.ply, scan.ply or a turntable view (about 500 MB of points and
/// normals at once: beyond it a setting is wrong, not the case large).
pub const MAX_POINTS: usize = 10_000_000;
/// `key = value unit` outside `lo..=hi` (or not finite) as a message naming the key.
pub(super) fn outside(key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Option<String> {
    (!(v.is_finite() && (lo..=hi).contains(&v)))
        .then(|| format!("`{key}` = {v:?} {unit} is outside {lo}..={hi} {unit}"))
}

//! Bounds shared by the synthetic case's settings and the turntable's.

/// Most points in reference.ply, scan.ply or a turntable view (about 500 MB of points and
/// normals at once: beyond it a setting is wrong, not the case large).
pub const MAX_POINTS: usize = 10_000_000;
/// `key = value unit` outside `lo..=hi` (or not finite) as a message naming the key.
pub(super) fn outside(key: &str, v: f64, lo: f64, hi: f64, unit: &str) -> Option<String> {
    (!(v.is_finite() && (lo..=hi).contains(&v)))
        .then(|| format!("`{key}` = {v:?} {unit} is outside {lo}..={hi} {unit}"))
}

/// A "min,max" range setting `key = [a, b] unit` that is not `lo <= a <= b <= hi` (or not
/// finite) as a message naming the key and the range both ends must lie in.
pub(super) fn range_outside(
    key: &str,
    [a, b]: [f64; 2],
    lo: f64,
    hi: f64,
    unit: &str,
) -> Option<String> {
    let fine = a.is_finite() && b.is_finite() && lo <= a && a <= b && b <= hi;
    (!fine).then(|| {
        format!("`{key}` = [{a:?}, {b:?}] {unit}: needs min <= max, both within {lo}..={hi} {unit}")
    })
}

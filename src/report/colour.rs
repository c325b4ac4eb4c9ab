//! The diverging colour map: blue (below nominal) - near white (zero) - red (material in
//! excess), after ColorBrewer's RdBu.
use plotters::style::RGBColor;

const STOPS: [(f64, [u8; 3]); 7] = [
    (-1.0, [5, 48, 97]),
    (-0.6, [67, 147, 195]),
    (-0.25, [209, 229, 240]),
    (0.0, [247, 247, 247]),
    (0.25, [253, 219, 199]),
    (0.6, [214, 96, 77]),
    (1.0, [103, 0, 31]),
];

/// Colour of value `v` on a symmetric scale of half-width `range`; grey for NaN.
pub fn diverging(v: f64, range: f64) -> RGBColor {
    if !v.is_finite() {
        return RGBColor(180, 180, 180);
    }
    let t = (v / range).clamp(-1.0, 1.0);
    let k = STOPS
        .windows(2)
        .position(|w| t <= w[1].0)
        .unwrap_or(STOPS.len() - 2);
    let ((t0, c0), (t1, c1)) = (STOPS[k], STOPS[k + 1]);
    let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
    let mix = |i: usize| (c0[i] as f64 + (c1[i] as f64 - c0[i] as f64) * f).round() as u8;
    RGBColor(mix(0), mix(1), mix(2))
}

/// `c` darkened by Lambert shading `s` in [0, 1] (ambient floor 0.35).
pub fn shade(c: RGBColor, s: f64) -> RGBColor {
    let k = 0.35 + 0.65 * s.clamp(0.0, 1.0);
    RGBColor(
        (c.0 as f64 * k) as u8,
        (c.1 as f64 * k) as u8,
        (c.2 as f64 * k) as u8,
    )
}

//! The report's interactive 3D viewer: `viewer-data.js` beside the page holds the core points
//! as base64 typed arrays (positions quantised to 16 bits per axis over the bounding box,
//! normals to 8 bits, deviation and uncertainty as float32, region labels as int16: 19 bytes a
//! point), and the page embeds assets/viewer.js, a software point renderer on a 2D canvas (no
//! WebGL, no network). The script checks what it decoded against counts written here and says
//! so in `#viewer-check`.
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use serde_json::json;

use super::html::escape;
use super::input::ReportInput;

/// The viewer's script.
const SCRIPT: &str = include_str!("../../assets/viewer.js");
/// The viewer's data file, beside report.html.
pub const DATA_FILE: &str = "viewer-data.js";
/// Canvas size, px.
const CANVAS: (u32, u32) = (960, 640);
/// Quantisation steps of a position over the bounding box (16 bits): 1.2 µm over 80 mm, far
/// below the scan noise and the screen.
const POS_STEPS: f64 = 65_535.0;
/// Quantisation of a unit normal component (8 bits, shading only).
const NRM_STEPS: f64 = 127.0;

/// Standard base64 (RFC 4648 §4) with padding.
pub fn base64(data: &[u8]) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(data.len().div_ceil(3) * 4);
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            chunk.get(1).copied().unwrap_or(0),
            chunk.get(2).copied().unwrap_or(0),
        ];
        let v = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ABC[(v >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Writes `dir/viewer-data.js` and returns the page's viewer section (canvas, controls,
/// self-check element, the script).
pub fn write(dir: &Path, input: &ReportInput, range: f64) -> Result<String> {
    let n = input.points.len();
    let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
    for p in input.points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if n == 0 {
        (lo, hi) = ([0.0; 3], [0.0; 3]);
    }
    let step: Vec<f64> = (0..3)
        .map(|k| (hi[k] - lo[k]).max(1e-9) / POS_STEPS)
        .collect();
    let mut pos = Vec::with_capacity(6 * n);
    let mut nrm = Vec::with_capacity(3 * n);
    for (p, q) in input.points.iter().zip(input.normals) {
        for k in 0..3 {
            let s = ((p[k] - lo[k]) / step[k]).round().clamp(0.0, POS_STEPS) as u16;
            pos.extend_from_slice(&s.to_le_bytes());
            nrm.push(((q[k] * NRM_STEPS).round().clamp(-NRM_STEPS, NRM_STEPS) as i8) as u8);
        }
    }
    let dev: Vec<f32> = input.distances.iter().map(|&d| d as f32).collect();
    let unc: Vec<f32> = (0..n)
        .map(|i| input.uncertainties.get(i).map_or(f32::NAN, |&u| u as f32))
        .collect();
    let lab: Vec<i16> = (0..n)
        .map(|i| {
            input
                .labels
                .get(i)
                .map_or(-1, |&l| l.clamp(-1, i16::MAX as i64) as i16)
        })
        .collect();
    let le = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let lab_bytes: Vec<u8> = lab.iter().flat_map(|x| x.to_le_bytes()).collect();
    let max_abs = dev
        .iter()
        .filter(|d| d.is_finite())
        .fold(0.0f32, |m, d| m.max(d.abs()));
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(1e-9, f64::max);
    let regions: Vec<_> = input
        .regions
        .iter()
        .map(|r| {
            let n = [r.normal.x, r.normal.y, r.normal.z];
            json!({"id": r.id, "centroid": r.centroid, "normal": n})
        })
        .collect();
    let meta = json!({
        "n": n,
        "origin": lo,
        "step": step,
        "centre": (0..3).map(|k| (lo[k] + hi[k]) / 2.0).collect::<Vec<_>>(),
        "extent": extent,
        "spacing": extent / (n.max(1) as f64 / 2.0).sqrt(),
        "range": range,
        "tolerance": input.tolerance,
        "regions": regions,
        "check": {
            "nan": dev.iter().filter(|d| !d.is_finite()).count(),
            "max_abs": f64::from(max_abs),
            "labelled": lab.iter().filter(|&&l| l >= 0).count(),
        },
    });
    let mut js = format!("window.POLISHBOT_VIEWER = {meta};\n");
    for (key, data) in [
        ("pos", pos),
        ("nrm", nrm),
        ("dev", le(&dev)),
        ("unc", le(&unc)),
        ("lab", lab_bytes),
    ] {
        let _ = writeln!(js, "window.POLISHBOT_VIEWER.{key} = \"{}\";", base64(&data));
    }
    let path = dir.join(DATA_FILE);
    std::fs::write(&path, js).with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(section(input, range))
}

/// The page's viewer section.
fn section(input: &ReportInput, range: f64) -> String {
    format!(
        "<section id=\"viewer\" class=\"viewer\">\n<h2>3D viewer</h2>\n\
<p class=\"viewer-controls\">drag: rotate; shift-drag or right-drag: pan; wheel: zoom \
<button name=\"reset\" type=\"button\">reset view</button> \
<label>tolerance band ± <input name=\"tolerance\" type=\"number\" step=\"0.005\" min=\"0\" value=\"{tol}\"> mm</label> \
<label>colour range ± <input name=\"range\" type=\"number\" step=\"0.01\" min=\"0.001\" value=\"{range:.4}\"> mm</label> \
<span class=\"viewer-band\"></span></p>\n\
<canvas width=\"{w}\" height=\"{h}\"></canvas>\n\
<p class=\"viewer-info\">hover a point to read it</p>\n\
<p id=\"viewer-check\" data-ok=\"pending\">viewer self-check did not run (scripts off?)</p>\n\
<p class=\"viewer-legend\">pale green: within the band; blue below nominal, red material in \
excess; grey: no value. {title}</p>\n\
<script src=\"{DATA_FILE}\"></script>\n<script>\n{SCRIPT}</script>\n</section>\n",
        tol = input.tolerance,
        w = CANVAS.0,
        h = CANVAS.1,
        title = escape(&input.title),
    )
}

#[cfg(test)]
mod tests {
    use super::base64;

    #[test]
    fn base64_matches_rfc_4648_test_vectors() {
        // RFC 4648 §10.
        for (plain, coded) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(plain.as_bytes()), coded);
        }
    }
}

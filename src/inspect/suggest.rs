//! Suggested views: from the coverage map, what would measure the unmeasured part of the area
//! to inspect on a turntable cell with a fixed scanner: which table angles in the first scan's
//! setup, and how much of it only a second setup (the part turned over) can show.
use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use crate::compare::{self, Deviations};

/// The cell the suggestion is for, in the first scan's frame (a turntable merge's: the first
/// view's, the table at angle 0).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SuggestConfig {
    /// Table axis (default +z, as `synth --views` and a merge with `--axis 0,0,1`).
    pub table_axis: [f64; 3],
    /// Direction from the part towards the scanner (default (0, -cos 35°, sin 35°): the
    /// scanner 35 degrees above the table, as the held-out cell of issue 53).
    pub scanner_direction: [f64; 3],
    /// Largest angle between a surface normal and the scanner direction at which the scanner
    /// measures the surface, degrees (default 80, synth's visibility test).
    pub max_incidence_deg: f64,
    /// Width of a suggested table-angle bin, degrees (default 30: 12 views a turn).
    pub step_deg: f64,
}

impl Default for SuggestConfig {
    fn default() -> Self {
        let e = 35f64.to_radians();
        SuggestConfig {
            table_axis: [0.0, 0.0, 1.0],
            scanner_direction: [0.0, -e.cos(), e.sin()],
            max_incidence_deg: 80.0,
            step_deg: 30.0,
        }
    }
}

/// What would measure the rest.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Suggestion {
    /// Unmeasured share of the area to inspect.
    pub unmeasured: f64,
    /// Table angles (bin centres, degrees, the first scan's table angle 0) at which this setup
    /// faces unmeasured surface, with the share of the area to inspect each faces; surface
    /// that faces the scanner at an angle already scanned was hidden by the part itself.
    pub table_angles: Vec<(f64, f64)>,
    /// Share of the area to inspect that this setup cannot face at any table angle: a
    /// second setup with the part turned over (or tilted) is needed.
    pub other_setup: f64,
}

/// The suggestion for `dev` (rows in the area where `in_area` holds, all without it), the
/// first scan's pose `scan_to_reference`.
pub fn suggest(
    dev: &Deviations,
    in_area: Option<&[bool]>,
    scan_to_reference: &Isometry3<f64>,
    cfg: &SuggestConfig,
) -> Suggestion {
    let axis = Vector3::from(cfg.table_axis).normalize();
    let towards = Vector3::from(cfg.scanner_direction).normalize();
    let horizontal = |v: &Vector3<f64>| v - axis * v.dot(&axis);
    let scanner_h = horizontal(&towards);
    let elevation = towards.dot(&axis).clamp(-1.0, 1.0).asin();
    let share = compare::area_shares(&dev.points);
    let inside = |i: usize| in_area.is_none_or(|a| a[i]);
    let total: f64 = (0..share.len())
        .filter(|&i| inside(i))
        .map(|i| share[i])
        .sum();
    let bins = (360.0 / cfg.step_deg).round().max(1.0) as usize;
    let mut by_angle = vec![0.0; bins];
    let mut out = Suggestion::default();
    let to_scan = scan_to_reference.rotation.inverse();
    for i in (0..share.len()).filter(|&i| inside(i) && !dev.values[i].distance.is_finite()) {
        let a = share[i] / total.max(f64::MIN_POSITIVE);
        out.unmeasured += a;
        let n = to_scan * dev.normals[i];
        let tilt = n.dot(&axis).clamp(-1.0, 1.0).asin();
        if (tilt - elevation).abs().to_degrees() > cfg.max_incidence_deg {
            out.other_setup += a;
            continue;
        }
        // The table angle that turns the normal's horizontal part onto the scanner's.
        let nh = horizontal(&n);
        let turn = nh.cross(&scanner_h).dot(&axis).atan2(nh.dot(&scanner_h));
        let deg = turn.to_degrees().rem_euclid(360.0);
        by_angle[((deg / cfg.step_deg).round() as usize) % bins] += a;
    }
    out.table_angles = by_angle
        .iter()
        .enumerate()
        .filter(|(_, a)| **a >= MIN_SUGGESTED_SHARE)
        .map(|(k, a)| (k as f64 * cfg.step_deg, *a))
        .collect();
    out
}

/// A table angle is suggested when it faces at least this share of the area to inspect (0.5
/// %: a tenth of the 5 % a verdict may leave unmeasured).
const MIN_SUGGESTED_SHARE: f64 = 0.005;

//! Suggested views: from the coverage map, what would measure the unmeasured part of the area
//! to inspect on a turntable cell with a fixed scanner: which table angles in the first scan's
//! setup, and how much of it only a second setup (the part turned over) can show.
use nalgebra::{Isometry3, Point3, Vector3};
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
    let unmeasured: Vec<bool> = (0..dev.values.len())
        .map(|i| !dev.values[i].distance.is_finite())
        .collect();
    let surface = (&dev.points[..], &dev.normals[..]);
    views_for(
        surface,
        in_area,
        &unmeasured,
        scan_to_reference,
        cfg,
        MIN_SUGGESTED_SHARE,
    )
}

/// The views that would show the core points of `surface` (points and outward unit normals,
/// reference frame) where `wanted` holds (shares of the area where `in_area` holds, all
/// without it; `Suggestion::unmeasured` is then their share): the table angles of this setup that
/// face them, and the share no table angle faces; a table angle is listed when it faces at least
/// `min_share` of the area. [`suggest`] asks it for the unmeasured points; the loop's rescan for
/// the points a plan ground ([`rescan_setups`]).
pub fn views_for(
    (points, normals): (&[Point3<f64>], &[Vector3<f64>]),
    in_area: Option<&[bool]>,
    wanted: &[bool],
    scan_to_reference: &Isometry3<f64>,
    cfg: &SuggestConfig,
    min_share: f64,
) -> Suggestion {
    let axis = Vector3::from(cfg.table_axis).normalize();
    let towards = Vector3::from(cfg.scanner_direction).normalize();
    let horizontal = |v: &Vector3<f64>| v - axis * v.dot(&axis);
    let scanner_h = horizontal(&towards);
    let elevation = towards.dot(&axis).clamp(-1.0, 1.0).asin();
    let share = compare::area_shares(points);
    let inside = |i: usize| in_area.is_none_or(|a| a[i]);
    let total: f64 = (0..share.len())
        .filter(|&i| inside(i))
        .map(|i| share[i])
        .sum();
    let bins = (360.0 / cfg.step_deg).round().max(1.0) as usize;
    let mut by_angle = vec![0.0; bins];
    let mut out = Suggestion::default();
    let to_scan = scan_to_reference.rotation.inverse();
    for i in (0..share.len()).filter(|&i| inside(i) && wanted[i]) {
        let a = share[i] / total.max(f64::MIN_POSITIVE);
        out.unmeasured += a;
        let n = to_scan * normals[i];
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
        .filter(|(_, a)| **a > 0.0 && **a >= min_share)
        .map(|(k, a)| (k as f64 * cfg.step_deg, *a))
        .collect();
    out
}

/// A setup a rescan should scan: the table angles in it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RescanSetup {
    /// Which setup: 0 the first scan's (the part as it sits), 1 the part turned over.
    pub setup: usize,
    /// Table angles to scan in it, degrees (the first scan's table angle 0); empty for the
    /// turned-over setup: a full turn, its angles are not known from this setup's scan.
    pub table_angles: Vec<f64>,
    /// Share of the wanted area this setup would show (0..1).
    pub share: f64,
}

/// The setups (and table angles) a rescan must scan to see the points of `surface` (as
/// [`views_for`]) where `wanted` holds (the area a plan ground, or the unmeasured area): the first
/// scan's setup at the table angles facing at least [`RESCAN_MIN_SHARE`] of the wanted area, and
/// the part turned over when at least that share faces no table angle of it. Empty when nothing is
/// wanted.
pub fn rescan_setups(
    surface: (&[Point3<f64>], &[Vector3<f64>]),
    in_area: Option<&[bool]>,
    wanted: &[bool],
    scan_to_reference: &Isometry3<f64>,
    cfg: &SuggestConfig,
) -> Vec<RescanSetup> {
    let all = views_for(surface, in_area, wanted, scan_to_reference, cfg, 0.0);
    let wanted_share = all.unmeasured.max(f64::MIN_POSITIVE);
    let least = RESCAN_MIN_SHARE * all.unmeasured;
    let angles: Vec<(f64, f64)> = (all.table_angles.into_iter())
        .filter(|(_, a)| *a >= least)
        .collect();
    let mut out = Vec::new();
    if !angles.is_empty() {
        out.push(RescanSetup {
            setup: 0,
            table_angles: angles.iter().map(|(a, _)| *a).collect(),
            share: angles.iter().map(|(_, a)| a).sum::<f64>() / wanted_share,
        });
    }
    if all.other_setup > 0.0 && all.other_setup >= least {
        out.push(RescanSetup {
            setup: 1,
            table_angles: Vec::new(),
            share: all.other_setup / wanted_share,
        });
    }
    out
}

/// A table angle is suggested when it faces at least this share of the area to inspect (0.5
/// %: a tenth of the 5 % a verdict may leave unmeasured).
const MIN_SUGGESTED_SHARE: f64 = 0.005;

/// A rescan scans a table angle (or turns the part over) when it shows at least this share of
/// the wanted area (2 %: a ground region's rim seen at grazing incidence from a further angle
/// does not earn a view of its own).
pub const RESCAN_MIN_SHARE: f64 = 0.02;

/// The rescan in words, for the loop's prompt: "setup 1 (as the part sits) at table angles
/// 0, 30 deg; setup 2 (the part turned over), a full turn".
pub fn describe_rescan(setups: &[RescanSetup]) -> String {
    if setups.is_empty() {
        return "nothing to rescan".to_string();
    }
    let words: Vec<String> = setups
        .iter()
        .map(|s| match s.setup {
            0 => {
                let angles: Vec<String> =
                    s.table_angles.iter().map(|a| format!("{a:.0}")).collect();
                format!(
                    "setup 1 (as the part sits) at table angles {} deg ({:.0} % of it)",
                    angles.join(", "),
                    100.0 * s.share
                )
            }
            _ => format!(
                "setup 2 (the part turned over), a full turn ({:.0} % of it)",
                100.0 * s.share
            ),
        })
        .collect();
    words.join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three 10 × 10 mm patches (1 mm grid): facing -y (the scanner's side at table angle 0),
    /// +x (a quarter turn away: table angle 270) and -z (down: no table angle; turned over).
    fn patches() -> (Vec<Point3<f64>>, Vec<Vector3<f64>>) {
        let mut points = Vec::new();
        let mut normals = Vec::new();
        for (k, n) in [-Vector3::y(), Vector3::x(), -Vector3::z()]
            .iter()
            .enumerate()
        {
            let (u, v) = (n.cross(&Vector3::new(0.3, 0.5, 0.7)).normalize(), n);
            let w = v.cross(&u);
            for i in 0..100 {
                let (a, b) = ((i % 10) as f64, (i / 10) as f64);
                points.push(Point3::from(
                    n * 20.0 + u * a + w * b + Vector3::x() * k as f64 * 100.0,
                ));
                normals.push(*n);
            }
        }
        (points, normals)
    }

    #[test]
    fn rescan_scans_the_table_angles_facing_the_wanted_area_and_turns_the_part_for_the_rest() {
        let (points, normals) = patches();
        let surface = (&points[..], &normals[..]);
        let cfg = SuggestConfig::default();
        let pose = Isometry3::identity();
        let group =
            |g: &[usize]| -> Vec<bool> { (0..300).map(|i| g.contains(&(i / 100))).collect() };
        let sides = rescan_setups(surface, None, &group(&[0, 1]), &pose, &cfg);
        assert_eq!(sides.len(), 1, "{sides:?}");
        assert_eq!(sides[0].setup, 0);
        assert_eq!(sides[0].table_angles, vec![0.0, 270.0]);
        assert!((sides[0].share - 1.0).abs() < 1e-9, "{sides:?}");
        let below = rescan_setups(surface, None, &group(&[2]), &pose, &cfg);
        assert_eq!(below.len(), 1, "{below:?}");
        assert_eq!((below[0].setup, below[0].share), (1, 1.0));
        assert!(rescan_setups(surface, None, &group(&[]), &pose, &cfg).is_empty());
        let text = describe_rescan(&rescan_setups(surface, None, &group(&[0, 2]), &pose, &cfg));
        assert!(
            text.contains("table angles 0 deg") && text.contains("turned over"),
            "{text}"
        );
    }
}

//! Removal where the plan removed nothing, anywhere on the part (issue 50: "a grind whose
//! removal ... removed where nothing was planned stops the loop"). The registration
//! (`removal_shift`) counts unplanned removal only within its window around each region; on
//! an arm with 1 degree of backlash per joint, calibrated on itself, grind 1 of acceptance
//! case 61 cut a new pit 0.25 mm deep over 8 mm^2 beside region 0, 2.5 mm from the nearest
//! planned landing, which the window held 5 points of (under its 10), and the loop ground two
//! more times. Here every core point measured in both inspections counts: a point that lost
//! more than [`ShiftConfig::removed_mm`] where the plan, moved by the measured shifts,
//! predicted under [`ShiftConfig::planned_mm`] is a stray point when [`STRAY_NEIGHBOURS`]
//! other stray points lie within [`STRAY_RADIUS_MM`] (the noise tail of 50,000 points holds
//! isolated ones: at 0.02 mm scatter a 0.06 mm loss is 3 sigma, about 65 points a grind);
//! more stray points than [`ShiftConfig::unplanned_points`] stop the loop.
use nalgebra::Point3;

use super::removal_shift::ShiftConfig;
use crate::removal::matching::GrindPair;
use crate::spatial::Neighbours;

/// Radius within which stray points count as one patch, mm (1.0: the contact patch's radius
/// is 0.6 mm and core points lie 0.3-0.5 mm apart, so a patch ground off the plan holds
/// 10-30 core points within a millimetre of each other).
pub const STRAY_RADIUS_MM: f64 = 1.0;
/// Other stray points a stray point needs within [`STRAY_RADIUS_MM`] (3: isolated noise points
/// at 0.13 % of 50,000 lie about 8 mm apart on the part, a ground patch packs them).
pub const STRAY_NEIGHBOURS: usize = 3;

/// Removal off the plan: how many points, the deepest loss and where.
#[derive(Debug, Clone, PartialEq)]
pub struct Stray {
    /// Stray points (each with its neighbours, see the module).
    pub points: usize,
    /// Deepest measured loss among them, mm.
    pub deepest_mm: f64,
    /// Where that loss was measured, reference frame, mm.
    pub at: Point3<f64>,
}

/// The stray removal of a grind (`pair`: the inspections before and after; `predicted`: the
/// plan's removal per core point of `pair.before`, moved by the measured shifts), None when
/// the stray points are not more than `cfg.unplanned_points`.
pub fn stray(pair: &GrindPair, predicted: &[f64], cfg: &ShiftConfig) -> Option<Stray> {
    let lost: Vec<(Point3<f64>, f64)> = (0..pair.before.points.len())
        .filter(|i| predicted.get(*i).is_some_and(|p| *p < cfg.planned_mm))
        .filter_map(|i| Some((pair.before.points[i].position, pair.removal(i)?)))
        .filter(|(_, m)| m.is_finite() && *m > cfg.removed_mm)
        .collect();
    if lost.len() <= cfg.unplanned_points {
        return None;
    }
    let positions: Vec<Point3<f64>> = lost.iter().map(|(p, _)| *p).collect();
    let index = Neighbours::new(&positions);
    let packed: Vec<&(Point3<f64>, f64)> = (lost.iter())
        .filter(|(p, _)| index.within(p, STRAY_RADIUS_MM).len() > STRAY_NEIGHBOURS)
        .collect();
    let deepest = packed.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    (packed.len() > cfg.unplanned_points).then_some(Stray {
        points: packed.len(),
        deepest_mm: deepest.1,
        at: deepest.0,
    })
}

/// The loop's stop line for `s`.
pub fn describe(s: &Stray, cfg: &ShiftConfig) -> String {
    format!(
        "{} points lost more than {} mm where the plan removed nothing (deepest {:.3} mm at \
         ({:.2}, {:.2}, {:.2}) mm; limit {}): the arm ground where it was not sent; not \
         grinding again on that model",
        s.points, cfg.removed_mm, s.deepest_mm, s.at.x, s.at.y, s.at.z, cfg.unplanned_points
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::repair::{Inspection, SurfacePoint};
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// A flat part of core points 0.35 mm apart over 20 x 20 mm, conform before the grind;
    /// after it every point lost noise (0.02 mm scatter, the difference of two inspections)
    /// and the points within `patch` mm of (5, 5) lost 0.1 mm more, nothing predicted
    /// anywhere: the stray removal read.
    fn ground(patch: f64, seed: u64) -> Option<Stray> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = (20.0 / 0.35) as i32;
        let (mut before, mut after) = (Vec::new(), Vec::new());
        for i in 0..=n {
            for j in 0..=n {
                let p = Point3::new(i as f64 * 0.35 - 10.0, j as f64 * 0.35 - 10.0, 0.0);
                let point = |distance: f64| SurfacePoint {
                    position: p,
                    normal: Vector3::z(),
                    distance,
                    uncertainty: 0.01,
                    region: -1,
                };
                let off = (p - Point3::new(5.0, 5.0, 0.0)).norm() <= patch;
                let lost = if off { 0.1 } else { 0.0 } + rng.gen_range(-1.0..1.0) * 0.02 * 1.7;
                before.push(point(0.0));
                after.push(point(-lost));
            }
        }
        let predicted = vec![0.0; before.len()];
        let inspection = |points| Inspection {
            dir: std::path::PathBuf::new(),
            tolerance: Some(0.05),
            regions: Vec::new(),
            points,
            fine: Vec::new(),
        };
        let (before, after) = (inspection(before), inspection(after));
        stray(
            &GrindPair::new(&before, &after),
            &predicted,
            &ShiftConfig::default(),
        )
    }

    #[test]
    fn a_patch_ground_off_the_plan_is_found_where_it_is() {
        for seed in 0..5 {
            let s = ground(1.2, seed).expect("a 1.2 mm patch off the plan");
            assert!(s.points >= 20, "{s:?}");
            assert!(
                (s.at - Point3::new(5.0, 5.0, 0.0)).norm() <= 1.2 + 1e-9,
                "{s:?}"
            );
            assert!(s.deepest_mm > 0.1, "{s:?}");
        }
    }

    #[test]
    fn the_inspections_noise_alone_is_not_stray_removal() {
        for seed in 0..5 {
            assert_eq!(ground(0.0, 100 + seed), None);
        }
    }
}

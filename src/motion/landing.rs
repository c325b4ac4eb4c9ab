//! How far from its prediction a contact's removal may land (issue 50): the margin the rim
//! guard (`motion::dwell`, `removal::guard`) and the Monte Carlo's landing (`motion::predict`)
//! move a region's contacts within.
use super::config::PlanConfig;
use crate::removal::{self, Contact, ToolModel};

/// Landing error and reach beyond the model's patch of a grind, the floor of
/// [`landing_margin`]'s shift term on every grind, mm (1.8): the documented arm's first grinds
/// landed about 0.9 mm from their plan (0.6-0.7 mm of it on the ideal arm too: the planner's
/// removal sits 0.2-0.45 mm from the simulator's), the shift registration misreads by as much
/// (the demo's region 1: 1.50 mm read where 0.28 mm was true), and the removal reaches
/// farther than the model's patch: survey case 61 (documented arm) lost 0.033/0.024/0.013 mm
/// in grinds 1/2/3 at a rim point 1.8-2.3 mm from the nearest commanded contact, 1.2-1.7 mm
/// beyond the model's patch edge, which a 0.9 mm margin let it take to -0.067 mm. The reach
/// the loop measures from grind 2 on (`cell::removal_reach`) widens the margin but does not
/// replace the floor: grinds 2 and 3 read 0 mm on 4 of 16 where the truth reached 0.75-1.75
/// mm, and with the rim budgets held in the
/// dwell solve (`removal::guard`) and the measured reach in place of the floor, survey cases
/// 1/141/181 (documented arm, cell seed 29) ground true points to -0.061/-0.065/-0.070 mm;
/// with the floor kept, -0.033/-0.029/-0.039 mm (softened contacts not commanded in either).
pub const UNMEASURED_LANDING_MM: f64 = 1.8;

/// Share of the preload below which a contact is commanded shallow (0.75): between the
/// softened contacts' half preload (`press_depth::MIN_DEPTH_SHARE`) and the full preload;
/// such a contact takes [`SHALLOW_LANDING_MM`] as its landing margin at least.
const SHALLOW_DEPTH_SHARE: f64 = 0.75;

/// Landing margin of a contact commanded shallower than [`SHALLOW_DEPTH_SHARE`] of the
/// preload, mm (3.0): on the simulator's rescans (survey cases 1/141/161, documented arm,
/// grinds 1-3) the removal of the points whose nearest predicted landing is a half-preload
/// contact reached 1.5-3 mm from it (99th percentile 0.011-0.053 mm at 1.5-2.5 mm, 0.002-0.010
/// mm at 2.5-3 mm), where a full-preload contact's fell to 0 beyond 1.5 mm (99th percentile
/// at most 0.002 mm at 1.5-2 mm on 5 of 6 grinds); case 141 lost 0.055 mm in one grind at a
/// conform point 1.8-2.1 mm from four half-preload contacts of 0.8-3.9 s dwell (a spot
/// 0.45 mm wide, nothing within 1.5 mm of it predicted).
pub const SHALLOW_LANDING_MM: f64 = 3.0;

/// [`landing_margin`] from its terms, mm: the tip error `tip`, the error of the spindle's slide
/// `slide`, the carried removal shift's magnitude `carried` (at least
/// [`UNMEASURED_LANDING_MM`]), widened to the loop's measured `reach` when it is known, and to
/// [`SHALLOW_LANDING_MM`] for a `shallow` contact.
fn margin_of(tip: f64, slide: f64, carried: f64, reach: Option<f64>, shallow: bool) -> f64 {
    let floored = tip + slide + carried.max(UNMEASURED_LANDING_MM);
    let measured = reach.map_or(floored, |r| floored.max(r));
    match shallow {
        true => measured.max(SHALLOW_LANDING_MM),
        false => measured,
    }
}

/// How far from where each contact's removal is predicted it may land, mm: the tool-tip error
/// the Monte Carlo draws (`removal::montecarlo::tip_error`), the error of the spring-loaded
/// spindle's slide ([`slide_error`]), and the carried removal shift's magnitude (its own error
/// is of its size: the registration reads the stroke spacing's ripple), that shift term at
/// least [`UNMEASURED_LANDING_MM`] on every grind; once the loop measured how far beyond its
/// plans' footprints the removal really reached (`motion::aim::Aim::reach_mm`, read from the
/// rescans by `cell::removal_reach`) the margin is at least that reach; a contact commanded
/// shallow lands within [`SHALLOW_LANDING_MM`] ([`margin_of`]).
pub(crate) fn landing_margins(cs: &[Contact], tool: &ToolModel, config: &PlanConfig) -> Vec<f64> {
    let tip = removal::montecarlo::tip_error(tool, &config.monte_carlo).mm;
    cs.iter()
        .map(|c| landing_margin(c, tip, tool, config))
        .collect()
}

/// [`landing_margins`] of one contact `c` with the tool-tip error `tip`, mm.
fn landing_margin(c: &Contact, tip: f64, tool: &ToolModel, config: &PlanConfig) -> f64 {
    let slide = slide_error(c, tool);
    let carried = config.aim.shift_at(&c.point, &c.normal).norm();
    let shallow = c.depth_mm < SHALLOW_DEPTH_SHARE * tool.preload_mm;
    margin_of(tip, slide, carried, config.aim.reach_mm, shallow)
}

/// Share of the spring-loaded spindle's slide `preload x tan(tilt)` the landing margin holds
/// (0.75). The slide itself is modelled: the contact's centre carries it
/// (`removal::press::along_axis`) and the aim moves the raster by it (`motion::aim`). What is
/// left of it is its error: the part's excess compresses the spring further, the axis the arm
/// holds differs from the first walk's, and the documented arm's joint 1 flips its lateral
/// error with the stroke. That error is not modelled, so the share is measured. 30-run survey
/// (cell seeds 29-31, true k 1.3 x, 3 grinds, the loop's first plan uncapped), documented arm:
/// share 1.0 (the whole slide, as until 2026-12-07): no run gouged (lowest true ground point
/// -0.048 mm), true volume above tolerance left 0.40 of its start on median, halved in 26 of
/// 30; 0.75: none gouged (-0.049 mm), 0.34, halved in 27 (ideal arm: none, -0.028 mm, 0.30,
/// 29); 0.5: 1 gouged (-0.058 mm), 0.30; 0 (or the tip error's slide alone): 5-6 gouged
/// (-0.053..-0.071 mm), 0.21, halved in 30. The gouges of the narrow margins were in the
/// defects' interior as often as at the rim, where the rescans read a ground spot above its
/// truth (case 121, cell 30: 0.060 mm read, 0.020 mm true, before the grind that took it to
/// -0.050 mm).
pub const SLIDE_MARGIN_SHARE: f64 = 0.75;

/// The part of the spring-loaded spindle's slide a contact `c`'s landing margin holds, mm:
/// [`SLIDE_MARGIN_SHARE`] x `preload x tan(tilt)`; 0 for a mount that gives along the normal.
fn slide_error(c: &Contact, tool: &ToolModel) -> f64 {
    match tool.compliance_direction {
        removal::ComplianceDirection::SpindleAxis => {
            let (tilt, _) = c.tilt();
            let cos = tilt.cos.max(removal::press::MIN_AXIS_COS);
            SLIDE_MARGIN_SHARE * tool.preload_mm * tilt.sin / cos
        }
        removal::ComplianceDirection::SurfaceNormal => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A measured reach short of the floor (grinds 2 and 3 read 0 mm on 4 of 16 grinds where
    /// the truth reached 0.75-1.75 mm) leaves the margin at its floor: tip 0.12 + slide 0.2 +
    /// 1.8 mm; a longer reach widens it; a shallow contact lands within 3 mm whatever the reach
    /// read, a full one does not.
    #[test]
    fn the_margin_keeps_its_floor_on_a_short_reach_and_widens_for_a_shallow_contact() {
        let floor = 0.12 + 0.2 + UNMEASURED_LANDING_MM;
        let m = |reach, shallow| margin_of(0.12, 0.2, 0.3, reach, shallow);
        for reach in [None, Some(0.0), Some(1.2)] {
            assert!(
                (m(reach, false) - floor).abs() < 1e-12,
                "{reach:?}: {}",
                m(reach, false)
            );
            assert!((m(reach, true) - SHALLOW_LANDING_MM).abs() < 1e-12);
        }
        assert!((m(Some(2.6), false) - 2.6).abs() < 1e-12);
        assert!((m(Some(3.4), true) - 3.4).abs() < 1e-12);
        // a carried shift beyond the floor counts in full
        assert!((margin_of(0.12, 0.2, 2.0, Some(0.5), false) - 2.32).abs() < 1e-12);
    }
}

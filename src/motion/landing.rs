//! How far from its prediction a contact's removal may land (issue 50): the margin the rim
//! guard (`motion::dwell`, `removal::guard`) and the Monte Carlo's landing (`motion::predict`)
//! move a region's contacts within.
use super::config::PlanConfig;
use super::program::PlannedPass;
use crate::removal::{self, Contact, ToolModel};
use crate::robot::compliance::{Compliance, FLANK_TORQUE_NM};
use crate::robot::units::mm;
use crate::robot::{Robot, Workcell};
use nalgebra::Vector3;

/// What the landing margins read of the cell (`motion::dwell::Setup` lends its parts).
pub(crate) struct Cell<'a> {
    /// The arm, with its `[compliance]` table.
    pub robot: &'a Robot,
    /// Robot base from the reference frame.
    pub workcell: &'a Workcell,
    /// The compliant tool.
    pub tool: &'a ToolModel,
    /// The planner's settings.
    pub config: &'a PlanConfig,
}

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
/// [`UNMEASURED_LANDING_MM`], and at least the contact's unsettled gear flanks `flank`,
/// [`flank_errors`]), widened to the loop's measured `reach` when it is known, and to
/// [`SHALLOW_LANDING_MM`] for a `shallow` contact.
fn margin_of(
    tip: f64,
    slide: f64,
    (carried, flank): (f64, f64),
    reach: Option<f64>,
    shallow: bool,
) -> f64 {
    let floored = tip + slide + carried.max(UNMEASURED_LANDING_MM).max(flank);
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
/// least [`UNMEASURED_LANDING_MM`] on every grind and at least what the gears the contact's
/// load does not hold on one flank may move the ball ([`flank_errors`]); once the loop
/// measured how far beyond its plans' footprints the removal really reached
/// (`motion::aim::Aim::reach_mm`, read from the rescans by `cell::removal_reach`) the margin
/// is at least that reach; a contact commanded shallow lands within [`SHALLOW_LANDING_MM`]
/// ([`margin_of`]). `pieces` are the contacts' one-contact pieces, in order.
pub(crate) fn landing_margins(pieces: &[&PlannedPass], cs: &[Contact], cell: &Cell) -> Vec<f64> {
    margins_with(cs, &flank_errors(pieces, cs, cell), cell)
}

/// [`landing_margins`] of the contacts `cs` whose [`flank_errors`] are `flank`.
pub(crate) fn margins_with(cs: &[Contact], flank: &[f64], cell: &Cell) -> Vec<f64> {
    let (tool, config) = (cell.tool, cell.config);
    let tip = removal::montecarlo::tip_error(tool, &config.monte_carlo).mm;
    cs.iter()
        .zip(flank)
        .map(|(c, f)| landing_margin(c, (tip, *f), tool, config))
        .collect()
}

/// [`landing_margins`] of one contact `c` with the tool-tip error `tip` and its unsettled
/// flanks' error `flank`, mm.
fn landing_margin(
    c: &Contact,
    (tip, flank): (f64, f64),
    tool: &ToolModel,
    config: &PlanConfig,
) -> f64 {
    let slide = slide_error(c, tool);
    let carried = config.aim.shift_at(&c.point, &c.normal).norm();
    let shallow = c.depth_mm < SHALLOW_DEPTH_SHARE * tool.preload_mm;
    margin_of(tip, slide, (carried, flank), config.aim.reach_mm, shallow)
}

/// Factor by which a contact's force may lie above or below the planned one (4): the spring
/// is compressed by the planned preload plus the part's excess under the ball plus the arm's
/// error along the normal, which the plan does not know. Measured on a 1-degree arm calibrated
/// on itself (survey cases 61 and 181, cell seed 29): the simulated contact force reached
/// 3.9-5.8 N where the plan pressed 1.2-2.4 N, and in case 181's grind 2 the elbow, whose load
/// torque the plan put at -0.04 N m (its gravity flank), sat on the other flank through a whole
/// chain of contacts, 4-7 mm from its plan. With a span of 2 five of the ten cases still
/// gouged, with 4 one (docs/ALGORITHMS.md, "A looser gear's flank in the margin").
pub const FORCE_SPAN: f64 = 4.0;

/// Gear band, degrees, whose flank errors [`UNMEASURED_LANDING_MM`] already holds (0.55): the
/// floor was measured on the documented arm, whose bands `calibrate compliance` fits at
/// 0.44-0.54 degree (the shipped servos.toml). Only a looser gear's band beyond it widens a
/// contact's margin ([`flank_errors`]), so on the documented arm the margins stay what the
/// surveys measured.
pub const FLOOR_BAND_DEG: f64 = 0.55;

/// What the gears a contact's load does not settle on one flank may move its ball, mm, per
/// contact (0 without a `[compliance]` table): at each end pose of the contact's piece, every
/// joint whose load torque (the table's model: the arm's weight and the contact force along the
/// contact's outward normal) changes sign, or stays under `FLANK_TORQUE_NM`, as the force goes
/// from 1 / [`FORCE_SPAN`] to [`FORCE_SPAN`] times the planned one may sit on either flank of
/// its gear: the ball may land up to that joint's whole band (the table's `backlash_deg`, turned
/// through the joint's lever to the tip) from where the compensation put it. The table is
/// what `calibrate compliance` measured: on the documented arm's bands (about 0.5 degree) a
/// joint's whole band is 1.5-2.5 mm at the ball, on a 1-degree arm twice that.
pub(crate) fn flank_errors(pieces: &[&PlannedPass], cs: &[Contact], cell: &Cell) -> Vec<f64> {
    // no band beyond the floor's: nothing to add (the documented arm's plans, at no cost)
    let table = cell.robot.servos.compliance.as_ref();
    let Some(table) = table.filter(|t| t.backlash_deg.iter().any(|b| *b > FLOOR_BAND_DEG)) else {
        return vec![0.0; cs.len()];
    };
    let force = cell.tool.force_n();
    (pieces.iter().zip(cs))
        .map(|(p, c)| {
            let push = cell.workcell.direction_from_reference(&c.normal) * force * c.force_ratio;
            let ends = [p.points.first(), p.points.last()];
            (ends.iter().flatten())
                .map(|e| flank_error(table, cell.robot, &e.q, &push))
                .fold(0.0, f64::max)
        })
        .collect()
}

/// `cs` as the rim guard holds them: a contact whose gear flank the force does not settle
/// (its [`flank_errors`] in `flank` above 0) pressed [`FORCE_SPAN`] times harder, since the force that decides its
/// flank is not the plan's.
pub(crate) fn pressed_harder(cs: &[Contact], flank: &[f64]) -> Vec<Contact> {
    (cs.iter().zip(flank))
        .map(|(c, f)| match *f > 0.0 {
            true => Contact {
                force_ratio: c.force_ratio * FORCE_SPAN,
                ..*c
            },
            false => *c,
        })
        .collect()
}

/// [`flank_errors`] at one pose `q` under the planned contact force `push` (N, robot frame).
fn flank_error(table: &Compliance, robot: &Robot, q: &[f64], push: &Vector3<f64>) -> f64 {
    let lo = table.torques(robot, q, &(push / FORCE_SPAN));
    let hi = table.torques(robot, q, &(push * FORCE_SPAN));
    let jac = robot.jacobian(q);
    (0..lo.len().min(hi.len()).min(jac.ncols()))
        .filter(|&k| {
            lo[k].signum() != hi[k].signum() || lo[k].abs().min(hi[k].abs()) < FLANK_TORQUE_NM
        })
        .map(|k| {
            let band = table
                .backlash_deg
                .get(k)
                .map_or(0.0, |b| b - FLOOR_BAND_DEG);
            let band = band.max(0.0).to_radians();
            mm((0..3).map(|r| jac[(r, k)].powi(2)).sum::<f64>().sqrt()) * band
        })
        .sum()
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
        let m = |reach, shallow| margin_of(0.12, 0.2, (0.3, 0.0), reach, shallow);
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
        assert!((margin_of(0.12, 0.2, (2.0, 0.0), Some(0.5), false) - 2.32).abs() < 1e-12);
        // unsettled flanks beyond the floor count in full, under it not at all
        assert!((margin_of(0.12, 0.2, (0.3, 3.5), None, false) - 3.82).abs() < 1e-12);
        assert!((margin_of(0.12, 0.2, (0.3, 1.0), None, false) - floor).abs() < 1e-12);
    }

    /// A gear whose load torque changes sign within the force's span (the elbow where the
    /// contact force just balances its weight) may sit on either flank: the margin takes its
    /// band beyond [`FLOOR_BAND_DEG`] turned through its lever to the ball. Pressed a hundred
    /// times harder the contact holds it on one flank, and the documented arm's bands (within
    /// the floor's) add nothing.
    #[test]
    fn an_unsettled_gear_widens_the_margin_by_its_band_beyond_the_floors() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("calibration");
        let robot = Robot::load(
            &dir.join("dofbot.urdf"),
            &dir.join("tool.toml"),
            &dir.join("servos.toml"),
        )
        .unwrap();
        let shipped = robot.servos.compliance.clone().unwrap();
        let mut loose = shipped.clone();
        loose.backlash_deg = [0.0, 0.0, FLOOR_BAND_DEG + 1.0, 0.0, 0.0];
        // a pose of a face looking at the base (survey case 181), pressed towards the base
        let q = [0.05, -1.35, 1.50, -1.40, 0.0];
        let push = Vector3::new(0.0, -1.0, -0.15).normalize();
        let weight = loose.torques(&robot, &q, &Vector3::zeros())[2];
        let per_newton = loose.torques(&robot, &q, &push)[2] - weight;
        let balance = -weight / per_newton;
        assert!(balance > 0.0, "the elbow's weight and the push must oppose");
        let jac = robot.jacobian(&q);
        let lever = mm((0..3).map(|r| jac[(r, 2)].powi(2)).sum::<f64>().sqrt());
        let unsettled = flank_error(&loose, &robot, &q, &(push * balance));
        assert!(
            (unsettled - lever * 1f64.to_radians()).abs() < 1e-9,
            "{unsettled} mm"
        );
        assert!(
            unsettled > 2.0,
            "a 1-degree band at the elbow moves the ball {unsettled} mm"
        );
        assert_eq!(
            flank_error(&loose, &robot, &q, &(push * balance * 100.0)),
            0.0
        );
        assert_eq!(flank_error(&shipped, &robot, &q, &(push * balance)), 0.0);
    }
}

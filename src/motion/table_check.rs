//! A plan that turns the part turntable, checked in its cell before `run` sends it: the table
//! part against the cell's turntable with the arm at rest during every table move
//! ([`Plan::check_cell`]), and the collision re-check of each stretch of samples against the
//! part turned to its table angle ([`Plan::check_clearance_cell`]).
use super::collide::CollisionConfig;
use super::error::PlanError;
use super::file::{CheckedPlan, Plan};
use super::program::SegmentKind;
use super::table_file::{check, TablePlan};
use super::validate::ValidationConfig;
use crate::repair::Inspection;
use crate::robot::{Robot, Turntable, Workcell};

/// Largest difference, rad, between the arm's pose while the table turns and its start pose.
const REST_TOLERANCE: f64 = 1e-9;

impl Plan {
    /// [`Plan::check`] in a cell that may have a turntable: the arm's part as there, and a
    /// `turntable` part checked against `table` ([`check`]), with the arm resting at its start
    /// (home, retracted) pose at every table move. A plan that turns the table is refused
    /// without a table in the cell, and one made for another table servo id is refused.
    pub fn check_cell(
        &self,
        robot: &Robot,
        table: Option<&Turntable>,
        config: &ValidationConfig,
    ) -> Result<CheckedPlan, PlanError> {
        let Some(part) = &self.turntable else {
            return self.check(robot, config);
        };
        let Some(table) = table else {
            return Err(PlanError::Frames(
                "the plan has a `turntable` part but the cell has no [turntable] (run --cell DIR)"
                    .into(),
            ));
        };
        let arm_only = Plan {
            turntable: None,
            ..self.clone()
        };
        let mut checked = arm_only.check(robot, config)?;
        let moves = check(part, table, self.samples.len(), self.period)?;
        let home = &self.samples[0].q;
        for (k, m) in part.moves.iter().enumerate() {
            let q = &self.samples[m.at_sample].q;
            let off = q.iter().zip(home).map(|(a, b)| (a - b).abs());
            if off.fold(0.0, f64::max) > REST_TOLERANCE {
                return Err(PlanError::Frames(format!(
                    "turntable: move {k}: the arm is not at its start (home) pose at sample {} while the table turns",
                    m.at_sample
                )));
            }
        }
        self.check_region_angles(part)?;
        checked.table = Some(moves);
        Ok(checked)
    }

    /// Every grinding segment runs at its region's planned table angle (a plan whose table
    /// moves were deleted or edited would grind with the part at another angle).
    fn check_region_angles(&self, part: &TablePlan) -> Result<(), PlanError> {
        let ranges = angle_ranges(part, self.samples.len());
        for s in &self.segments {
            let (SegmentKind::Grind, Some(region)) = (&s.kind, s.region) else {
                continue;
            };
            let Some(want) = part.regions.iter().find(|r| r.region == region) else {
                return Err(PlanError::Frames(format!(
                    "turntable: region {region} is ground but has no table angle in `turntable.regions`"
                )));
            };
            let at = ranges
                .iter()
                .find(|(lo, hi, _)| s.first_sample >= *lo && s.first_sample < (*hi).max(*lo + 1))
                .map_or(part.start, |r| r.2);
            if want
                .angles_deg()
                .all(|a| (at.to_degrees() - a).abs() > ANGLE_TOLERANCE_DEG)
            {
                let planned: Vec<String> = want.angles_deg().map(|a| format!("{a:.4}")).collect();
                return Err(PlanError::Frames(format!(
                    "turntable: region {region} is planned at {} deg but the table is at {:.4} deg \
                     when it is ground (sample {}): are table moves missing?",
                    planned.join(" / "),
                    at.to_degrees(),
                    s.first_sample
                )));
            }
        }
        Ok(())
    }
}

/// Largest accepted difference between a region's planned table angle and the angle the plan's
/// moves leave the table at, degrees (the angles are written as computed; a thousandth of a
/// degree is far below the table servo's step).
const ANGLE_TOLERANCE_DEG: f64 = 1e-3;

/// The arm samples at one table angle: `first..=last` (a move's resting sample belongs to
/// the ranges on both sides: the arm rests there while the table turns).
fn angle_ranges(plan: &TablePlan, samples: usize) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::with_capacity(plan.moves.len() + 1);
    let (mut first, mut angle) = (0usize, plan.start);
    for m in &plan.moves {
        out.push((first, m.at_sample, angle));
        first = m.at_sample;
        angle = *m.samples.last().unwrap_or(&angle);
    }
    out.push((first, samples.saturating_sub(1), angle));
    out
}

impl Plan {
    /// [`Plan::check_clearance`] in a cell that may have a turntable: the samples between two
    /// table moves against the part turned to the table angle they are ground at.
    pub fn check_clearance_cell(
        &self,
        inspection: &Inspection,
        robot: &Robot,
        wc: &Workcell,
        table: Option<&Turntable>,
        cfg: &CollisionConfig,
    ) -> Result<(), PlanError> {
        let (Some(part), Some(table)) = (&self.turntable, table) else {
            return self.check_clearance(inspection, robot, wc, cfg);
        };
        let mut found = Vec::new();
        for (lo, hi, angle) in angle_ranges(part, self.samples.len()) {
            let owners: Vec<usize> = (0..self.segments.len())
                .filter(|&k| {
                    let s = &self.segments[k];
                    s.last_sample >= lo && s.first_sample <= hi
                })
                .collect();
            let segments: Vec<_> = owners
                .iter()
                .map(|&k| {
                    let mut s = self.segments[k].clone();
                    s.first_sample = s.first_sample.max(lo) - lo;
                    s.last_sample = s.last_sample.min(hi) - lo;
                    s
                })
                .collect();
            let sub = Plan {
                samples: self.samples[lo..=hi].to_vec(),
                segments,
                turntable: None,
                ..self.clone()
            };
            let at = table.workcell_at(wc, angle);
            match sub.check_clearance(inspection, robot, &at, cfg) {
                Ok(()) => {}
                Err(PlanError::Collides(hits)) => found.extend(hits.into_iter().map(|mut c| {
                    c.sample += lo;
                    c.segment = c.segment.map(|k| owners[k]);
                    c
                })),
                Err(e) => return Err(e),
            }
        }
        if found.is_empty() {
            Ok(())
        } else {
            Err(PlanError::Collides(found))
        }
    }
}

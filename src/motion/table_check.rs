//! A plan that turns the part turntable, checked in its cell before `run` sends it: the table
//! part against the cell's turntable with the arm at rest during every table move
//! ([`Plan::check_cell`]), and the collision re-check of each stretch of samples against the
//! part turned to its table angle ([`Plan::check_clearance_cell`]).
use super::clearance::{allowances, Collision};
use super::collide::{CollisionConfig, Scene};
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
            // ground with the table turning: its angle per sample is the stretch's (checked
            // against the table's limits and frames by `check`)
            let synced = part
                .synced
                .iter()
                .any(|st| s.first_sample >= st.first_sample && s.first_sample < st.last_sample());
            if synced && want.synced_strokes == 0 {
                return Err(PlanError::Frames(format!(
                    "turntable: region {region} is ground while the table turns (sample {}) but has no synced strokes",
                    s.first_sample
                )));
            }
            if synced {
                continue;
            }
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
/// the ranges on both sides: the arm rests there while the table turns; a synced stretch's
/// first sample ends one range and its last starts the next, and the samples between them
/// belong to none: each has its own angle).
fn angle_ranges(plan: &TablePlan, samples: usize) -> Vec<(usize, usize, f64)> {
    let mut events: Vec<(usize, usize, f64)> = (plan.moves.iter())
        .map(|m| (m.at_sample, m.at_sample, *m.samples.last().unwrap_or(&0.0)))
        .chain((plan.synced.iter()).map(|s| {
            (
                s.first_sample,
                s.last_sample(),
                *s.angles.last().unwrap_or(&0.0),
            )
        }))
        .collect();
    events.sort_by_key(|e| (e.0, e.1));
    let mut out = Vec::with_capacity(events.len() + 1);
    let (mut first, mut angle) = (0usize, plan.start);
    for (at, next, to) in events {
        out.push((first, at, angle));
        (first, angle) = (next, to);
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
        found.extend(self.synced_collisions(inspection, robot, wc, part, table, cfg)?);
        if found.is_empty() {
            Ok(())
        } else {
            Err(PlanError::Collides(found))
        }
    }

    /// The samples inside the synced stretches of `part`, each against the part turned to its
    /// own table angle (one scene, placed per sample), with what its segment allows.
    fn synced_collisions(
        &self,
        inspection: &Inspection,
        robot: &Robot,
        wc: &Workcell,
        part: &TablePlan,
        table: &Turntable,
        cfg: &CollisionConfig,
    ) -> Result<Vec<Collision>, PlanError> {
        cfg.check(robot.dof()).map_err(PlanError::Config)?;
        let mut cfg = cfg.clone();
        cfg.press_mm = self.removal.as_ref().map_or(0.0, |r| r.preload_mm);
        let mut found = Vec::new();
        if part.synced.is_empty() {
            return Ok(found);
        }
        let rules = allowances(&self.segments, self.samples.len());
        let mut scene = Scene::new(&inspection.points, robot, wc, &cfg);
        for st in &part.synced {
            let inner = st.first_sample + 1..st.last_sample();
            for (i, angle) in inner.zip(&st.angles[1..]) {
                let Some((sample, &(allow, owner))) = self.samples.get(i).zip(rules.get(i)) else {
                    continue;
                };
                scene.place(&table.workcell_at(wc, *angle), &cfg.solids);
                if let Some(hit) = scene.check(robot, &sample.q, allow) {
                    let seg = owner.map(|k| &self.segments[k]);
                    found.push(Collision {
                        sample: i,
                        segment: owner,
                        kind: seg.map(|s| s.kind),
                        region: seg.and_then(|s| s.region),
                        hit,
                    });
                }
            }
        }
        Ok(found)
    }
}

//! Finishing strokes (issue 50, item 4): the loop's later grinds average the arm's random
//! error instead of printing it. The arm leaves about 0.15 mm of tip error after compensation
//! that changes from stroke to stroke (backlash flank, read-back noise); under one parallel
//! raster each point is ground by the few lines within a patch of it, so one line's error
//! shows as a furrow or a ridge along it. A finishing plan (grind [`FinishConfig::from_grind`]
//! on; off by default, [`FINISH_FROM_GRIND`]: on the demo the finish cut deeper, beside regions
//! whose removal landed a millimetre from the carried aim) therefore
//! - presses with a smaller influence: the preload times [`FinishConfig::preload_share`]
//!   (lower force, a smaller Hertz patch and a slower removal, so that the same error in k or
//!   in the shift costs less depth); the tool model is changed once, where the planner reads
//!   it (`plan_part`), so the press, the dwell solve, the Monte Carlo, the prediction, the
//!   collision check's press depth and plan.json's `removal.preload_mm` all follow it, and the
//!   simulator derives its force from the penetration the plan commands, as for any plan;
//! - lays [`FinishConfig::directions`] rasters over each region, turned 180/n degrees apart
//!   and, grind to grind, by the golden angle (cross-hatch: Dunn and Walker, "Pseudo-random
//!   tool paths for CNC sub-aperture polishing", Optics Express 16(23), 2008, on regular
//!   rasters printing their own ripple), joined by links, with one dwell solved over all of
//!   them: each point is ground by n times as many strokes, each taking 1/n of its removal;
//! - asks of each point at most [`FinishConfig::removal_share`] of what is left above the
//!   allowance, so the planned removal falls grind by grind and a tool faster than the plan
//!   stops short of the allowance instead of below it.
//!
//! Measured on a plate (tests/finish_strokes.rs) and on the demo: docs/ALGORITHMS.md,
//! "Finishing strokes".
use serde::{Deserialize, Serialize};

use super::raster::{self, PathPoint, RasterGeometry, Stroke, StrokeKind};
use super::surface::Surface;
use crate::removal::ToolModel;
use crate::repair::{RegionInfo, SurfacePoint};

/// The first grind of a loop planned as a finish by default (0: none, the finish is off until
/// the loop's aim holds for crossing strokes). Set to 2 (`[plan.finish] from_grind = 2`),
/// grind 1 stays a raster (made before any removal shift or k was measured, capped at a share
/// of the tolerance: `motion::aim`) and grind 2 on finish. Measured on the demo (documented
/// arm, docs/ALGORITHMS.md "Finishing strokes"): the base's lowest ground point after grinds
/// 2 and 3 was -0.009 and -0.026 mm; finishing from grind 2 cut to -0.067 and -0.052 mm
/// (-0.020 and -0.068 mm at the full preload), and the two new pits that every run leaves
/// after grind 3 deepened from -0.056 / -0.057 to -0.092 / -0.069 mm. The lowest points lay
/// beside regions whose removal landed 1.0-1.3 mm from its aim: the shift the loop carries
/// was measured on strokes in one direction, and the crossing strokes move other joints.
pub const FINISH_FROM_GRIND: usize = 0;

/// Share of the tool's preload a finishing plan presses with (0.8): 2 mm -> 1.6 mm on the
/// shipped tool, 2.0 N -> 1.6 N, the Hertz patch x 0.93 (0.8^(1/3)) and the removal per
/// second of dwell x 0.8 (Preston: the volume rate follows the force). Lower is not better:
/// the normal part of the tip error changes the force by error / preload (0.15 mm: 7.5 % at
/// 2 mm, 9.4 % at 1.6 mm, 12.5 % at 1.2 mm), and on the plate (tests/finish_strokes.rs) the
/// cross-hatch at 0.6 of the preload spread the removal 1.20 x less than the raster, against
/// 1.33 x at the full preload; on the demo, grinds 2 and 3 at 0.6 cut to -0.079 and -0.083 mm
/// where the raster at the full preload cut to -0.009 and -0.026 mm.
pub const FINISH_PRELOAD_SHARE: f64 = 0.8;

/// Rasters a finishing plan lays over each region (2: a cross-hatch at 90 degrees): each
/// point is ground by twice the strokes, so independent per-stroke errors average down by
/// about sqrt(2) (measured 1.4-2.1 x on the plate, tests/finish_strokes.rs); a third
/// direction adds another 50 % of the grinding time for sqrt(3/2) more.
pub const FINISH_DIRECTIONS: usize = 2;

/// Share of each point's removal target a finishing plan asks for (0.85): k fitted after a
/// grind was within 15 % of the cell's (tests/calibrate_removal.rs measured 5.16e-6 against a
/// true 4.47e-6), and 0.85 x 1.15 < 1 keeps a tool that much faster than the plan above the
/// allowance; the target falls grind by grind with what is left.
pub const FINISH_REMOVAL_SHARE: f64 = 0.85;

/// The golden angle, degrees: successive finishing grinds turn their cross-hatch by it, so
/// that no two grinds lay their lines in the same directions (the turns modulo 180 degrees
/// fill the half circle evenly).
pub const GOLDEN_ANGLE_DEG: f64 = 137.507_764_050_037_85;

/// Settings of the finishing strokes (`[plan.finish]`); the loop sets `grind`. Off by default
/// ([`FINISH_FROM_GRIND`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FinishConfig {
    /// The loop's grind this plan makes, 1 first (0: a plan outside a loop, planned as a first
    /// grind). The loop sets it; `plan --config` takes it from the settings file.
    pub grind: usize,
    /// The first grind planned as a finish ([`FINISH_FROM_GRIND`]; 0: never, the default).
    pub from_grind: usize,
    /// Share of the tool's preload a finish presses with ([`FINISH_PRELOAD_SHARE`]).
    pub preload_share: f64,
    /// Rasters a finish lays over each region, turned 180/n degrees apart
    /// ([`FINISH_DIRECTIONS`]).
    pub directions: usize,
    /// Share of each point's removal target a finish asks for ([`FINISH_REMOVAL_SHARE`]).
    pub removal_share: f64,
}

impl Default for FinishConfig {
    fn default() -> Self {
        FinishConfig {
            grind: 0,
            from_grind: FINISH_FROM_GRIND,
            preload_share: FINISH_PRELOAD_SHARE,
            directions: FINISH_DIRECTIONS,
            removal_share: FINISH_REMOVAL_SHARE,
        }
    }
}

/// Whether a plan used one parallel raster at the tool's preload or finishing strokes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StrokeMode {
    /// One parallel raster per region at the tool's preload (a first grind).
    Raster,
    /// Finishing strokes: a smaller influence, a cross-hatch, the removal capped.
    Finish,
}

/// plan.json's `strokes` (removal plans): which strokes the plan used and with what.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StrokeRecord {
    /// Raster or finish.
    pub mode: StrokeMode,
    /// The loop's grind the plan was made for (0: outside a loop).
    pub grind: usize,
    /// The preload pressed with, mm (the tool's, or its finishing share).
    pub preload_mm: f64,
    /// Each raster's turn from the region's principal direction, degrees.
    pub turns_deg: Vec<f64>,
    /// Share of each point's removal target asked for (1 for a raster).
    pub removal_share: f64,
}

impl FinishConfig {
    /// True when the settings are the defaults (plan.json's provenance then leaves them out).
    pub fn is_default(&self) -> bool {
        *self == FinishConfig::default()
    }

    /// True when this plan is a finish: grind `grind` at or after `from_grind`.
    pub fn active(&self) -> bool {
        self.from_grind > 0 && self.grind >= self.from_grind
    }

    /// Checks the values; the message names the key.
    pub fn check(&self) -> Result<(), String> {
        let share = |name: &str, v: f64| match v.is_finite() && v > 0.0 && v <= 1.0 {
            true => Ok(()),
            false => Err(format!(
                "`finish.{name}` = {v:?} is outside 0 (excluded)..=1"
            )),
        };
        share("preload_share", self.preload_share)?;
        share("removal_share", self.removal_share)?;
        if !(1..=8).contains(&self.directions) {
            return Err(format!(
                "`finish.directions` = {} is outside 1..=8",
                self.directions
            ));
        }
        Ok(())
    }

    /// The tool a plan presses with: `tool` itself, or with its preload times
    /// `preload_share` in a finish (the force, patch and removal follow the preload).
    pub fn tool(&self, tool: ToolModel) -> ToolModel {
        match self.active() {
            true => ToolModel {
                preload_mm: tool.preload_mm * self.preload_share,
                ..tool
            },
            false => tool,
        }
    }

    /// A point's removal target `target`, mm, as a finish asks for it (times
    /// `removal_share`); unchanged otherwise.
    pub fn cap(&self, target: f64) -> f64 {
        match self.active() {
            true => target * self.removal_share,
            false => target,
        }
    }

    /// The turns of the rasters over each region, rad: one (0) outside a finish; in a finish
    /// `directions` turns 180/n degrees apart, the first turned by the golden angle per
    /// finishing grind after the first (grind 2: 0 and 90 degrees, grind 3: 137.5 and 47.5).
    pub fn turns(&self) -> Vec<f64> {
        if !self.active() {
            return vec![0.0];
        }
        let n = self.directions.max(1);
        let first = (self.grind - self.from_grind) as f64 * GOLDEN_ANGLE_DEG;
        (0..n)
            .map(|i| ((first + 180.0 * i as f64 / n as f64) % 180.0).to_radians())
            .collect()
    }

    /// plan.json's record of the strokes a plan used with `tool` (the tool as pressed,
    /// [`FinishConfig::tool`]).
    pub fn record(&self, tool: &ToolModel) -> StrokeRecord {
        let active = self.active();
        StrokeRecord {
            mode: match active {
                true => StrokeMode::Finish,
                false => StrokeMode::Raster,
            },
            grind: self.grind,
            preload_mm: tool.preload_mm,
            turns_deg: self.turns().iter().map(|t| t.to_degrees()).collect(),
            removal_share: if active { self.removal_share } else { 1.0 },
        }
    }
}

/// The strokes over `region` (its core points `members`) at the contact heights `offsets`:
/// one raster per turn of `turns` (rad, `raster::raster_turned`), in order, each joined to
/// the last by a link in contact from where it ended (so that the rasters grind as one run
/// where the arm can).
pub fn strokes(
    (region, members): (&RegionInfo, &[SurfacePoint]),
    surface: &Surface,
    g: &RasterGeometry,
    offsets: &[f64],
    turns: &[f64],
) -> Vec<Stroke> {
    let mut out: Vec<Stroke> = Vec::new();
    for &turn in turns {
        let next = raster::raster_turned(region, members, surface, g, offsets, turn);
        let end = out.last().and_then(|s| s.points.last()).copied();
        let start = next.first().and_then(|s| s.points.first()).copied();
        if let (Some(a), Some(b), Some(first)) = (end, start, next.first()) {
            let joined = link(&a, &b, first, surface, g.spacing);
            out.push(joined);
        }
        out.extend(next);
    }
    out
}

/// A link stroke in contact from `a` to `b` (both included), `spacing` mm apart, on
/// `surface` at `a`'s offset, in `next`'s region and layer.
fn link(a: &PathPoint, b: &PathPoint, next: &Stroke, surface: &Surface, spacing: f64) -> Stroke {
    let along = raster::resample(&a.surface, &b.surface, spacing);
    Stroke {
        region: next.region,
        layer: next.layer,
        kind: StrokeKind::Link,
        points: raster::project(&along, surface, a.offset),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_first_grind_is_a_raster_and_later_grinds_finish() {
        assert!(!FinishConfig {
            grind: 3,
            ..FinishConfig::default()
        }
        .active());
        let mut f = FinishConfig {
            grind: 1,
            from_grind: 2,
            ..FinishConfig::default()
        };
        assert!(!f.active());
        assert_eq!(f.turns(), vec![0.0]);
        assert_eq!(f.cap(0.2), 0.2);
        assert_eq!(f.tool(ToolModel::default()).preload_mm, 2.0);
        f.grind = 2;
        assert!(f.active());
        let deg: Vec<f64> = f.turns().iter().map(|t| t.to_degrees()).collect();
        assert!((deg[0] - 0.0).abs() < 1e-9 && (deg[1] - 90.0).abs() < 1e-9);
        assert!((f.cap(0.2) - 0.17).abs() < 1e-12);
        assert!((f.tool(ToolModel::default()).preload_mm - 1.6).abs() < 1e-12);
        f.grind = 3;
        let deg: Vec<f64> = f.turns().iter().map(|t| t.to_degrees()).collect();
        assert!((deg[0] - 137.507_764).abs() < 1e-5 && (deg[1] - 47.507_764).abs() < 1e-5);
        f.from_grind = 0;
        assert!(!f.active());
        assert!(FinishConfig {
            directions: 0,
            ..FinishConfig::default()
        }
        .check()
        .unwrap_err()
        .contains("finish.directions"));
    }
}

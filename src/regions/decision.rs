//! The decision rule with measurement uncertainty (ISO 14253-1, "decision rules for proving
//! conformity or nonconformity with specifications"): each measured core point is
//! - *conform* when its distance plus its uncertainty stays within the tolerance
//!   (|d| + U <= tol: conformity proven),
//! - *non-conform* when its distance minus its uncertainty is still beyond it
//!   (|d| - U > tol: nonconformity proven),
//! - *undecided* otherwise (the uncertainty zone straddles the tolerance),
//!
//! with U the point's expanded uncertainty: the comparison's level of detection at 95 %
//! (`uncertainty` of deviations.csv, M3C2's LoD95, registration error included). A point
//! with no distance is not judged here (the coverage counts it); a point whose uncertainty is
//! not a number is undecided.
//!
//! The verdict uses it ([`super::find_regions_in`]): a region is evidence of a defect only
//! when a member is non-conform or carries a fitted peak beyond the tolerance by more than
//! its LoD; "within tolerance" needs no non-conform point and an undecided share of the
//! area at most [`MAX_UNDECIDED_SHARE`]; otherwise, with no region as evidence, the verdict
//! is `undecided` (rescan at a higher resolution or with less noise).
use serde::{Deserialize, Serialize};

use crate::compare::Deviations;

/// Largest share of the measured area to inspect that may be undecided for a "within
/// tolerance" verdict: 1 %. Issue 50's acceptance asks that at least 99 % of the repairable
/// area be within the tolerance, so a part may leave at most 1 % unproven; ISO 14253-1 alone
/// would refuse any undecided point, which the LoD95 (5 % false alarms per point by its
/// definition) makes unreachable on 50,000 core points. The demo's fresh scan leaves
/// 0.08 % of its core points undecided, its rescan after a grind 0.46 %.
pub const MAX_UNDECIDED_SHARE: f64 = 0.01;

/// What ISO 14253-1 proves of one measured value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Conformity {
    /// |d| + U <= tol.
    Conform,
    /// |d| - U > tol.
    NonConform,
    /// Neither: the uncertainty zone contains the tolerance.
    Undecided,
}

/// The rule on one value: `distance` (None when not measured: NaN), `uncertainty` U (its
/// LoD95; NaN: undecided), `tolerance`.
pub fn conformity(distance: f64, uncertainty: f64, tolerance: f64) -> Option<Conformity> {
    if !distance.is_finite() {
        return None;
    }
    let d = distance.abs();
    Some(if d - uncertainty > tolerance {
        Conformity::NonConform
    } else if d + uncertainty <= tolerance {
        Conformity::Conform
    } else {
        Conformity::Undecided
    })
}

/// The rule over the measured core points of the area to inspect (regions.json's
/// `decision`). Absent in files from before 2026-12-05: every count 0.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Decision {
    /// The rule's name: "ISO 14253-1: conform |d|+U<=tol, non-conform |d|-U>tol, else
    /// undecided; U = LoD95".
    pub rule: String,
    /// Conform core points.
    pub conform: usize,
    /// Non-conform core points.
    pub nonconform: usize,
    /// Undecided core points.
    pub undecided: usize,
    /// Share of the measured area to inspect (by the core points' area shares) that is
    /// undecided (0..1).
    pub undecided_share: f64,
    /// Share of it that is non-conform (0..1).
    pub nonconform_share: f64,
    /// Largest undecided share for "within tolerance" ([`MAX_UNDECIDED_SHARE`]).
    pub max_undecided_share: f64,
    /// Non-conform core points outside every region (clusters too small to be a region).
    pub nonconform_outside_regions: usize,
    /// Ids of the regions none of whose members is non-conform (nor carries a vouched
    /// fitted peak): listed, but not evidence for the verdict.
    pub undecided_regions: Vec<usize>,
}

/// The rule's counts over a set of core points.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Conform core points.
    pub conform: usize,
    /// Non-conform core points.
    pub nonconform: usize,
    /// Undecided core points.
    pub undecided: usize,
}

impl Counts {
    /// The rule over `(distance, uncertainty)` pairs at `tolerance` (unmeasured ones left out).
    pub fn of(values: impl Iterator<Item = (f64, f64)>, tolerance: f64) -> Counts {
        let mut out = Counts::default();
        for (d, u) in values {
            match conformity(d, u, tolerance) {
                Some(Conformity::Conform) => out.conform += 1,
                Some(Conformity::NonConform) => out.nonconform += 1,
                Some(Conformity::Undecided) => out.undecided += 1,
                None => {}
            }
        }
        out
    }
}

/// The rule's name as files and pages carry it.
pub const RULE: &str =
    "ISO 14253-1: conform |d|+U<=tol, non-conform |d|-U>tol, else undecided; U = LoD95";

/// Counts the rule over `dev`'s measured core points in the area to inspect (`in_area`;
/// None: all), with their area shares `share`; `labels` give each point's region (-1: none).
pub fn decide(
    dev: &Deviations,
    share: &[f64],
    in_area: Option<&[bool]>,
    labels: &[i64],
    tolerance: f64,
) -> Decision {
    let mut out = Decision {
        rule: RULE.to_string(),
        max_undecided_share: MAX_UNDECIDED_SHARE,
        ..Decision::default()
    };
    let (mut total, mut undecided, mut nonconform) = (0.0, 0.0, 0.0);
    for i in (0..dev.values.len()).filter(|&i| in_area.is_none_or(|a| a[i])) {
        let v = &dev.values[i];
        let Some(c) = conformity(v.distance, v.uncertainty, tolerance) else {
            continue;
        };
        total += share[i];
        match c {
            Conformity::Conform => out.conform += 1,
            Conformity::NonConform => {
                out.nonconform += 1;
                nonconform += share[i];
                if labels[i] < 0 {
                    out.nonconform_outside_regions += 1;
                }
            }
            Conformity::Undecided => {
                out.undecided += 1;
                undecided += share[i];
            }
        }
    }
    if total > 0.0 {
        out.undecided_share = undecided / total;
        out.nonconform_share = nonconform / total;
    }
    out
}

impl Decision {
    /// Whether the rule proves the part within tolerance: no non-conform point and an
    /// undecided share at most `max_undecided_share`.
    pub fn proves_conform(&self) -> bool {
        self.nonconform == 0 && self.undecided_share <= self.max_undecided_share
    }

    /// The counts in words ("ISO 14253-1 with U = LoD95: 50137 conform, 637 non-conform,
    /// 40 undecided (0.08 % of the measured area, at most 1.0 % for within tolerance)").
    pub fn describe(&self) -> String {
        format!(
            "ISO 14253-1 with U = LoD95: {} conform, {} non-conform, {} undecided ({:.2} % of \
             the measured area; at most {:.1} % for within tolerance)",
            self.conform,
            self.nonconform,
            self.undecided,
            100.0 * self.undecided_share,
            100.0 * self.max_undecided_share
        )
    }

    /// Why the verdict is undecided, for the user: what is missing and what to do.
    pub fn undecided_reason(&self) -> String {
        if self.nonconform > 0 {
            format!(
                "{} non-conform core point(s) in no region (clusters smaller than a region): \
                 rescan at a higher resolution",
                self.nonconform
            )
        } else {
            format!(
                "{:.2} % of the measured area is undecided (its uncertainty zone straddles the \
                 tolerance), more than {:.1} %: rescan at a higher resolution or with less noise",
                100.0 * self.undecided_share,
                100.0 * self.max_undecided_share
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_at_its_bounds() {
        let c = |d: f64, u: f64| conformity(d, u, 0.05);
        // |d| + U = tol exactly is conform; a hair more is undecided.
        assert_eq!(c(0.04, 0.01), Some(Conformity::Conform));
        assert_eq!(c(-0.04, 0.01), Some(Conformity::Conform));
        assert_eq!(c(0.0401, 0.01), Some(Conformity::Undecided));
        // |d| - U = tol is still undecided; beyond it non-conform, either sign.
        assert_eq!(c(0.07, 0.02), Some(Conformity::Undecided));
        assert_eq!(c(0.0701, 0.02), Some(Conformity::NonConform));
        assert_eq!(c(-0.0701, 0.02), Some(Conformity::NonConform));
        // Beyond the tolerance but within the uncertainty: undecided.
        assert_eq!(c(0.06, 0.02), Some(Conformity::Undecided));
        // No uncertainty: undecided; no distance: not judged.
        assert_eq!(c(0.01, f64::NAN), Some(Conformity::Undecided));
        assert_eq!(c(f64::NAN, 0.01), None);
        let n = Counts::of(
            [(0.0, 0.01), (0.2, 0.01), (0.05, 0.01), (f64::NAN, 0.0)].into_iter(),
            0.05,
        );
        assert_eq!((n.conform, n.nonconform, n.undecided), (1, 1, 1));
    }
}

//! The loop's records: what one inspection of the loop measured, what its plan set out to
//! remove, the rule that ends the loop ([`decide`] with a [`CycleConfig`]) and the table of
//! the records (text, cycle.json, cycle.html's rows). Nothing here touches a file or the arm;
//! the engine (`super::engine`) feeds these types.
use serde::{Deserialize, Serialize};

use super::config::CycleConfig;
use crate::cell::removal_shift::CarriedShift;
use crate::motion::{Inspection, Plan};
use crate::regions::{Counts, Region, Verdict};
use crate::removal::fit::{Agreement, GrindPair};
use crate::report::{escape, table_page};

/// What one inspection of the loop measured (over the repairable regions: pits are never
/// ground and are only counted).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measured {
    /// The inspection's verdict.
    pub verdict: Verdict,
    /// Repairable regions (material in excess).
    pub repairable: usize,
    /// Pits (not repairable).
    pub pits: usize,
    /// Largest peak of a repairable region, mm (None: no repairable region).
    pub peak_mm: Option<f64>,
    /// RMS of the distance over the core points of repairable regions, mm.
    pub rms_mm: Option<f64>,
    /// Volume above the tolerance of the repairable regions, mm^3.
    pub volume_mm3: f64,
    /// The decision rule with uncertainty (ISO 14253-1, `regions::decision`) over every
    /// measured core point: conform, non-conform, undecided. Absent in older cycle.json: 0s.
    #[serde(default)]
    pub decision: Counts,
}

impl Measured {
    /// Summary of an inspection: its verdict (regions.json) and its regions and core points.
    pub fn of(verdict: Verdict, inspection: &Inspection) -> Measured {
        let repairable: Vec<&Region> = inspection.regions.iter().filter(|r| r.repairable).collect();
        let ids: Vec<i64> = repairable.iter().map(|r| r.id as i64).collect();
        let d: Vec<f64> = inspection
            .points
            .iter()
            .filter(|p| ids.contains(&p.region) && p.distance.is_finite())
            .map(|p| p.distance)
            .collect();
        Measured {
            verdict,
            repairable: repairable.len(),
            pits: inspection.regions.len() - repairable.len(),
            peak_mm: repairable.iter().map(|r| r.peak).reduce(f64::max),
            rms_mm: rms(&d),
            volume_mm3: repairable.iter().map(|r| r.volume).sum(),
            decision: Counts::of(
                inspection
                    .points
                    .iter()
                    .map(|p| (p.distance, p.uncertainty)),
                inspection.tolerance.unwrap_or(f64::NAN),
            ),
        }
    }
}

/// Root mean square (None for no values).
fn rms(d: &[f64]) -> Option<f64> {
    (!d.is_empty()).then(|| (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt())
}

/// Ids of the regions `plan` grinds: depth layers planned (rigid mode), or a removal
/// prediction (removal mode).
pub fn planned_regions(plan: &Plan) -> Vec<usize> {
    let mut ids = plan.reachability.planned_ids();
    if let Some(rem) = &plan.removal {
        ids.extend(rem.regions.iter().map(|r| r.region));
    }
    ids.sort_unstable();
    ids.dedup();
    ids
}

/// The predicted RMS residual over `plan`'s removal regions' points (weighted by their core
/// points), mm; None for a rigid plan.
pub fn predicted_rms(plan: &Plan) -> Option<f64> {
    let rem = plan.removal.as_ref()?;
    let n: usize = rem.regions.iter().map(|r| r.core_points).sum();
    (n > 0).then(|| {
        let s: f64 = rem
            .regions
            .iter()
            .map(|r| r.core_points as f64 * r.after.rms_mm * r.after.rms_mm)
            .sum();
        (s / n as f64).sqrt()
    })
}

/// One inspection of the loop and, when it was followed by a grind, what was planned and
/// what the next inspection found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IterationRecord {
    /// 1-based iteration (the folder iter-k).
    pub iteration: usize,
    /// What the inspection measured.
    pub measured: Measured,
    /// Ids of the regions the plan grinds.
    pub planned_regions: Vec<usize>,
    /// Excess volume of the regions the plan grinds, mm^3 (None: not planned).
    pub planned_volume_mm3: Option<f64>,
    /// The plan's predicted RMS residual over its regions, mm (removal plans only).
    pub predicted_residual_mm: Option<f64>,
    /// RMS of the next inspection's distance over the core points of the planned regions, mm.
    pub achieved_residual_mm: Option<f64>,
    /// Share of the planned excess volume that the next inspection found removed.
    pub progress: Option<f64>,
    /// Preston's k fitted after this iteration's grind to the points of every grind so far
    /// (`removal::fit::pool`), the next plan's k, mm^2/N (None: not fitted).
    pub k_fitted: Option<f64>,
    /// The grind's prediction at the plan's and at the fitted k against the achieved
    /// residual, over the same defect points (removal plans only).
    pub agreement: Option<Agreement>,
    /// Each region's removal shift this iteration's grind measured and the correction the
    /// next plan aims back by there (`cell::removal_shift::carry`); empty when none was
    /// registered or the loop stopped on it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub shifts: Vec<CarriedShift>,
    /// Why the loop stopped at this inspection when the stop rule did not say it alone: the
    /// registration's line (`Outcome::OffPlan`) or the failed plan's (`Outcome::PlanFailed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stopped: Option<String>,
}

impl IterationRecord {
    /// A record of a fresh inspection (nothing planned yet).
    pub fn new(iteration: usize, measured: Measured) -> IterationRecord {
        IterationRecord {
            iteration,
            measured,
            planned_regions: Vec::new(),
            planned_volume_mm3: None,
            predicted_residual_mm: None,
            achieved_residual_mm: None,
            progress: None,
            k_fitted: None,
            agreement: None,
            shifts: Vec::new(),
            stopped: None,
        }
    }

    /// Records the plan made from this inspection.
    pub fn planned(&mut self, inspection: &Inspection, plan: &Plan) {
        let ids = planned_regions(plan);
        let volume = inspection
            .regions
            .iter()
            .filter(|r| r.repairable && ids.contains(&r.id))
            .map(|r| r.volume)
            .sum();
        self.planned_volume_mm3 = Some(volume);
        self.planned_regions = ids;
        self.predicted_residual_mm = predicted_rms(plan);
    }

    /// Records what the next inspection found: the progress share of the planned excess
    /// volume and the achieved residual over the planned regions' core points (`pair`: this
    /// inspection's and the next one's, matched).
    pub fn followed_by(&mut self, next: &Measured, pair: &GrindPair) {
        if let Some(planned) = self.planned_volume_mm3.filter(|v| *v > 0.0) {
            self.progress = Some((self.measured.volume_mm3 - next.volume_mm3) / planned);
        }
        let ids: Vec<i64> = self.planned_regions.iter().map(|&i| i as i64).collect();
        self.achieved_residual_mm = achieved_residual(pair, &ids);
    }
}

/// RMS of `pair.after`'s distance over `pair.before`'s core points of the regions `ids` that
/// have a partner there; None when no point matched.
pub fn achieved_residual(pair: &GrindPair, ids: &[i64]) -> Option<f64> {
    let d: Vec<f64> = (pair.before.points.iter().enumerate())
        .filter(|(_, p)| ids.contains(&p.region))
        .filter_map(|(i, _)| pair.partner(i))
        .map(|j| pair.after.points[j].distance)
        .filter(|d| d.is_finite())
        .collect();
    rms(&d)
}

/// How the loop ended, or that it goes on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Grind again.
    Continue,
    /// The last inspection's verdict is "within tolerance" (the decision rule proves it).
    WithinTolerance,
    /// The last inspection's verdict is "undecided": no region is evidence of a defect, but
    /// the decision rule does not prove the part within tolerance (non-conform points too
    /// few for a region, or too much of the area undecided): rescan, do not grind.
    Undecided,
    /// No repairable region is left but the part is not within tolerance (pits, or an
    /// incomplete verdict): grinding cannot help.
    NothingToGrind,
    /// The plan grinds none of the repairable regions (all out of the arm's reach).
    NothingPlanned,
    /// The last grind removed less than `min_progress` of the planned excess volume.
    NoProgress,
    /// `max_iterations` grinds were made and the part is not within tolerance.
    MaxIterations,
    /// The last grind's removal landed off its plan (`removal_shift::carry`; the loop printed
    /// the region and its shift, the last record's `stopped` holds it): no grind on a wrong
    /// model.
    OffPlan,
    /// The next grind's plan failed (its own checks refused it; the last record's `stopped`
    /// names the failure): the part stays as last measured.
    PlanFailed,
    /// Before the first grind, the arm contradicted the cell's calibration (its loaded
    /// touch-offs against servos.toml's `[compliance]`; the last record's `stopped` holds the
    /// measured scatter): nothing was ground.
    ArmMismatch,
}

impl Outcome {
    /// One line for the user.
    pub fn describe(&self) -> &'static str {
        match self {
            Outcome::Continue => "continue",
            Outcome::WithinTolerance => "within tolerance",
            Outcome::Undecided => {
                "stopped: undecided under ISO 14253-1 (no region is a proven defect, but the \
                 part is not proven within tolerance): rescan at a higher resolution"
            }
            Outcome::NothingToGrind => {
                "not finished: no repairable region left (pits remain: the part is rejected)"
            }
            Outcome::NothingPlanned => "not finished: the plan reaches none of the regions",
            Outcome::NoProgress => "not finished: no progress (less removed than --min-progress)",
            Outcome::MaxIterations => "not finished: --max-iterations reached",
            Outcome::OffPlan => {
                "stopped: the last grind's removal landed off its plan (region and shift above)"
            }
            Outcome::PlanFailed => {
                "stopped: the next grind's plan failed (the failure above); the part is as last \
                 measured"
            }
            Outcome::ArmMismatch => {
                "stopped before grinding: the arm contradicts the cell's calibration (measured \
                 above); calibrate this arm (calibrate compliance) and run again"
            }
        }
    }
}

/// The stop rule, applied after each inspection. `records` are the loop's inspections in
/// order; every record but the last was planned and ground (and followed by the next).
/// Order: within tolerance; undecided (the verdict's decision rule, ISO 14253-1: nothing
/// proven to grind, nothing proven conform); nothing repairable left; the last grind's progress
/// under `min_progress`; `max_iterations` grinds made; else grind again.
pub fn decide(records: &[IterationRecord], cfg: &CycleConfig) -> Outcome {
    let Some(last) = records.last() else {
        return Outcome::Continue;
    };
    if last.measured.verdict == Verdict::WithinTolerance {
        return Outcome::WithinTolerance;
    }
    if last.measured.verdict == Verdict::Undecided {
        return Outcome::Undecided;
    }
    if last.measured.repairable == 0 {
        return Outcome::NothingToGrind;
    }
    let grinds = records.len() - 1;
    if let Some(prev) = grinds.checked_sub(1).map(|i| &records[i]) {
        if prev.progress.is_none_or(|p| p < cfg.min_progress) {
            return Outcome::NoProgress;
        }
    }
    if grinds >= cfg.max_iterations {
        return Outcome::MaxIterations;
    }
    Outcome::Continue
}

/// After planning the last record: [`Outcome::NothingPlanned`] when the plan grinds no
/// excess volume, else [`Outcome::Continue`].
pub fn decide_plan(record: &IterationRecord) -> Outcome {
    match record.planned_volume_mm3 {
        Some(v) if v > 0.0 => Outcome::Continue,
        _ => Outcome::NothingPlanned,
    }
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.digits$}"))
}

/// Columns of the table.
const COLUMNS: usize = 12;

/// The table's header cells.
pub const TABLE_HEADER: [&str; COLUMNS] = [
    "iter",
    "verdict",
    "regions (pits)",
    "peak mm",
    "RMS mm",
    "volume mm3",
    "ISO conform/non/undecided",
    "removed %",
    "residual pred/achieved mm",
    "defect pts: pred k0/pred k fit/achieved (fit-achieved) mm",
    "lowest ground mm",
    "k mm2/N",
];

/// The agreement cell: the RMS residuals over the same defect points, predicted at the
/// plan's k, at the fitted k and achieved, and the point-by-point RMS difference.
fn agreement_cell(a: Option<&Agreement>) -> String {
    a.map_or("-".into(), |a| {
        format!(
            "{:.4}/{}/{:.4} ({:.4})",
            a.predicted_plan_k_mm,
            opt(a.predicted_fitted_k_mm, 4),
            a.achieved_mm,
            a.difference_mm
        )
    })
}

/// The table's cells of one record.
pub fn table_row(r: &IterationRecord) -> [String; COLUMNS] {
    let m = &r.measured;
    let verdict = serde_json::to_value(m.verdict)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    [
        r.iteration.to_string(),
        verdict,
        format!("{} ({})", m.repairable, m.pits),
        opt(m.peak_mm, 4),
        opt(m.rms_mm, 4),
        format!("{:.4}", m.volume_mm3),
        format!(
            "{}/{}/{}",
            m.decision.conform, m.decision.nonconform, m.decision.undecided
        ),
        opt(r.progress.map(|p| 100.0 * p), 1),
        format!(
            "{} / {}",
            opt(r.predicted_residual_mm, 4),
            opt(r.achieved_residual_mm, 4)
        ),
        agreement_cell(r.agreement.as_ref()),
        opt(r.agreement.map(|a| a.lowest_ground_mm), 4),
        r.k_fitted
            .map_or("not fitted".into(), |k| format!("{k:.3e}")),
    ]
}

/// The table as aligned text, one line per record.
pub fn table_text(records: &[IterationRecord]) -> String {
    let rows: Vec<[String; COLUMNS]> = records.iter().map(table_row).collect();
    let mut width = TABLE_HEADER.map(str::len);
    for row in &rows {
        for (w, c) in width.iter_mut().zip(row) {
            *w = (*w).max(c.len());
        }
    }
    let line = |cells: &[String]| {
        let padded: Vec<String> = cells
            .iter()
            .zip(&width)
            .map(|(c, w)| format!("{c:>w$}"))
            .collect();
        padded.join("  ") + "\n"
    };
    let mut text = line(&TABLE_HEADER.map(str::to_string));
    for row in &rows {
        text.push_str(&line(row));
    }
    text
}

/// `cycle.json`: how the loop ended and every record (what the table shows, in full).
pub fn table_json(records: &[IterationRecord], outcome: Outcome) -> serde_json::Value {
    serde_json::json!({"format": "polishbot-cycle", "version": 1, "outcome": outcome,
        "records": records})
}

/// `cycle.html`: the table and the outcome, plain HTML without scripts.
pub fn table_html(records: &[IterationRecord], outcome: Outcome) -> String {
    let rows: Vec<Vec<String>> = records.iter().map(|r| table_row(r).to_vec()).collect();
    let why = (records.last().and_then(|r| r.stopped.as_deref())).map_or(String::new(), |w| {
        format!(" Stopped because {}.", escape(w))
    });
    let paragraphs = [
        format!("Outcome: {}.{why}", escape(outcome.describe())),
        "Each row is the inspection that began iteration k (folder iter-k); removed % and the \
         achieved residual come from the next inspection. The defect points' column re-predicts \
         the grind with the k fitted after it (the plan's removal x fitted k / plan's k) and \
         compares it with the achieved residual at the same points; lowest ground is the next \
         inspection's lowest distance where the plan ground."
            .to_string(),
        format!(
            "The verdict and the ISO column follow {}; within tolerance needs no non-conform \
             point and at most {:.1} % of the measured area undecided.",
            escape(crate::regions::decision::RULE),
            100.0 * crate::regions::MAX_UNDECIDED_SHARE
        ),
    ];
    table_page(
        "polishbot cycle",
        &TABLE_HEADER.map(str::to_string),
        &rows,
        &paragraphs,
    )
}

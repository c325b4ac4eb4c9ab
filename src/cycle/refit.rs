//! Preston's k refitted from grinds: `calibrate removal` fits it from the files of one grind
//! ([`fit_files`]); the loop ([`refit`]) from the grinds it made, held in memory, pooled
//! (`removal::fit::pool`) on the prediction moved by each region's measured shift
//! (`cell::removal_shift`). Either writes the fitted k into a copy of the tool file.
use std::path::{Path, PathBuf};

use anyhow::Context;

use super::plan_stage::Planned;
use crate::calibrate::files;
use crate::cell::removal_reach::{self, ReachConfig};
use crate::cell::removal_shift::{self, CarriedShift, RegionShift, ShiftConfig};
use crate::cell::stray;
use crate::motion::aim::Aim;
use crate::motion::Plan;
use crate::removal::fit::{self, Agreement, Evidence, FitConfig, GrindPair, RemovalFit};
use crate::removal::ToolModel;
use crate::repair::Inspection;
use crate::robot::ToolText;

/// What `calibrate removal` reads.
#[derive(Debug, Clone)]
pub struct RefitInputs {
    /// Inspection before the grind (the one the plan was made from).
    pub before: PathBuf,
    /// Inspection of the rescan after the grind.
    pub after: PathBuf,
    /// The plan that was ground (removal mode; predicted.csv beside it).
    pub plan: PathBuf,
    /// The tool file the fit is written from (a plan without a recorded k also takes its k
    /// from it).
    pub tool: PathBuf,
}

/// Fits k from the files of `inputs`, on the prediction moved by each region's registered
/// shift (`removal_shift`); every refusal is one line naming the file.
pub fn fit_files(inputs: &RefitInputs, cfg: &FitConfig) -> anyhow::Result<RemovalFit> {
    let before = Inspection::load(&inputs.before)?;
    let (predicted, plan_k) = prediction(&inputs.plan, &inputs.tool, &before)?;
    let after = Inspection::load(&inputs.after)?;
    let pair = GrindPair::new(&before, &after);
    // k after the shift of where the tool really ground (issue 50)
    let shift_cfg = ShiftConfig::default();
    let shifts = removal_shift::register(&pair, &predicted, &shift_cfg);
    let predicted = removal_shift::shifted_prediction(&before, &predicted, &shifts, &shift_cfg);
    fit::fit(&pair, &predicted, plan_k, cfg).map_err(|m| in_folders(inputs, m))
}

/// The plan's predicted removal per core point of `before` (predicted.csv beside the removal
/// plan `plan`, at the plan's k) and that k: the one plan.json's provenance records
/// (`config.removal_tool.preston_k_mm2_n`), so that a tool file already rewritten by an
/// earlier fit does not scale the prediction again; the tool file `tool` only for a plan
/// without that record.
pub fn prediction(
    plan: &Path,
    tool: &Path,
    before: &Inspection,
) -> anyhow::Result<(Vec<f64>, f64)> {
    let plan_text = std::fs::read_to_string(plan)
        .with_context(|| format!("{}: cannot read", plan.display()))?;
    let loaded = Plan::parse(plan, &plan_text)?;
    ensure_removal(plan, &loaded)?;
    let csv = plan.with_file_name("predicted.csv");
    let text = std::fs::read_to_string(&csv)
        .with_context(|| format!("{}: cannot read (written beside plan.json)", csv.display()))?;
    let recorded = serde_json::from_str::<serde_json::Value>(&plan_text)?["provenance"]["config"]
        ["removal_tool"]["preston_k_mm2_n"]
        .as_f64();
    let tool_k = || Ok(ToolModel::load(tool)?.preston_k_mm2_n);
    predicted_at_k(plan, &text, recorded, &tool_k, before)
}

/// [`prediction`] of a plan the loop made and holds (`planned`, written to `plan`; its tool
/// file as held).
pub fn prediction_of(
    plan: &Path,
    planned: &Planned,
    before: &Inspection,
) -> anyhow::Result<(Vec<f64>, f64)> {
    ensure_removal(plan, &planned.plan)?;
    let csv = planned.predicted_csv.as_deref().unwrap_or_default();
    let recorded = planned.removal_tool.as_ref().map(|t| t.preston_k_mm2_n);
    let tool_k = || Ok(ToolModel::of_text(&planned.tool)?.preston_k_mm2_n);
    predicted_at_k(plan, csv, recorded, &tool_k, before)
}

/// Refuses a rigid plan (`plan` its file): k is fitted against a removal plan's prediction.
fn ensure_removal(plan: &Path, loaded: &Plan) -> anyhow::Result<()> {
    anyhow::ensure!(
        loaded.removal.is_some(),
        "{}: no `removal` prediction (a rigid plan): k is fitted against a plan made with \
         --mode removal",
        plan.display()
    );
    Ok(())
}

/// The prediction of predicted.csv's text `csv` (beside `plan`) per core point of `before`
/// and the plan's k: `recorded` (plan.json's), else the tool file's (`tool_k`).
fn predicted_at_k(
    plan: &Path,
    csv: &str,
    recorded: Option<f64>,
    tool_k: &dyn Fn() -> anyhow::Result<f64>,
    before: &Inspection,
) -> anyhow::Result<(Vec<f64>, f64)> {
    let csv_file = plan.with_file_name("predicted.csv");
    let rows =
        fit::parse_predicted(csv).map_err(|m| anyhow::anyhow!("{}: {m}", csv_file.display()))?;
    let k = match recorded {
        Some(k) if k.is_finite() && k > 0.0 => k,
        Some(k) => anyhow::bail!(
            "{}: provenance.config.removal_tool.preston_k_mm2_n {k:.4e} is not a positive k",
            plan.display()
        ),
        None => tool_k()?,
    };
    let predicted = fit::predicted_removal(before, &rows)
        .map_err(|m| anyhow::anyhow!("{}: {m}", csv_file.display()))?;
    Ok((predicted, k))
}

/// One grind's evidence (`removal::fit::evidence`) from inspections already read from
/// `inputs`' folders and matched (`pair`); the refusal names both folders.
pub fn evidence_loaded(
    inputs: &RefitInputs,
    pair: &GrindPair,
    predicted: &[f64],
    plan_k: f64,
    cfg: &FitConfig,
) -> anyhow::Result<Evidence> {
    fit::evidence(pair, predicted, plan_k, cfg).map_err(|m| in_folders(inputs, m))
}

/// `removal::fit`'s refusal `m` prefixed with the two inspection folders of `inputs`.
fn in_folders(inputs: &RefitInputs, m: String) -> anyhow::Error {
    anyhow::anyhow!(
        "{} -> {}: {m}",
        inputs.before.display(),
        inputs.after.display()
    )
}

/// Reads the tool file `input` (`calibrate removal`'s) to write a fit from.
pub fn read_tool(input: &Path) -> anyhow::Result<ToolText> {
    let text = std::fs::read_to_string(input)
        .with_context(|| format!("{}: cannot read", input.display()))?;
    Ok(ToolText {
        path: input.to_path_buf(),
        text,
    })
}

/// Writes `out` from the tool file `input` (held) with the fit's `[removal] preston_k_mm2_n`
/// and `preston_k_rel_sd` (`RemovalFit::k_rel_sd`, at most 1, the key's range) (two lines
/// changed, comments kept), checks the text written through the planner's loader (in memory)
/// and returns it.
pub fn write_fit(input: &ToolText, out: &Path, fit: &RemovalFit) -> anyhow::Result<ToolText> {
    let (k, sd) = (fit.k_mm2_n, fit.k_rel_sd().min(1.0));
    let set = [("preston_k_mm2_n", k), ("preston_k_rel_sd", sd)];
    let written = ToolText {
        path: out.to_path_buf(),
        text: files::patch_removal(&input.text, &set),
    };
    files::write(out, &written.text)?;
    let back = ToolModel::of_text(&written)?;
    anyhow::ensure!(
        back.preston_k_mm2_n == k && back.preston_k_rel_sd == sd,
        "{}: preston_k_mm2_n, preston_k_rel_sd read back as {}, {}; wrote {k}, {sd}",
        out.display(),
        back.preston_k_mm2_n,
        back.preston_k_rel_sd
    );
    Ok(written)
}

/// The fit in lines for the user, each starting with `label`.
pub fn describe(fit: &RemovalFit, label: &str) -> Vec<String> {
    let per: Vec<String> = fit
        .regions
        .iter()
        .map(|r| format!("{} {:.3e} ({} pts)", r.region, r.k_mm2_n, r.points))
        .collect();
    vec![
        format!(
            "{label}: k {:.4e} +- {:.2e} mm^2/N (plan's {:.4e}, x {:.3}) from {} \
             defect points ({} unmatched); fit residual RMS {:.4} mm; measured mean removal \
             {:.4} mm, predicted {:.4} mm at the plan's k; k varies {:.1} % from point to point \
             over a measurement noise of {:.4} mm and {:.1} % between regions (the next plan's k \
             uncertainty {:.1} %)",
            fit.k_mm2_n,
            fit.k_std_error_mm2_n,
            fit.plan_k_mm2_n,
            fit.k_mm2_n / fit.plan_k_mm2_n,
            fit.points,
            fit.unmatched,
            fit.residual_rms_mm,
            fit.measured_mean_mm,
            fit.predicted_mean_mm,
            100.0 * fit.k_local_rel_sd,
            fit.noise_mm,
            100.0 * fit.k_region_rel_sd,
            100.0 * fit.k_rel_sd()
        ),
        format!(
            "{label}: k per region [mm^2/N]: {}",
            if per.is_empty() {
                "none with enough points".into()
            } else {
                per.join(", ")
            }
        ),
    ]
}

/// What a grind of the loop was made from: its inspection (in memory, its folder in
/// `inspection.dir`), its plan (file and what was written, with the tool file it was made with).
pub struct PlannedGrind {
    /// The inspection the plan was made from.
    pub inspection: Inspection,
    /// plan.json.
    pub plan_file: PathBuf,
    /// The plan as made and written.
    pub planned: Planned,
}

/// What [`refit`] found after a grind.
pub struct Refitted {
    /// The fitted k, or None with the reason printed (a rigid plan, too little evidence).
    pub k: Option<f64>,
    /// The grind's prediction against the achieved residual (None for a rigid plan).
    pub agreement: Option<Agreement>,
    /// The registration's reason to stop (`removal_shift::carry`), or None.
    pub off_plan: Option<String>,
    /// Each registered region's measured and carried shift (empty when stopped or rigid).
    pub shifts: Vec<CarriedShift>,
    /// What cycle.html draws: the plan's unshifted prediction per core point of the
    /// inspection before the grind, and each region's measured shift (None for a rigid plan).
    pub seen: Option<(Vec<f64>, Vec<RegionShift>)>,
    /// The grind's prediction per core point of the inspection before it, moved by each
    /// region's measured shift, and the k its plan was made with (None for a rigid plan): what
    /// the loop's removal ledger enters (`cycle::ledger`).
    pub moved: Option<(Vec<f64>, f64)>,
}

/// Refits k after the last grind from the points of every grind so far (`pooled`, which this
/// grind's points join; `removal::fit::pool`) and, when the fit holds, writes DIR/tool.toml
/// with it and makes it (held in memory) the `tool` of the next plan; re-predicts the grind
/// with the fitted k over the defect points of the regions `ids` against the `after`
/// inspection (its folder, and its core points matched once to those of `before.inspection`,
/// `pair.before`). k is fitted on the prediction moved by each region's measured shift; the
/// shift is carried into `aim`, the next plan's, unless the registration stops the loop
/// (`removal_shift::carry`, the grind's plan aimed by `aim`). Also hands back what cycle.html
/// draws ([`Refitted::seen`]).
pub fn refit(
    before: &PlannedGrind,
    (after, pair): (&Path, &GrindPair),
    ids: &[i64],
    dir: &Path,
    (tool, aim): (&mut Option<ToolText>, &mut Aim),
    pooled: &mut Vec<Evidence>,
) -> Refitted {
    debug_assert!(std::ptr::eq(pair.before, &before.inspection));
    let inputs = RefitInputs {
        before: before.inspection.dir.clone(),
        after: after.to_path_buf(),
        plan: before.plan_file.clone(),
        tool: before.planned.tool.path.clone(),
    };
    let written = dir.join("tool.toml");
    let prediction = prediction_of(&before.plan_file, &before.planned, &before.inspection);
    let shift_cfg = ShiftConfig::default();
    let (mut off_plan, mut carried) = (None, Vec::new());
    let mut seen = None;
    let prediction = prediction.map(|(p, k)| {
        let shifts = removal_shift::register(pair, &p, &shift_cfg);
        shifts
            .iter()
            .for_each(|r| println!("{}", describe_shift(r)));
        match removal_shift::carry(&shifts, aim, &shift_cfg) {
            Ok(next) => {
                print_carried(&next);
                (*aim, carried) = (next.aim, next.regions);
                carry_reach(pair, &p, aim);
            }
            Err(why) => off_plan = Some(why),
        }
        let moved = removal_shift::shifted_prediction(&before.inspection, &p, &shifts, &shift_cfg);
        if let (None, Some(s)) = (&off_plan, stray::stray(pair, &moved, &shift_cfg)) {
            off_plan = Some(stray::describe(&s, &shift_cfg));
        }
        seen = Some((p, shifts));
        (moved, k)
    });
    let fitted = prediction.as_ref().map_err(clone_error).and_then(|(p, k)| {
        let cfg = FitConfig::default();
        let grind = evidence_loaded(&inputs, pair, p, *k, &cfg)?;
        pooled.push(grind);
        let fit = fit_pooled(pooled, &cfg)?;
        let text = write_fit(&before.planned.tool, &written, &fit)?;
        Ok((fit.k_mm2_n, text))
    });
    let k = match fitted {
        Ok((k, text)) => {
            println!("cycle: the next plan uses k from {}", written.display());
            *tool = Some(text);
            Some(k)
        }
        Err(e) => {
            println!(
                "cycle: k not refitted ({}); the next plan keeps {}",
                one_line(&e),
                before.planned.tool.path.display()
            );
            None
        }
    };
    let agreement = prediction
        .as_ref()
        .ok()
        .and_then(|(p, plan_k)| fit::agreement(pair, p, k.map(|k| k / plan_k), ids));
    Refitted {
        k,
        agreement,
        off_plan,
        seen,
        shifts: carried,
        moved: prediction.ok(),
    }
}

/// Reads how far beyond the grind's predicted footprint (`predicted`, per core point of
/// `pair.before`) its removal reached (`removal_reach::measure`) and carries into `aim` the largest
/// reach of the loop's grinds so far: a later grind removes less and may read a shorter reach
/// than its removal had (0 mm in 4 of 16 grinds 2-3 of the int13 survey where the truth
/// reached 0.75-1.75 mm), while the first grind's reading never fell short of the truth.
/// Nothing read (too thin a far field): the aim keeps what it carried.
fn carry_reach(pair: &GrindPair, predicted: &[f64], aim: &mut Aim) {
    let Some(r) = removal_reach::measure(pair, predicted, &ReachConfig::default()) else {
        println!("cycle: the removal's reach beyond the plan's footprint not read (far field)");
        return;
    };
    let carried = aim.reach_mm.map_or(r.reach_mm, |was| was.max(r.reach_mm));
    println!(
        "cycle: the removal reached {:.2} mm beyond the plan's predicted footprint (far field \
         {:.4} +- {:.4} mm); the next plan's landing margin is at least {carried:.2} mm",
        r.reach_mm, r.far_mm[0], r.far_mm[1]
    );
    aim.reach_mm = Some(carried);
}

/// Prints the correction the next plan aims by.
fn print_carried(c: &removal_shift::Carried) {
    let v = |s: &[f64; 3]| format!("[{:.2}, {:.2}, {:.2}]", s[0], s[1], s[2]);
    let per: Vec<String> = (c.regions.iter())
        .map(|r| match r.measured_mm {
            Some(_) => format!("{} {}", r.region, v(&r.carried_mm)),
            None => format!("{} {} (not measured: kept)", r.region, v(&r.carried_mm)),
        })
        .collect();
    println!(
        "cycle: the next plan aims back by the removal shift: cell-wide {} mm; per region {}",
        v(&c.aim.common_mm),
        per.join(", ")
    );
}

/// One line on a region's registration for the loop's log.
fn describe_shift(r: &RegionShift) -> String {
    let s = r.shift_mm;
    format!(
        "cycle: region {}: removal shift {:.2} mm [{:.2}, {:.2}, {:.2}], depth scale {:.3} \
         (unshifted {:.3}), residual RMS {:.4} -> {:.4} mm over {} points, {} removed where \
         nothing was planned; {}",
        r.region,
        s.norm(),
        s.x,
        s.y,
        s.z,
        r.scale,
        r.scale_unshifted,
        r.rms_mm[0],
        r.rms_mm[1],
        r.points,
        r.unplanned,
        match r.hidden_share > ShiftConfig::default().hidden_share {
            true => format!(
                "least squares ({:.0} % of the prediction on other regions)",
                100.0 * r.hidden_share
            ),
            false => "first moments".to_string(),
        }
    )
}

/// Prints the last grind's own fit (or why it cannot fit alone, when it has earlier grinds to
/// pool with) and fits k to the points of all grinds in `pooled`, printing that fit with the
/// grinds and points it pooled.
fn fit_pooled(pooled: &[Evidence], cfg: &FitConfig) -> anyhow::Result<RemovalFit> {
    let last = pooled.last().expect("the grind just pushed");
    match fit::pool(std::slice::from_ref(last), cfg) {
        Ok(own) => describe(&own, "cycle: this grind alone")
            .iter()
            .for_each(|line| println!("{line}")),
        // with no earlier grind the pool's refusal below says the same
        Err(m) if pooled.len() > 1 => println!(
            "cycle: this grind alone fits no k ({m}); its {} points join the pool",
            last.points.len()
        ),
        Err(_) => {}
    }
    let fit = fit::pool(pooled, cfg).map_err(|m| anyhow::anyhow!("{m}"))?;
    println!(
        "cycle: k {:.4e} +- {:.2e} mm^2/N pooled over {} grind{} / {} points (x {:.3} of the last \
         plan's {:.4e}); fit residual RMS {:.4} mm; k uncertainty {:.1} % ({:.1} % point to point, {:.1} % between regions)",
        fit.k_mm2_n,
        fit.k_std_error_mm2_n,
        fit.grinds,
        if fit.grinds == 1 { "" } else { "s" },
        fit.points,
        fit.k_mm2_n / fit.plan_k_mm2_n,
        fit.plan_k_mm2_n,
        fit.residual_rms_mm,
        100.0 * fit.k_rel_sd(),
        100.0 * fit.k_local_rel_sd,
        100.0 * fit.k_region_rel_sd
    );
    Ok(fit)
}

/// A copy of `e` (its one-line chain) to hand on while the original is kept.
fn clone_error(e: &anyhow::Error) -> anyhow::Error {
    anyhow::anyhow!("{}", one_line(e))
}

/// Joins an error chain into one line: "outer: inner: root" (a part already in the line is
/// not repeated).
pub fn one_line(err: &anyhow::Error) -> String {
    let parts: Vec<String> = err.chain().map(|e| e.to_string()).collect();
    let mut line = String::new();
    for part in parts {
        if !line.contains(&part) {
            if !line.is_empty() {
                line.push_str(": ");
            }
            line.push_str(&part);
        }
    }
    line.replace('\n', " ")
}

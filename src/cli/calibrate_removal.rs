//! `polishbot calibrate removal --before DIR1 --after DIR2 --plan plan.json [--tool FILE]`:
//! Preston's k fitted from two inspections and the plan ground between them
//! (`removal::fit`), written into tool.toml's `[removal] preston_k_mm2_n` with its
//! uncertainty `preston_k_rel_sd`. No arm is
//! needed. `cycle` collects every grind's points through [`prediction`] and
//! [`evidence_loaded`], pools them and writes k with [`write_fit`].
use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::calibrate::files;
use crate::cell::removal_shift::{self, ShiftConfig};
use crate::motion::{Inspection, Plan};
use crate::removal::fit::{self, Evidence, FitConfig, RemovalFit};
use crate::removal::ToolModel;

/// What `calibrate removal` reads.
#[derive(Debug, Clone)]
pub struct Inputs {
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
pub fn fit_files(inputs: &Inputs, cfg: &FitConfig) -> anyhow::Result<RemovalFit> {
    let before = Inspection::load(&inputs.before)?;
    let (predicted, plan_k) = prediction(&inputs.plan, &inputs.tool, &before)?;
    let after = Inspection::load(&inputs.after)?;
    // k after the shift of where the tool really ground (issue 50)
    let shift_cfg = ShiftConfig::default();
    let shifts = removal_shift::register(&before, &after, &predicted, &shift_cfg);
    let predicted = removal_shift::shifted_prediction(&before, &predicted, &shifts, &shift_cfg);
    fit::fit(&before, &after, &predicted, plan_k, cfg).map_err(|m| in_folders(inputs, m))
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
    anyhow::ensure!(
        loaded.removal.is_some(),
        "{}: no `removal` prediction (a rigid plan): k is fitted against a plan made with \
         --mode removal",
        plan.display()
    );
    let csv = plan.with_file_name("predicted.csv");
    let text = std::fs::read_to_string(&csv)
        .with_context(|| format!("{}: cannot read (written beside plan.json)", csv.display()))?;
    let rows =
        fit::parse_predicted(&text).map_err(|m| anyhow::anyhow!("{}: {m}", csv.display()))?;
    let recorded = serde_json::from_str::<serde_json::Value>(&plan_text)?["provenance"]["config"]
        ["removal_tool"]["preston_k_mm2_n"]
        .as_f64();
    let k = match recorded {
        Some(k) if k.is_finite() && k > 0.0 => k,
        Some(k) => anyhow::bail!(
            "{}: provenance.config.removal_tool.preston_k_mm2_n {k:.4e} is not a positive k",
            plan.display()
        ),
        None => ToolModel::load(tool)?.preston_k_mm2_n,
    };
    let predicted = fit::predicted_removal(before, &rows)
        .map_err(|m| anyhow::anyhow!("{}: {m}", csv.display()))?;
    Ok((predicted, k))
}

/// One grind's evidence (`removal_fit::evidence`) from inspections already read from
/// `inputs`' folders; the refusal names both folders.
pub fn evidence_loaded(
    inputs: &Inputs,
    before: &Inspection,
    after: &Inspection,
    predicted: &[f64],
    plan_k: f64,
    cfg: &FitConfig,
) -> anyhow::Result<Evidence> {
    fit::evidence(before, after, predicted, plan_k, cfg).map_err(|m| in_folders(inputs, m))
}

/// `removal_fit`'s refusal `m` prefixed with the two inspection folders of `inputs`.
fn in_folders(inputs: &Inputs, m: String) -> anyhow::Error {
    anyhow::anyhow!(
        "{} -> {}: {m}",
        inputs.before.display(),
        inputs.after.display()
    )
}

/// Writes `out` from the tool file `input` with the fit's `[removal] preston_k_mm2_n` and
/// `preston_k_rel_sd` (`RemovalFit::k_rel_sd`, at most 1, the key's range) (two lines changed,
/// comments kept) and reads them back through the planner's loader.
pub fn write_fit(input: &Path, out: &Path, fit: &RemovalFit) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(input)
        .with_context(|| format!("{}: cannot read", input.display()))?;
    let (k, sd) = (fit.k_mm2_n, fit.k_rel_sd().min(1.0));
    let set = [("preston_k_mm2_n", k), ("preston_k_rel_sd", sd)];
    files::write(out, &files::patch_removal(&text, &set))?;
    let back = ToolModel::load(out)?;
    anyhow::ensure!(
        back.preston_k_mm2_n == k && back.preston_k_rel_sd == sd,
        "{}: preston_k_mm2_n, preston_k_rel_sd read back as {}, {}; wrote {k}, {sd}",
        out.display(),
        back.preston_k_mm2_n,
        back.preston_k_rel_sd
    );
    Ok(())
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

/// Runs `calibrate removal`: fits, prints, writes `out` (tool.toml) from `inputs.tool`.
pub fn run(inputs: &Inputs, out: &Path) -> anyhow::Result<()> {
    let fit = fit_files(inputs, &FitConfig::default())
        .map_err(|e| anyhow::anyhow!("calibrate removal: {}", super::common::one_line(&e)))?;
    for line in describe(&fit, "calibrate removal") {
        println!("{line}");
    }
    write_fit(&inputs.tool, out, &fit)
        .map_err(|e| anyhow::anyhow!("calibrate removal: {}", super::common::one_line(&e)))?;
    println!("calibrate removal: wrote {}", out.display());
    Ok(())
}

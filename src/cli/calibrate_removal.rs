//! `polishbot calibrate removal --before DIR1 --after DIR2 --plan plan.json [--tool FILE]`:
//! Preston's k fitted from two inspections and the plan ground between them
//! (`removal::fit`), written into tool.toml's `[removal] preston_k_mm2_n` with its
//! uncertainty `preston_k_rel_sd`. No arm is needed. The fit itself is `crate::cycle::refit`'s,
//! which the loop shares.
use std::path::Path;

pub use crate::cycle::refit::Inputs;
use crate::cycle::refit::{describe, fit_files, read_tool, write_fit};
use crate::removal::fit::FitConfig;

/// Runs `calibrate removal`: fits, prints, writes `out` (tool.toml) from `inputs.tool`.
pub fn run(inputs: &Inputs, out: &Path) -> anyhow::Result<()> {
    let fit = fit_files(inputs, &FitConfig::default())
        .map_err(|e| anyhow::anyhow!("calibrate removal: {}", crate::cycle::one_line(&e)))?;
    for line in describe(&fit, "calibrate removal") {
        println!("{line}");
    }
    read_tool(&inputs.tool)
        .and_then(|tool| write_fit(&tool, out, &fit))
        .map_err(|e| anyhow::anyhow!("calibrate removal: {}", crate::cycle::one_line(&e)))?;
    println!("calibrate removal: wrote {}", out.display());
    Ok(())
}

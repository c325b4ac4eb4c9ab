//! `polishbot inspect`: parses the flags and the `--config` file and runs
//! [`inspect::inspect_into`], which writes the files: registration.json, deviations.csv,
//! deviations.ply, regions.json and the report (docs/FORMATS.md).
use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Args;

use super::common::GeometryInput;
use crate::compare::Method;
use crate::inspect::{self, InspectConfig, MAX_REFERENCE_POINTS};

/// Arguments of `inspect` (they override the `--config` file's values).
#[derive(Debug, Args)]
pub struct InspectArgs {
    /// Reference: a mesh (sampled area-uniformly with its facet normals, turned outward) or a
    /// cloud. A cloud's own normals must be unit vectors; they are checked against a propagated
    /// outward orientation (turned round with a notice when they point inward, refused when
    /// mixed). A cloud without normals gets PCA normals of 20 neighbours oriented by
    /// propagation, with a notice.
    #[arg(long)]
    pub reference: PathBuf,
    /// Scan point cloud; several (`--scan A --scan B`, or `--scan A B`) are scans of one part
    /// in several setups: each filtered and registered to the reference on its own, measured
    /// jointly (deviations.ply's `scans` says which supported each core point).
    #[arg(long, required = true, num_args = 1..)]
    pub scan: Vec<PathBuf>,
    /// Output folder.
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Tolerance on |distance|, mm [default: 0.05].
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// M3C2 variant [default: adaptive].
    #[arg(long, value_enum)]
    pub method: Option<Method>,
    /// Registration error for the level of detection, mm [default: the registration's
    /// `registration_error`, 2 × the fine ICP's pose uncertainty on the surface].
    #[arg(long)]
    pub registration_error: Option<f64>,
    /// Skip registration: take scan_to_reference from this JSON file (registration.json or
    /// a synth truth.json).
    #[arg(long)]
    pub pose: Option<PathBuf>,
    /// Core points: a cloud file with outward unit normals, instead of a sample of the
    /// reference.
    #[arg(long)]
    pub core: Option<PathBuf>,
    /// The area to inspect: a mesh or cloud in the reference frame (a part of the
    /// reference); the verdict needs `[regions] min_coverage` (default 95 %) of it measured
    /// [default: the whole reference].
    #[arg(long)]
    pub inspect_area: Option<PathBuf>,
    #[command(flatten)]
    /// Units and format of the inputs.
    pub input: GeometryInput,
}

/// Smallest accepted tolerance, mm: the verdict needs each core point's LoD95 within the
/// tolerance (regions::resolution), and at full density the LoD95 is 0.004-0.013 mm (5-95 %,
/// femoral_dm synth case, 0.015 mm scanner noise), so a tolerance under 0.01 mm leaves no
/// verdict on the cell's scanner; a tolerance of 0 also made every noise point a region
/// (168 regions, a plan past 200 s).
pub const MIN_TOLERANCE_MM: f64 = 0.01;
/// Largest accepted tolerance, mm: 10 mm is a fifth of the part; more is a unit slip.
pub const MAX_TOLERANCE_MM: f64 = 10.0;

/// The settings of a run: the `--config` file (checked: unknown keys, ranges with file, line
/// and key) with the flags `args` over it (none: `cycle`'s inspections).
pub fn settings(
    args: Option<&InspectArgs>,
    file: &super::settings::ConfigFile,
) -> Result<InspectConfig> {
    let mut cfg: InspectConfig = file.parse_strict()?;
    let points = cfg.reference_points as f64;
    let max = MAX_REFERENCE_POINTS as f64;
    super::settings::in_range("reference_points", points, 0.0, max, "points")
        .map_err(|m| file.refuse("", &m))?;
    super::settings::check_filter(file, "filter", &cfg.filter, None)?;
    if let Some(e) = args.and_then(|a| a.registration_error) {
        let max = crate::compare::MAX_LENGTH_MM;
        super::settings::in_range("registration_error", e, 0.0, max, "mm")
            .map_err(|m| anyhow::anyhow!("--registration-error: {m}"))?;
    }
    check_settings(file, &cfg)?;
    if let Some(a) = args {
        anyhow::ensure!(
            a.pose.is_none() || a.scan.len() == 1,
            "--pose gives one scan's pose: with {} scans each is registered, leave --pose out",
            a.scan.len()
        );
    }
    let tolerance = |t: f64| {
        super::settings::in_range("tolerance", t, MIN_TOLERANCE_MM, MAX_TOLERANCE_MM, "mm")
    };
    match args.and_then(|a| a.tolerance) {
        Some(t) => {
            tolerance(t).map_err(|m| anyhow::anyhow!("--tolerance: {m}"))?;
            cfg.regions.tolerance = t;
        }
        None => tolerance(cfg.regions.tolerance).map_err(|m| file.refuse("regions", &m))?,
    }
    if let Some(m) = args.and_then(|a| a.method) {
        cfg.compare.method = m;
    }
    Ok(cfg)
}

/// Largest `[regions] gap_factor`, core-point spacings: 100 spacings (57 mm at the default
/// 0.57 mm) span a femoral component, so beyond it every error point is one region anyway,
/// and the neighbour search's radius grows with it.
pub const MAX_GAP_FACTOR: f64 = 100.0;

/// Checks the `[register]`, `[compare]`, `[regions]`, `[core]` and `[suggest]` settings that
/// need no cloud: a refusal names the file, the line, the table and the key.
fn check_settings(file: &super::settings::ConfigFile, cfg: &InspectConfig) -> Result<()> {
    use super::settings::{above, at_least, in_range};
    let refuse = |section: &'static str| move |m: String| file.refuse(section, &m);
    cfg.register.check().map_err(refuse("register"))?;
    cfg.compare.check().map_err(refuse("compare"))?;
    let r = &cfg.regions;
    let regions = [
        above(
            "gap_factor",
            r.gap_factor,
            0.0,
            MAX_GAP_FACTOR,
            "(spacings)",
        ),
        at_least("min_points", r.min_points, 1, "points"),
        in_range("min_coverage", r.min_coverage, 0.0, 1.0, "(share)"),
    ];
    regions
        .into_iter()
        .try_for_each(|c| c.map_err(refuse("regions")))?;
    let c = &cfg.core;
    let core = [
        at_least("count", c.count.unwrap_or(1), 1, "points"),
        in_range("uniform_ratio", c.uniform_ratio, 0.0, 1.0, "(share)"),
    ];
    core.into_iter()
        .try_for_each(|c| c.map_err(refuse("core")))?;
    let sg = &cfg.suggest;
    let vector = |key: &str, v: [f64; 3]| match v.iter().all(|x| x.is_finite()) && v != [0.0; 3] {
        true => Ok(()),
        false => Err(format!("`{key}` = {v:?} is not a finite non-zero vector")),
    };
    let suggest = [
        vector("table_axis", sg.table_axis),
        vector("scanner_direction", sg.scanner_direction),
        above("max_incidence_deg", sg.max_incidence_deg, 0.0, 90.0, "deg"),
        in_range("step_deg", sg.step_deg, 1.0, 360.0, "deg"),
    ];
    suggest
        .into_iter()
        .try_for_each(|c| c.map_err(refuse("suggest")))
}

/// The library's inputs from the flags.
fn inputs(args: &InspectArgs) -> inspect::Inputs {
    inspect::Inputs {
        reference: inspect::Source::file(&args.reference),
        scan: inspect::Source::file(&args.scan[0]),
        more_scans: args.scan[1..].iter().map(inspect::Source::file).collect(),
        files: inspect::FileInput {
            format: args.input.format,
            units: args.input.units,
        },
        pose: args.pose.clone(),
        core: args.core.clone(),
        inspect_area: args.inspect_area.clone(),
        registration_error: args.registration_error,
        fine_radius: None,
    }
}

/// Runs the inspection, writes its files and prints the summary table.
pub fn run(args: InspectArgs, config: Option<&Path>) -> Result<()> {
    let cfg = settings(Some(&args), &super::settings::ConfigFile::read(config)?)?;
    inspect::inspect_into(&cfg, &inputs(&args), &args.out).map(drop)
}

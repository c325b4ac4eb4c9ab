//! `polishbot inspect`: parses the flags and the `--config` file, runs [`inspect::run`] and
//! writes its files: registration.json, deviations.csv, deviations.ply, regions.json and the
//! report (docs/FORMATS.md).
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde_json::json;

use super::common::GeometryInput;
use crate::cloud::{self, transform, PlyPrecision};
use crate::compare::{self, Method};
use crate::inspect::{self, InspectConfig, PoseSource, MAX_REFERENCE_POINTS};
use crate::regions::{self, Regions};
use crate::register::RegisterError;
use crate::report::{self, provenance::Provenance};

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

fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
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
/// and key) with the flags over it.
fn settings(args: &InspectArgs, config: Option<&Path>) -> Result<InspectConfig> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: InspectConfig = file.parse_strict()?;
    let points = cfg.reference_points as f64;
    let max = MAX_REFERENCE_POINTS as f64;
    super::settings::in_range("reference_points", points, 0.0, max, "points")
        .map_err(|m| file.refuse("", &m))?;
    super::settings::check_filter(&file, "filter", &cfg.filter, None)?;
    if let Some(e) = args.registration_error {
        anyhow::ensure!(
            e.is_finite() && e >= 0.0,
            "--registration-error: {e} mm is not a non-negative number of mm"
        );
    }
    let sg = &cfg.suggest;
    let finite = |v: [f64; 3]| v.iter().all(|x| x.is_finite()) && v != [0.0; 3];
    anyhow::ensure!(
        finite(sg.table_axis) && finite(sg.scanner_direction),
        "[suggest] table_axis and scanner_direction must be finite non-zero vectors"
    );
    anyhow::ensure!(
        sg.max_incidence_deg > 0.0 && sg.max_incidence_deg <= 90.0,
        "[suggest] max_incidence_deg must be in (0, 90]"
    );
    anyhow::ensure!(
        sg.step_deg >= 1.0 && sg.step_deg <= 360.0,
        "[suggest] step_deg must be in 1..=360"
    );
    anyhow::ensure!(
        args.pose.is_none() || args.scan.len() == 1,
        "--pose gives one scan's pose: with {} scans each is registered, leave --pose out",
        args.scan.len()
    );
    let tolerance = |t: f64| {
        super::settings::in_range("tolerance", t, MIN_TOLERANCE_MM, MAX_TOLERANCE_MM, "mm")
    };
    match args.tolerance {
        Some(t) => {
            tolerance(t).map_err(|m| anyhow::anyhow!("--tolerance: {m}"))?;
            cfg.regions.tolerance = t;
        }
        None => tolerance(cfg.regions.tolerance).map_err(|m| file.refuse("regions", &m))?,
    }
    if let Some(m) = args.method {
        cfg.compare.method = m;
    }
    anyhow::ensure!(
        (0.0..=1.0).contains(&cfg.regions.min_coverage),
        "[regions] min_coverage must be a share between 0 and 1, not {}",
        cfg.regions.min_coverage
    );
    Ok(cfg)
}

/// The library's inputs from the flags.
fn inputs(args: &InspectArgs) -> inspect::Inputs {
    inspect::Inputs {
        reference: args.reference.clone(),
        scan: args.scan[0].clone(),
        more_scans: args.scan[1..].to_vec(),
        files: inspect::FileInput {
            format: args.input.format,
            units: args.input.units,
        },
        pose: args.pose.clone(),
        core: args.core.clone(),
        inspect_area: args.inspect_area.clone(),
        registration_error: args.registration_error,
    }
}

/// Runs the inspection, writes its files and prints the summary table.
pub fn run(args: InspectArgs, config: Option<&Path>) -> Result<()> {
    let cfg = settings(&args, config)?;
    inspect_into(&cfg, &inputs(&args), &args.out)
}

/// Runs [`inspect::run`] and writes its files into `out` (created), then prints the summary
/// table; an incomplete verdict is the error [`super::inspect_report::Incomplete`].
pub fn inspect_into(cfg: &InspectConfig, inputs: &inspect::Inputs, out: &Path) -> Result<()> {
    let start = Instant::now();
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let reg_file = out.join("registration.json");
    let files = (inputs.scan.as_path(), inputs.reference.as_path());
    let (found, provenance) = rayon::join(
        || inspect::run(cfg, inputs),
        || super::inspect_report::provenance(cfg, inputs),
    );
    let mut found = match found {
        Ok(found) => found,
        Err(e) => match e.downcast::<RegisterError>() {
            Ok(failed) => {
                let e = super::register::record_failure(failed, &reg_file, files);
                if let Ok(p) = &provenance {
                    // The failure is the error to report; a record without provenance is
                    // still a record.
                    let _ = p.stamp_json(&reg_file);
                }
                return Err(e);
            }
            Err(e) => return Err(e),
        },
    };
    // After the inspection's own errors: it names a missing or unreadable input first.
    let provenance = provenance?;
    for notice in &found.notices {
        eprintln!("{notice}");
    }
    match &found.pose {
        PoseSource::Registered(reg) => super::register::record_ok(reg, &reg_file, files)?,
        PoseSource::Given { pose, source } => write_json(
            &reg_file,
            &json!({
                "status": "given",
                "scan_to_reference": transform::isometry_to_rows(pose),
                "source": source.display().to_string(),
                "fitness": null,
                "inlier_rmse": null,
                "coarse": null,
                "fine": null,
            }),
        )?,
    }
    provenance.stamp_json(&reg_file)?;
    for (k, pose) in found.more_poses.iter().enumerate() {
        let file = out.join(format!("registration_scan{}.json", k + 2));
        if let PoseSource::Registered(reg) = pose {
            let scan = inputs.more_scans[k].as_path();
            super::register::record_ok(reg, &file, (scan, inputs.reference.as_path()))?;
            provenance.stamp_json(&file)?;
        }
    }
    let lines = std::mem::take(&mut found.provenance);
    let support = std::mem::take(&mut found.support);
    let suggestion = found.suggestion.as_ref().map(suggestion_line);
    let written = Written {
        dev: &found.deviations,
        found: &found.regions,
        support: &support,
        unmeasured: suggestion.as_ref().map(|words| report::Unmeasured {
            in_area: found.in_area.as_deref(),
            suggestion: words.clone(),
        }),
    };
    write_outputs(out, written, lines, &provenance)?;
    found.times.lap("files and report");
    print_summary(
        &found.deviations,
        &found.regions,
        start.elapsed().as_secs_f64(),
    );
    println!("times: {}", found.times.line());
    if let Some(words) = &suggestion {
        println!("suggested views: {words}");
    }
    match found.regions.verdict {
        regions::Verdict::Incomplete => Err(super::inspect_report::Incomplete {
            coverage: found.regions.coverage,
            shortfall: found.regions.shortfall,
            min_coverage: found.regions.min_coverage,
        }
        .into()),
        _ => Ok(()),
    }
}

/// What [`write_outputs`] writes: the deviations, the regions and, with several scans, the
/// scans that supported each core point.
struct Written<'a> {
    dev: &'a compare::Deviations,
    found: &'a Regions,
    support: &'a [u32],
    /// With an incomplete verdict, the report's picture of the unmeasured area.
    unmeasured: Option<report::Unmeasured<'a>>,
}

/// Writes deviations.csv, deviations.ply, regions.json and the report, all four at once
/// (formatting is most of their time, and each is single-threaded).
fn write_outputs(
    out: &Path,
    written: Written,
    report_summary: Vec<(String, String)>,
    provenance: &Provenance,
) -> Result<()> {
    let Written {
        dev,
        found,
        support,
        unmeasured,
    } = written;
    let table = compare::to_cloud(dev, &found.labels);
    // deviations.csv keeps its columns (a contract); the PLY also maps what was measured and,
    // with several scans, which supported each row.
    let mut ply_table = table.clone();
    compare::add_coverage_fields(dev, &mut ply_table);
    if !support.is_empty() {
        ply_table.set_field("scans", support.iter().map(|&m| m as f64).collect());
    }
    let write_regions = || -> Result<()> {
        let text = serde_json::to_string_pretty(found)?;
        let path = out.join("regions.json");
        std::fs::write(&path, text).with_context(|| format!("{}: cannot write", path.display()))?;
        provenance.stamp_json(&path)
    };
    let ((csv, ply), (regions, report)) = rayon::join(
        || {
            rayon::join(
                || cloud::write_csv(&out.join("deviations.csv"), &table),
                || {
                    let path = out.join("deviations.ply");
                    cloud::write_ply(&path, &ply_table, None, PlyPrecision::F64)
                },
            )
        },
        || {
            rayon::join(write_regions, || {
                super::inspect_report::write(
                    out,
                    (dev, found),
                    report_summary,
                    provenance,
                    unmeasured,
                )
            })
        },
    );
    csv?;
    ply?;
    regions?;
    report
}

fn print_summary(dev: &compare::Deviations, found: &Regions, seconds: f64) {
    println!(
        "inspect: core points {}, method {:?}, tolerance {} mm, {:.2} s",
        dev.summary(),
        dev.method,
        found.tolerance,
        seconds
    );
    println!(
        "{:>6} {:>10} {:>10} {:>11} {:>7} {:>9}  kind",
        "region", "peak mm", "area mm2", "volume mm3", "points", "measured"
    );
    for r in &found.regions {
        let kind = if r.repairable {
            "excess (repairable)"
        } else {
            "pit (not repairable)"
        };
        println!(
            "{:>6} {:>10} {:>10.3} {:>11.5} {:>7} {:>6.1} %{} {kind}",
            r.id,
            super::inspect_report::peak_text(r),
            r.area,
            r.volume,
            r.points,
            100.0 * r.measured_share,
            super::inspect_report::touch_mark(r),
        );
    }
    if found.regions.iter().any(|r| r.peak_lower_bound) {
        println!("* {}", super::inspect_report::LOWER_BOUND_NOTE);
    }
    if found.regions.iter().any(|r| r.touches_unmeasured) {
        println!("† {}", super::inspect_report::UNMEASURED_NOTE);
    }
    println!("verdict: {}", super::inspect_report::verdict_line(found));
}

/// The suggested views of an incomplete inspection in words (printed after "suggested
/// views: " and under the report's picture of the unmeasured area).
fn suggestion_line(sg: &inspect::suggest::Suggestion) -> String {
    let angles: Vec<String> = sg
        .table_angles
        .iter()
        .map(|(deg, share)| format!("{deg:.0} deg ({:.1} %)", 100.0 * share))
        .collect();
    let here = match angles.is_empty() {
        true => "no table angle of this setup faces it".to_string(),
        false => format!(
            "this setup faces it at table angles {} (where those views exist the part hid it)",
            angles.join(", ")
        ),
    };
    format!(
        "{:.1} % of the area to inspect not measured; {here}; {:.1} % faces \
         no table angle of this setup: scan it in a second setup, the part turned over \
         ([suggest] in --config: table axis and scanner direction)",
        100.0 * sg.unmeasured,
        100.0 * sg.other_setup
    )
}

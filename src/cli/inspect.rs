//! `polishbot inspect`: load -> filter -> register -> compare -> regions; writes
//! registration.json, deviations.csv, deviations.ply and regions.json (docs/FORMATS.md).
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde::{Deserialize, Serialize};

use super::inspect_checks as checks;
use serde_json::json;

use super::GeometryInput;
use crate::cloud::{self, transform, Geometry, PlyPrecision, PointCloud};
use crate::compare::{self, CompareConfig, CoreConfig, Method};
use crate::preprocess::{self, SorConfig};
use crate::regions::{self, RegionConfig, Regions};
use crate::register::RegisterConfig;

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
    /// Scan point cloud.
    #[arg(long)]
    pub scan: PathBuf,
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

/// Settings of `inspect` (TOML `--config`), one section per stage.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct InspectConfig {
    /// Points sampled on a mesh reference (default 400,000 when 0).
    pub reference_points: usize,
    /// Core points.
    pub core: CoreConfig,
    /// Comparison.
    pub compare: CompareConfig,
    /// Regions.
    pub regions: RegionConfig,
    /// Statistical outlier filter of the scan.
    pub filter: SorConfig,
    /// Registration (skipped when --pose is given).
    pub register: RegisterConfig,
}

/// Most points sampled on a mesh reference (`reference_points`): 5 million points and normals
/// are 240 MB, far denser than any scan the comparison meets.
const MAX_REFERENCE_POINTS: usize = 5_000_000;

/// The reference as a cloud with outward normals, and where the normals came from.
fn load_reference(
    path: &Path,
    input: &GeometryInput,
    samples: usize,
) -> Result<(PointCloud, String)> {
    match cloud::load(path, input.format, input.units)?.geometry {
        Geometry::Mesh { mesh, .. } => Ok((
            compare::mesh_reference(&mesh, samples, 1)?,
            format!("{samples} points sampled from the mesh, with its facet normals"),
        )),
        Geometry::Cloud(mut c) if c.normals.is_some() => {
            checks::check_unit_normals(path, "reference", &c)?;
            match checks::orient_outward(path, &mut c)? {
                Some(note) => {
                    eprintln!("inspect: notice: {note}");
                    Ok((c, format!("the reference cloud's own normals, {note}")))
                }
                None => Ok((c, "the reference cloud's own normals".into())),
            }
        }
        Geometry::Cloud(c) => {
            let (c, note) = compare::cloud_reference(c)
                .with_context(|| format!("{}: reference normals", path.display()))?;
            eprintln!(
                "inspect: notice: {}: the reference cloud has no normals: estimated ({note})",
                path.display()
            );
            Ok((c, note))
        }
    }
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
}

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
    if let Some(t) = args.tolerance {
        cfg.regions.tolerance = t;
    }
    if let Some(m) = args.method {
        cfg.compare.method = m;
    }
    anyhow::ensure!(
        cfg.regions.tolerance.is_finite() && cfg.regions.tolerance >= 0.0,
        "--tolerance must be a non-negative number"
    );
    anyhow::ensure!(
        (0.0..=1.0).contains(&cfg.regions.min_coverage),
        "[regions] min_coverage must be a share between 0 and 1, not {}",
        cfg.regions.min_coverage
    );
    // The comparison works to the regions' tolerance (peaks, densification, narrow defects).
    cfg.compare.tolerance = cfg.regions.tolerance;
    Ok(cfg)
}

/// Runs the chain and prints the summary table.
pub fn run(args: InspectArgs, config: Option<&Path>) -> Result<()> {
    let mut cfg = settings(&args, config)?;
    let start = Instant::now();
    let mut times = StageTimes::default();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create", args.out.display()))?;
    let spin = crate::progress::spinner("load");
    let samples = if cfg.reference_points == 0 {
        400_000
    } else {
        cfg.reference_points
    };
    // Both files at once: parsing is single-threaded.
    let (reference, scan) = rayon::join(
        || load_reference(&args.reference, &args.input, samples),
        || cloud::load_cloud(&args.scan, args.input.format, args.input.units),
    );
    let ((reference, reference_note), scan) = (reference?, scan?);
    spin.finish_and_clear();
    times.lap("load");
    // Statistical outlier filter of the scan, then registration (unless the pose is given).
    let sor = preprocess::statistical_outlier_filter(&scan, &cfg.filter)
        .with_context(|| format!("{}", args.scan.display()))?;
    let mut scan = sor.apply(&scan);
    checks::check_sizes((&args.reference, &reference), (&args.scan, &scan))?;
    times.lap("filter");
    let reg_file = args.out.join("registration.json");
    let (pose, reg_error, reg_line) = match &args.pose {
        Some(pose_file) => {
            let pose = checks::read_pose(pose_file)?;
            write_json(
                &reg_file,
                &json!({
                    "status": "given",
                    "scan_to_reference": transform::isometry_to_rows(&pose),
                    "source": pose_file.display().to_string(),
                    "fitness": null,
                    "inlier_rmse": null,
                    "coarse": null,
                    "fine": null,
                }),
            )?;
            (pose, None, format!("pose given in {}", pose_file.display()))
        }
        None => {
            let reg = super::register::register_and_record(
                &scan,
                &reference,
                &cfg.register,
                &reg_file,
                &args.scan,
                &args.reference,
            )?;
            let line = format!(
                "FPFH + MAC + ICP: fitness {:.4}, inlier RMSE {:.4} mm, point-to-plane RMSE {:.4} mm, registration error {:.5} mm, {:.2} s",
                reg.fitness,
                reg.inlier_rmse,
                reg.fine.map_or(f64::NAN, |f| f.plane_rmse),
                reg.registration_error,
                reg.times.total
            );
            // The registration error of the level of detection is the pose's own
            // uncertainty on the surface (`Registration::registration_error`), not a residual
            // RMSE: those hold the scan noise, which the LoD already counts, and the
            // reference's sampling spacing.
            (reg.pose, Some(reg.registration_error), line)
        }
    };
    scan.transform(&pose);
    times.lap("register");
    let mut report_summary = vec![
        ("reference normals".to_string(), reference_note),
        ("registration".to_string(), reg_line),
        (
            "outlier filter".to_string(),
            format!(
                "{} of {} scan points removed",
                sor.removed,
                sor.removed + sor.kept.len()
            ),
        ),
    ];
    cfg.compare.registration_error = args
        .registration_error
        .or(reg_error)
        .unwrap_or(cfg.compare.registration_error);

    let (core, core_line) = select_core(&args, &cfg, &reference, scan.len())?;
    report_summary.push(("core point sample".to_string(), core_line));
    times.lap("core points");
    let dev = compare::compare(&core, &reference, &scan, &cfg.compare)?;
    times.lap("compare");
    let in_area = match &args.inspect_area {
        Some(path) => Some(super::inspect_area::core_points_in(
            path,
            &args.input,
            &dev,
        )?),
        None => None,
    };
    let found = regions::find_regions_in(&dev, &cfg.regions, in_area.as_deref());
    times.lap("regions");
    write_outputs(&args.out, &dev, &found, report_summary)?;
    times.lap("files and report");
    print_summary(&dev, &found, start.elapsed().as_secs_f64());
    println!("times: {}", times.line());
    match found.verdict {
        regions::Verdict::Incomplete => Err(super::inspect_report::Incomplete {
            coverage: found.coverage,
            min_coverage: found.min_coverage,
        }
        .into()),
        _ => Ok(()),
    }
}

/// The core points (from `--core`, or a sample of the reference) and the report's line on
/// them.
fn select_core(
    args: &InspectArgs,
    cfg: &InspectConfig,
    reference: &PointCloud,
    scan_points: usize,
) -> Result<(PointCloud, String)> {
    let core = match &args.core {
        Some(path) => {
            let c = cloud::load_cloud(path, args.input.format, args.input.units)?;
            checks::check_unit_normals(path, "--core file", &c)?;
            compare::core_points(
                &c,
                scan_points,
                &CoreConfig {
                    selection: compare::CoreSelection::All,
                    ..cfg.core.clone()
                },
            )
            .with_context(|| format!("{}", path.display()))?
        }
        None => compare::core_points(reference, scan_points, &cfg.core)?,
    };
    let every_point = args.core.is_none() && core.len() == reference.len();
    if every_point && cfg.compare.method == Method::Adaptive {
        eprintln!(
            "inspect: warning: every one of the {} reference points is a core point: \
             densification has none left to add around a defect's top, so defects narrower \
             than about twice their spacing may be missed; give a denser reference",
            reference.len()
        );
    }
    let line = match (&args.core, every_point) {
        (Some(path), _) => format!("{} from {}", core.len(), path.display()),
        (None, true) => format!("all {} reference points", core.len()),
        (None, false) => format!("{} of {} reference points", core.len(), reference.len()),
    };
    Ok((core, line))
}

/// Writes deviations.csv, deviations.ply, regions.json and the report, all four at once
/// (formatting is most of their time, and each is single-threaded).
fn write_outputs(
    out: &Path,
    dev: &compare::Deviations,
    found: &Regions,
    report_summary: Vec<(String, String)>,
) -> Result<()> {
    let table = compare::to_cloud(dev, &found.labels);
    // deviations.csv keeps its columns (a contract); the PLY also maps what was measured.
    let mut ply_table = table.clone();
    compare::add_coverage_fields(dev, &mut ply_table);
    let write_regions = || -> Result<()> {
        let text = serde_json::to_string_pretty(found)?;
        let path = out.join("regions.json");
        std::fs::write(&path, text).with_context(|| format!("{}: cannot write", path.display()))
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
                super::inspect_report::write(out, dev, found, report_summary)
            })
        },
    );
    csv?;
    ply?;
    regions?;
    report
}

/// Wall time per stage of `inspect`, for the closing `times:` line.
struct StageTimes {
    last: Instant,
    laps: Vec<(&'static str, f64)>,
}

impl Default for StageTimes {
    fn default() -> Self {
        StageTimes {
            last: Instant::now(),
            laps: Vec::new(),
        }
    }
}

impl StageTimes {
    /// Ends the stage `name` now.
    fn lap(&mut self, name: &'static str) {
        let now = Instant::now();
        self.laps
            .push((name, now.duration_since(self.last).as_secs_f64()));
        self.last = now;
    }

    /// "load 0.12 s, filter 0.30 s, ...".
    fn line(&self) -> String {
        let parts: Vec<String> = self
            .laps
            .iter()
            .map(|(name, s)| format!("{name} {s:.2} s"))
            .collect();
        parts.join(", ")
    }
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

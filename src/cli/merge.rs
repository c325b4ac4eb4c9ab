//! `polishbot merge SCAN... -o OUT`: joins turntable range views into one cloud (OUT, mm) and
//! writes the poses, loop closure and axis estimate to OUT with the extension `.json`.
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Deserialize;
use serde_json::json;

use super::common::GeometryInput;
use crate::acquire::{merge_setups, merge_views, MergeConfig, Placement, SetupViews};
use crate::cloud::{self, PlyPrecision};
use crate::register::RegisterConfig;

/// Arguments of `merge` (flags override the `--config` file's values).
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The views, in turntable order.
    #[arg(required = true)]
    pub scans: Vec<PathBuf>,
    /// Output cloud (PLY, mm); the report goes beside it as .json.
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Nominal angle of each view in degrees, "a1,a2,...".
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        conflicts_with = "step"
    )]
    pub angles: Option<Vec<f64>>,
    /// Nominal step between views in degrees (view i at i * step) [default: 360 / views].
    #[arg(long, allow_hyphen_values = true)]
    pub step: Option<f64>,
    /// Table axis "x,y,z" in the views' frame [default: the calibration file's, else estimated
    /// from the first neighbouring pair of views that registers].
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, num_args = 1)]
    pub axis: Option<Vec<f64>>,
    /// A point "x,y,z" on the table axis, mm [default: the calibration file's, else the axis'
    /// point at the height of the first view's centroid].
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, num_args = 1)]
    pub centre: Option<Vec<f64>>,
    /// A saved axis: JSON with `axis` and `centre`, optionally `angle_tolerance` (e.g. an
    /// earlier merge report).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// The table's angle accuracy, degrees (each angle within it of nominal): a match that
    /// corrects a view's rotation from the first view by more than twice it, or spreads the
    /// views' corrections over more than twice it, is rejected [default: the calibration
    /// file's, else 5].
    #[arg(long)]
    pub angle_tolerance: Option<f64>,
    /// Leave out views that cannot be aligned (named in the output) instead of failing.
    #[arg(long)]
    pub skip_bad: bool,
    /// Statistical outlier filter on the joined cloud.
    #[arg(long)]
    pub sor: bool,
    /// Voxel of the joined cloud, mm [default: first view's mean spacing].
    #[arg(long)]
    pub voxel: Option<f64>,
    /// Views of several setups: a JSON file whose `views` list gives each view's `file`
    /// (matched by file name), `setup` (0 = the first) and `nominal_deg` (synth's
    /// turntable.json): each setup is merged about the table on its own, then the setups are
    /// joined by registration onto the first.
    #[arg(long, conflicts_with_all = ["angles", "step"])]
    pub setups: Option<PathBuf>,
    /// With --setups: join each setup through this reference (cloud or mesh) instead of
    /// registering it onto the first setup's cloud.
    #[arg(long, requires = "setups")]
    pub reference: Option<PathBuf>,
    /// Units and format of the views.
    #[command(flatten)]
    pub input: GeometryInput,
}

/// The part of a setups file `merge --setups` reads: per view its file, setup and nominal
/// angle (other fields, such as synth's true angles, are not read).
#[derive(Deserialize)]
struct SetupsFile {
    views: Vec<SetupEntry>,
}

/// One view of a setups file.
#[derive(Deserialize)]
struct SetupEntry {
    file: String,
    #[serde(default)]
    setup: usize,
    nominal_deg: f64,
}

/// The part of a calibration file `merge` reads.
#[derive(Deserialize)]
struct Calibration {
    axis: [f64; 3],
    centre: [f64; 3],
    angle_tolerance: Option<f64>,
}

fn triple(v: &[f64], what: &str) -> Result<[f64; 3]> {
    match v {
        [x, y, z] => Ok([*x, *y, *z]),
        _ => bail!(
            "--{what}: expected 3 comma-separated numbers, got {}",
            v.len()
        ),
    }
}

/// A tolerance must be a positive number of degrees below a half turn.
fn check_tolerance(t: f64, place: &str) -> Result<()> {
    if !(t > 0.0 && t < 180.0) {
        bail!("{place}: angle tolerance {t} deg is not in (0, 180)");
    }
    Ok(())
}

/// Points sampled on a mesh `--reference` (register's default: enough for its coarse stage).
const REFERENCE_SAMPLES: usize = 400_000;

/// Largest accepted distance of the table centre from the views' origin, mm: a scanner sees
/// a few metres at most, so 100 m is a typo or a unit slip (and a centre of 1e300 made the
/// matching run without end).
const MAX_CENTRE_MM: f64 = 1e5;

/// Refuses an axis that is not three finite numbers of non-zero length, or a centre that is
/// not finite or farther than [`MAX_CENTRE_MM`] from the origin; `place` names where it came
/// from (a flag or the calibration file).
fn check_axis_centre(axis: Option<[f64; 3]>, centre: Option<[f64; 3]>, place: &str) -> Result<()> {
    if let Some(a) = axis {
        let norm = a.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(norm.is_finite() && norm > 0.0) {
            bail!("{place}: axis {a:?} is not a finite direction of non-zero length");
        }
    }
    if let Some(c) = centre {
        let far = c.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(far.is_finite() && far <= MAX_CENTRE_MM) {
            bail!(
                "{place}: centre {c:?} mm is not finite or farther than {MAX_CENTRE_MM:.0} mm \
                 from the views' origin (check the unit)"
            );
        }
    }
    Ok(())
}

/// Refuses an angle that is not finite, or two views at one table angle (modulo 360 degrees):
/// two views at one angle cannot be told apart by the turn between them.
fn check_angles(angles: &[f64], place: &str) -> Result<()> {
    if let Some(i) = angles.iter().position(|a| !a.is_finite()) {
        bail!(
            "{place}: view {i}: angle {} is not a finite number of degrees",
            angles[i]
        );
    }
    for i in 0..angles.len() {
        for j in i + 1..angles.len() {
            let d = (angles[j] - angles[i]).rem_euclid(360.0);
            if d.min(360.0 - d) < 1e-6 {
                bail!(
                    "{place}: views {i} and {j} are both at {} deg (modulo 360): each view needs \
                     its own table angle",
                    angles[i]
                );
            }
        }
    }
    Ok(())
}

fn read_calibration(path: &Path) -> Result<Calibration> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a calibration", path.display()))
}

/// Merges the views and writes the cloud and the report.
pub fn run(args: MergeArgs, config: Option<&Path>) -> Result<()> {
    let mut cfg: MergeConfig = super::common::load_config(config)?;
    if let Some(c) = config {
        check_tolerance(
            cfg.angle_tolerance,
            &format!("{}: angle_tolerance", c.display()),
        )?;
    }
    if let Some(path) = &args.calibration {
        let c = read_calibration(path)?;
        check_axis_centre(Some(c.axis), Some(c.centre), &path.display().to_string())?;
        cfg.axis = Some(c.axis);
        cfg.centre = Some(c.centre);
        if let Some(t) = c.angle_tolerance {
            cfg.angle_tolerance = t;
            check_tolerance(t, &format!("{}: angle_tolerance", path.display()))?;
        }
    }
    if let Some(t) = args.angle_tolerance {
        check_tolerance(t, "--angle-tolerance")?;
        cfg.angle_tolerance = t;
    }
    if let Some(a) = &args.axis {
        cfg.axis = Some(triple(a, "axis")?);
    }
    if let Some(c) = &args.centre {
        cfg.centre = Some(triple(c, "centre")?);
    }
    let place = config.map_or("--axis/--centre".to_string(), |c| {
        format!("{} or --axis/--centre", c.display())
    });
    check_axis_centre(cfg.axis, cfg.centre, &place)?;
    cfg.skip_bad |= args.skip_bad;
    cfg.sor |= args.sor;
    cfg.voxel = args.voxel.or(cfg.voxel);
    if let Some(file) = &args.setups {
        return run_setups(&args, file, &cfg);
    }
    let n = args.scans.len();
    let angles = match &args.angles {
        Some(a) if a.len() != n => bail!("--angles has {} values for {n} views", a.len()),
        Some(a) => a.clone(),
        None => {
            let step = args.step.unwrap_or(360.0 / n as f64);
            (0..n).map(|i| i as f64 * step).collect()
        }
    };
    check_angles(
        &angles,
        if args.angles.is_some() {
            "--angles"
        } else {
            "--step"
        },
    )?;
    let views = args
        .scans
        .iter()
        .map(|p| cloud::load_cloud(p, args.input.format, args.input.units))
        .collect::<Result<Vec<_>>>()?;
    let names: Vec<String> = args.scans.iter().map(|p| p.display().to_string()).collect();
    let merged = merge_views(&views, &names, &angles, &cfg)?;
    cloud::write_ply(&args.out, &merged.cloud, None, PlyPrecision::F64)?;
    let report_path = args.out.with_extension("json");
    let axis = merged.axis.clone();
    let report = json!({
        "units": "mm",
        "cloud": args.out.display().to_string(),
        "points": merged.cloud.len(),
        "axis": axis.as_ref().map(|a| a.axis),
        "centre": axis.as_ref().map(|a| a.centre),
        "axis_estimate": axis,
        "axis_seed": merged.axis_seed,
        "loop_closure": merged.loop_closure.map(|[r, t]| json!({"rotation_deg": r, "translation_mm": t})),
        "angle_tolerance": merged.angle_tolerance,
        "global": merged.global,
        "skipped": merged.skipped,
        "voxel": merged.voxel,
        "joined_points": merged.joined_points,
        "times": merged.times,
        "views": merged.views,
    });
    std::fs::write(&report_path, serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("{}: cannot write", report_path.display()))?;
    let closure = merged
        .loop_closure
        .map_or("no full turn".to_string(), |[r, t]| {
            format!("loop closure {r:.4} deg {t:.4} mm")
        });
    let axis_text = axis.map_or("axis not estimated".to_string(), |a| {
        format!(
            "axis ({:.4}, {:.4}, {:.4}) through ({:.3}, {:.3}, {:.3}) mm",
            a.axis[0], a.axis[1], a.axis[2], a.centre[0], a.centre[1], a.centre[2]
        )
    });
    println!(
        "merge: {} of {n} views, {} points, {closure}, {axis_text} -> {}",
        merged.views.len(),
        merged.cloud.len(),
        args.out.display()
    );
    if let Some(s) = &merged.axis_seed {
        println!(
            "merge: no axis given; start axis ({:.4}, {:.4}, {:.4}) from {} onto {} \
             (turn {:.3} deg, nominal {:.3})",
            s.axis[0], s.axis[1], s.axis[2], s.pair[0], s.pair[1], s.turn_deg, s.nominal_deg
        );
    }
    for s in &merged.skipped {
        println!("merge: skipped {s} (could not be aligned)");
    }
    print_views(&merged);
    Ok(())
}

/// The setup and nominal angle of each of `scans` from the setups file `path`, the setups in
/// order with their views' indices.
fn read_setups(path: &Path, scans: &[PathBuf]) -> Result<Vec<(Vec<usize>, Vec<f64>)>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let file: SetupsFile = serde_json::from_str(&text).with_context(|| {
        format!(
            "{}: not a setups file (views: file, setup, nominal_deg)",
            path.display()
        )
    })?;
    let mut setups: Vec<(Vec<usize>, Vec<f64>)> = Vec::new();
    for (i, scan) in scans.iter().enumerate() {
        let name = scan.file_name().map(|n| n.to_string_lossy().to_string());
        let entry = file
            .views
            .iter()
            .find(|v| Some(&v.file) == name.as_ref())
            .with_context(|| {
                format!(
                    "{}: no view named {:?} (view {i})",
                    path.display(),
                    name.unwrap_or_default()
                )
            })?;
        if setups.len() <= entry.setup {
            setups.resize_with(entry.setup + 1, Default::default);
        }
        setups[entry.setup].0.push(i);
        setups[entry.setup].1.push(entry.nominal_deg);
    }
    if let Some(k) = setups.iter().position(|s| s.0.is_empty()) {
        bail!("{}: setup {k} has none of the given views", path.display());
    }
    for (k, s) in setups.iter().enumerate() {
        check_angles(&s.1, &format!("{}: setup {k}", path.display()))?;
    }
    Ok(setups)
}

/// `merge --setups`: each setup merged on its own, the setups joined by registration.
fn run_setups(args: &MergeArgs, file: &Path, cfg: &MergeConfig) -> Result<()> {
    let groups = read_setups(file, &args.scans)?;
    let mut setups = Vec::new();
    for (idx, angles) in &groups {
        let names: Vec<String> = idx
            .iter()
            .map(|&i| args.scans[i].display().to_string())
            .collect();
        let views = idx
            .iter()
            .map(|&i| cloud::load_cloud(&args.scans[i], args.input.format, args.input.units))
            .collect::<Result<Vec<_>>>()?;
        setups.push(SetupViews {
            views,
            names,
            angles: angles.clone(),
        });
    }
    let reference = match &args.reference {
        Some(r) => Some(super::common::load_reference(
            r,
            &args.input,
            REFERENCE_SAMPLES,
            1,
        )?),
        None => None,
    };
    let merged = merge_setups(&setups, cfg, reference.as_ref(), &RegisterConfig::default())?;
    cloud::write_ply(&args.out, &merged.cloud, None, PlyPrecision::F64)?;
    let report_path = args.out.with_extension("json");
    let report = json!({
        "units": "mm",
        "cloud": args.out.display().to_string(),
        "points": merged.cloud.len(),
        "voxel": merged.voxel,
        "setups": merged.setups,
        "joins": merged.joins,
    });
    std::fs::write(&report_path, serde_json::to_string_pretty(&report)? + "\n")
        .with_context(|| format!("{}: cannot write", report_path.display()))?;
    for (k, m) in merged.setups.iter().enumerate() {
        println!(
            "merge: setup {}: {} of {} views, {} points",
            k + 1,
            m.views.len(),
            groups[k].0.len(),
            m.cloud.len()
        );
        print_views(m);
    }
    for j in &merged.joins {
        let onto = if j.through_reference {
            "through the reference"
        } else {
            "onto setup 1"
        };
        println!(
            "merge: setup {} joined {onto}: fitness {:.3}, inlier RMSE {:.4} mm",
            j.setup + 1,
            j.fitness,
            j.inlier_rmse
        );
    }
    println!(
        "merge: {} setups, {} points -> {}",
        merged.setups.len(),
        merged.cloud.len(),
        args.out.display()
    );
    Ok(())
}

/// One line per view whose match was rejected or that was held, and the global step.
fn print_views(merged: &crate::acquire::Merged) {
    for v in &merged.views {
        for r in &v.rejected {
            println!(
                "merge: {}: rejected the match from the {} start (correction {:.2} deg, \
                 corrections spanning {:.2} deg; beyond twice the tolerance {} deg; fitness \
                 {:.2})",
                v.name, r.start, r.correction_deg, r.span_deg, merged.angle_tolerance, r.fitness
            );
        }
        if v.placement == Placement::Held {
            println!(
                "merge: {}: no match within twice the tolerance {} deg; held at its predicted \
                 pose (correction {:.2} deg, fitness {:.2})",
                v.name, merged.angle_tolerance, v.correction_deg, v.fitness
            );
        }
    }
    if let Some(g) = &merged.global {
        println!(
            "merge: global step over {} view pairs, {} iterations: RMS {:.4} -> {:.4} mm, \
             largest move {:.4} deg {:.4} mm",
            g.pairs,
            g.iterations,
            g.rms_before_mm,
            g.rms_after_mm,
            g.largest_move[0],
            g.largest_move[1]
        );
    }
}

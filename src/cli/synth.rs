//! `polishbot synth`: writes reference.ply, scan.ply and truth.json.
use std::path::PathBuf;

use clap::Args;

use crate::cloud::Units;
use crate::synth::{synth, SynthConfig, TurntableConfig};

/// Arguments of `synth` (they override the `--config` file's values).
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Use this mesh instead of the parametric femoral component.
    #[arg(long)]
    pub mesh: Option<PathBuf>,
    /// Articular surface of --mesh where defects go (same frame).
    #[arg(long, requires = "mesh")]
    pub surface: Option<PathBuf>,
    /// Unit of --mesh and --surface.
    #[arg(long, value_enum)]
    pub units: Option<Units>,
    /// Random seed [default: 1].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Number of defects [default: 6].
    #[arg(long)]
    pub defects: Option<usize>,
    /// Noise standard deviation per coordinate, mm [default: 0.015].
    #[arg(long, allow_hyphen_values = true)]
    pub noise: Option<f64>,
    /// Outlier share of scan points [default: 0.01].
    #[arg(long, allow_hyphen_values = true)]
    pub outliers: Option<f64>,
    /// Points in reference.ply [default: 400000].
    #[arg(long)]
    pub reference_points: Option<usize>,
    /// Surface points in scan.ply [default: 300000].
    #[arg(long)]
    pub scan_points: Option<usize>,
    /// Defect |height| range in mm, "min,max" [default: 0.04,0.5].
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true)]
    pub height_range: Option<[f64; 2]>,
    /// Defect width (FWHM) range in mm, "min,max" [default: 0.4,3].
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true)]
    pub width_range: Option<[f64; 2]>,
    /// Largest translation of the scan's random pose, mm [default: 60].
    #[arg(long, allow_hyphen_values = true)]
    pub max_translation: Option<f64>,
    /// Also write this many turntable range views (view_000.ply.., turntable.json).
    #[arg(long)]
    pub views: Option<usize>,
    /// Nominal turntable step between views, degrees [default: 360 / views].
    #[arg(long, requires = "views", allow_hyphen_values = true)]
    pub step: Option<f64>,
    /// Largest error of a view's true angle against its nominal one, degrees [default: 3].
    #[arg(long, requires = "views", allow_hyphen_values = true)]
    pub angle_error: Option<f64>,
    /// Points per turntable view [default: 100000].
    #[arg(long, requires = "views")]
    pub view_points: Option<usize>,
    /// Setups of the turntable views: setup k (from 0) has the part tilted by k * 360 / N
    /// degrees about the table's x axis (2: the part turned over), each with --views views;
    /// setup 2's files are setup2_view_000.ply.. [default: 1].
    #[arg(long, requires = "views")]
    pub setups: Option<usize>,
    /// Scanner elevation above the table plane, degrees (the scanner looks from -y, tilted
    /// down by this much) [default: the config's scanner_direction, about 19.3].
    #[arg(long, requires = "views", allow_hyphen_values = true)]
    pub elevation: Option<f64>,
}

/// "min,max" as two numbers (their order and range are checked with the other settings, so
/// that the message names the option and its range).
fn parse_range(s: &str) -> Result<[f64; 2], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|e| format!("{t:?}: {e}")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [a, b] => Ok([*a, *b]),
        _ => Err("expected \"min,max\"".into()),
    }
}

/// Builds the config from file and flags, makes the case and writes it.
pub fn run(args: SynthArgs, config: Option<&std::path::Path>) -> anyhow::Result<()> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: SynthConfig = file.parse()?;
    // the settings given as flags: a refusal of one names its flag, not the config file
    let mut flags = Vec::new();
    macro_rules! set {
        ($($field:ident),*) => {$(if let Some(v) = args.$field {
            cfg.$field = v;
            flags.push(stringify!($field));
        })*};
    }
    set!(
        seed,
        defects,
        noise,
        outliers,
        reference_points,
        scan_points,
        height_range,
        width_range,
        max_translation
    );
    if args.mesh.is_some() {
        cfg.mesh = args.mesh;
        cfg.surface = args.surface;
    }
    if args.units.is_some() {
        cfg.units = args.units;
    }
    if let Some(views) = args.views {
        let t = cfg.turntable.get_or_insert_with(TurntableConfig::default);
        t.views = views;
        t.step_deg = args.step.or(t.step_deg);
        t.angle_error_deg = args.angle_error.unwrap_or(t.angle_error_deg);
        t.points_per_view = args.view_points.unwrap_or(t.points_per_view);
        if let Some(n) = args.setups {
            let turn = 360.0 / n.max(1) as f64;
            t.setup_tilts_deg = (0..n).map(|k| k as f64 * turn).collect();
        }
        if let Some(e) = args.elevation {
            anyhow::ensure!(
                e.is_finite() && e.abs() < 90.0,
                "--elevation: {e:?} deg is not between -90 and 90"
            );
            let e = e.to_radians();
            t.scanner_direction = [0.0, -e.cos(), e.sin()];
        }
    }
    cfg.check().map_err(|m| {
        let key = m.split('`').nth(1).unwrap_or("");
        match flags.contains(&key) {
            true => anyhow::anyhow!("--{}: {m}", key.replace('_', "-")),
            false => file.refuse("", &m),
        }
    })?;
    let case = synth(&cfg)?;
    case.write(&args.out)?;
    let t = &case.truth;
    println!(
        "synth: {} -> {}: reference {} points, scan {} points ({} outliers), {} defects, seed {}",
        t.source,
        args.out.display(),
        t.reference_points,
        t.scan_points,
        t.outliers.scattered.len() + t.outliers.clustered.len(),
        t.defects.len(),
        t.seed
    );
    Ok(())
}

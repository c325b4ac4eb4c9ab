//! `polishbot cycle --reference R --scan S (--sim | --port DEV | --i2c DEV) -o DIR
//! [--max-iterations 3] [--min-progress SHARE]`: inspect, plan, run, rescan, until the part
//! is within tolerance, an iteration makes no progress, or the iterations run out. This file
//! parses the arguments and the settings, runs [`crate::cycle::run_cycle`] and prints how it
//! ended.
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use super::arm::DeviceArgs;
use super::common::GeometryInput;
use super::run::LoopArm;
use super::settings::ConfigFile;
use crate::cycle::{
    run_cycle, table_text, CycleConfig, CycleOutcome, LoopInputs, Outcome, DEFAULT_MAX_ITERATIONS,
    DEFAULT_MIN_PROGRESS,
};
use crate::inspect::{FileInput, Source};
use crate::motion::PlanMode;

/// Exit code of a loop that ended without the part within tolerance (no progress, iterations
/// used up, nothing left the arm can grind); an inspection's incomplete verdict keeps its 3.
pub const NOT_FINISHED_EXIT: u8 = 4;

/// The loop ended without the part within tolerance (exit [`NOT_FINISHED_EXIT`]).
#[derive(Debug)]
pub struct NotFinished(pub Outcome);

impl std::fmt::Display for NotFinished {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cycle: {}", self.0.describe())
    }
}

impl std::error::Error for NotFinished {}

/// Arguments of `cycle`.
#[derive(Debug, Args)]
pub struct CycleArgs {
    /// Reference mesh or cloud (as `inspect --reference`).
    #[arg(long)]
    pub reference: PathBuf,
    /// The first scan of the part.
    #[arg(long)]
    pub scan: PathBuf,
    /// Output folder: iter-1, iter-2, ... and cycle.html.
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Most grinding iterations.
    #[arg(long, default_value_t = DEFAULT_MAX_ITERATIONS)]
    pub max_iterations: usize,
    /// Least share of the planned excess volume an iteration must remove to go on.
    #[arg(long, default_value_t = DEFAULT_MIN_PROGRESS)]
    pub min_progress: f64,
    /// Also read every inspection with classic M3C2 cylinders of this radius, mm, and plan on
    /// that reading (footprint.csv; 0.6, the tool's patch radius, is what was measured:
    /// docs/ALGORITHMS.md, "The loop reads at the tool's footprint") [default: off].
    #[arg(long)]
    pub footprint_radius: Option<f64>,
    /// Plan every grind on the rescans' readings alone, without the removal ledger (from grind
    /// 4 on, each core point read at most at its first reading less the removal the grinds so
    /// far were predicted to make within 1 mm of it: docs/ALGORITHMS.md, "The removal
    /// ledger").
    #[arg(long)]
    pub no_removal_ledger: bool,
    /// Plan mode of every iteration, passed to `plan --mode` [default: plan's].
    #[arg(long, value_enum)]
    pub mode: Option<PlanMode>,
    /// Which arm: --sim (grinds a virtual part and rescans it), or --port DEV / --i2c DEV
    /// (after each run, asks for the next scan file on stdin).
    #[command(flatten)]
    pub device: DeviceArgs,
    /// Units and format of the inputs.
    #[command(flatten)]
    pub input: GeometryInput,
    /// Remove an earlier loop's outputs from the output folder first (its iter-N folders,
    /// cycle.html, cycle.json and the settings files); without it a non-empty output folder
    /// is refused, so that no earlier run's plans and scans sit beside the new ones.
    #[arg(long)]
    pub replace: bool,
}

/// Whether `name`, an entry of the output folder, is one `cycle` writes.
fn is_cycle_output(name: &str) -> bool {
    let iteration = name
        .strip_prefix("iter-")
        .is_some_and(|k| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()));
    iteration
        || ["cycle.html", "cycle.json"].contains(&name)
        || SECTIONS.iter().any(|s| name == format!("{s}.toml"))
}

/// Makes `out` ready for a new loop: created when missing; with `replace` the earlier loop's
/// outputs removed (other files, e.g. the inputs, stay); without it refused when not empty.
fn prepare_out(out: &Path, replace: bool) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let read = |out: &Path| {
        std::fs::read_dir(out)
            .with_context(|| format!("{}: cannot list", out.display()))?
            .map(|e| e.map(|e| e.path()).map_err(anyhow::Error::from))
            .collect::<anyhow::Result<Vec<PathBuf>>>()
    };
    if replace {
        for path in read(out)? {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if !is_cycle_output(name) {
                continue;
            }
            let gone = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            gone.with_context(|| format!("{}: cannot remove", path.display()))?;
        }
    }
    if let Some(first) = read(out)?.first().filter(|_| !replace) {
        anyhow::bail!(
            "{}: the output folder is not empty ({}): give an empty folder, or --replace to \
             remove an earlier loop's outputs (iter-N, cycle.html, cycle.json)",
            out.display(),
            first.display()
        );
    }
    Ok(())
}

/// One of the stages' settings cut from `cycle --config` (its `[inspect]`, `[plan]` or
/// `[run]` table), written to DIR/<name>.toml and read from memory.
#[derive(Debug, Default)]
pub struct Section {
    /// The settings file written (none without the table): its path names it in errors.
    pub file: ConfigFile,
    /// The table.
    pub table: toml::Table,
}

/// The stages' settings cut from `cycle --config`.
#[derive(Debug, Default)]
pub struct Configs {
    /// `inspect`'s settings.
    pub inspect: Section,
    /// `plan`'s settings.
    pub plan: Section,
    /// `run`'s settings.
    pub run: Section,
}

const SECTIONS: [&str; 3] = ["inspect", "plan", "run"];

impl Configs {
    /// Splits `config` into DIR/inspect.toml, plan.toml and run.toml; any other top-level
    /// key is refused with the file and its name.
    pub fn split(config: Option<&Path>, out: &Path) -> anyhow::Result<Configs> {
        let Some(path) = config else {
            return Ok(Configs::default());
        };
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let table: toml::Table = text
            .parse()
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        if let Some(k) = table.keys().find(|k| !SECTIONS.contains(&k.as_str())) {
            anyhow::bail!(
                "{}: line {}: unknown table `{k}` (cycle's settings have [inspect], [plan] and \
                 [run], each holding that command's settings)",
                path.display(),
                table_line(&text, k)
            );
        }
        let mut files = Configs::default();
        for (name, slot) in
            SECTIONS
                .iter()
                .zip([&mut files.inspect, &mut files.plan, &mut files.run])
        {
            let Some(section) = table.get(*name) else {
                continue;
            };
            let file = out.join(format!("{name}.toml"));
            let body = toml::to_string(section)
                .with_context(|| format!("{}: [{name}]", path.display()))?;
            std::fs::write(&file, &body)
                .with_context(|| format!("{}: cannot write", file.display()))?;
            slot.table = body
                .parse()
                .map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))?;
            slot.file = ConfigFile {
                path: Some(file),
                text: body,
            };
        }
        Ok(files)
    }
}

/// 1-based line where the top-level key `k` first appears (`[k]`, `[k.x]`, `k = ` or
/// `k.x = `); 1 when not found.
fn table_line(text: &str, k: &str) -> usize {
    let starts = |l: &str| {
        let l = l.trim_start().trim_start_matches('[');
        l.strip_prefix(k)
            .is_some_and(|r| r.trim_start().starts_with(['.', ']', '=']))
    };
    text.lines().position(starts).map_or(1, |i| i + 1)
}

/// Runs `cycle`.
pub fn run(args: CycleArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let mut cfg = CycleConfig {
        max_iterations: args.max_iterations,
        min_progress: args.min_progress,
        footprint_radius_mm: args.footprint_radius,
        ledger_from_grind: match args.no_removal_ledger {
            true => None,
            false => CycleConfig::default().ledger_from_grind,
        },
        ..CycleConfig::default()
    };
    cfg.check().map_err(|m| anyhow::anyhow!("cycle: {m}"))?;
    prepare_out(&args.out, args.replace)?;
    let configs = Configs::split(config, &args.out)?;
    let blame = |e| blame_config(e, &args.out, config);
    cfg.inspect = super::inspect::settings(None, &configs.inspect.file).map_err(blame)?;
    cfg.plan = configs.plan.file.parse().map_err(blame)?;
    if let Some(mode) = args.mode {
        cfg.plan.plan.mode = mode;
    }
    cfg.plan_table = configs.plan.table;
    let settings = super::run::settings(&configs.run.file, None).map_err(blame)?;
    // the cells of [plan] and [run] are read here, once; the loop parses them from memory
    let cell = cfg.plan.robot.read_cell()?;
    let mut arm = LoopArm {
        device: args.device,
        cell: settings.robot.read_cell()?,
        settings,
        table: configs.run.table,
        ground: None,
    };
    let out = args.out.clone();
    let inputs = LoopInputs {
        reference: Source::file(args.reference),
        scan: Source::file(args.scan),
        files: FileInput {
            units: args.input.units,
            format: args.input.format,
        },
        out: args.out,
        cell,
        first: None,
    };
    let ended = run_cycle(&cfg, inputs, &mut arm).map_err(|e| blame_config(e, &out, config))?;
    print_outcome(&ended);
    match ended.outcome {
        Outcome::WithinTolerance => Ok(()),
        o => Err(NotFinished(o).into()),
    }
}

/// `e` said of the user's `--config` when it is about a settings file cycle derived from it
/// ([`super::settings::blame_source`]).
fn blame_config(e: anyhow::Error, out: &Path, config: Option<&Path>) -> anyhow::Error {
    let Some(source) = config else { return e };
    let text = std::fs::read_to_string(source).unwrap_or_default();
    match super::settings::blame_source(&e.to_string(), out, source, &text) {
        Some(m) => anyhow::anyhow!(m),
        None => e,
    }
}

/// Prints how the loop ended and its table.
pub fn print_outcome(ended: &CycleOutcome) {
    println!("== cycle: {}", ended.outcome.describe());
    print!("{}", table_text(&ended.records));
    println!("cycle: table in {}", ended.html.display());
}

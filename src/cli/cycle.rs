//! `polishbot cycle --reference R --scan S (--sim | --port DEV | --i2c DEV) -o DIR
//! [--max-iterations 3] [--min-progress SHARE]`: inspect, plan, run, rescan, until the part
//! is within tolerance, an iteration makes no progress, or the iterations run out. This file
//! wires folders and files; the records and the stop rule are `cell::cycle`'s.
use std::io::BufRead;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use super::arm::DeviceArgs;
use super::calibrate_removal::{self as calib, Inputs};
use super::common::{load_config, read_json, GeometryInput};
use super::{inspect, plan, run as run_cmd};
use crate::cell::cycle::{
    decide, decide_plan, table_html, table_json, table_text, CycleConfig, IterationRecord,
    Measured, Outcome, DEFAULT_MAX_ITERATIONS, DEFAULT_MIN_PROGRESS,
};
use crate::cell::removal_shift::{self, RegionShift, ShiftConfig};
use crate::motion::{Inspection, Plan, PlanMode};
use crate::regions::Regions;
use crate::removal::fit::{self as removal_fit, Agreement, Evidence, FitConfig, RemovalFit};

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

/// The per-command settings files cut from `cycle --config`: its `[inspect]`, `[plan]` and
/// `[run]` tables, each written to DIR/<name>.toml and given to that command.
#[derive(Debug, Default, Clone)]
pub struct Configs {
    /// `inspect`'s settings file.
    pub inspect: Option<PathBuf>,
    /// `plan`'s settings file.
    pub plan: Option<PathBuf>,
    /// `run`'s settings file.
    pub run: Option<PathBuf>,
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
            std::fs::write(&file, body)
                .with_context(|| format!("{}: cannot write", file.display()))?;
            *slot = Some(file);
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

/// One loop to run: `demo` builds it with its own first inspection and plan.
pub struct Loop {
    /// Reference file.
    pub reference: PathBuf,
    /// The first scan.
    pub scan: PathBuf,
    /// Output folder.
    pub out: PathBuf,
    /// Stop rule settings.
    pub config: CycleConfig,
    /// The arm.
    pub device: DeviceArgs,
    /// Input units and format.
    pub input: GeometryInput,
    /// Per-command settings files.
    pub configs: Configs,
    /// Iteration 1's inspection folder and plan file when already made (demo).
    pub first: Option<(PathBuf, PathBuf)>,
    /// Plan mode (None: plan's default).
    pub mode: Option<PlanMode>,
}

/// Runs `cycle`.
pub fn run(args: CycleArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let cfg = CycleConfig {
        max_iterations: args.max_iterations,
        min_progress: args.min_progress,
    };
    cfg.check().map_err(|m| anyhow::anyhow!("cycle: {m}"))?;
    prepare_out(&args.out, args.replace)?;
    let configs = Configs::split(config, &args.out)?;
    let outcome = run_loop(&Loop {
        reference: args.reference,
        scan: args.scan,
        out: args.out,
        config: cfg,
        device: args.device,
        input: args.input,
        configs,
        first: None,
        mode: args.mode,
    })?;
    match outcome {
        Outcome::WithinTolerance => Ok(()),
        o => Err(NotFinished(o).into()),
    }
}

/// Inspects `scan` into `dir` with `inspect`'s settings and reads the result; an incomplete
/// verdict ends the loop with `inspect`'s error.
fn inspect_scan(l: &Loop, scan: &Path, dir: &Path) -> anyhow::Result<()> {
    inspect::run(
        inspect::InspectArgs {
            reference: l.reference.clone(),
            scan: vec![scan.to_path_buf()],
            out: dir.to_path_buf(),
            tolerance: None,
            method: None,
            registration_error: None,
            pose: None,
            core: None,
            inspect_area: None,
            input: l.input.clone(),
        },
        l.configs.inspect.as_deref(),
    )
}

/// An inspection folder read: its summary and its core points.
fn measure(dir: &Path) -> anyhow::Result<(Measured, Inspection)> {
    let regions: Regions = read_json(&dir.join("regions.json"))?;
    let inspection = Inspection::load(dir)?;
    Ok((Measured::of(regions.verdict, &inspection), inspection))
}

/// Streams `plan` to the arm, journalling into `dir`; with the simulator the virtual `part`
/// (its file, and whether it is in the reference frame: `run --part-in-reference`) is ground
/// and its rescan written to DIR/after.ply, with a real arm the next scan's path is read from
/// stdin.
fn grind(
    l: &Loop,
    plan: &Path,
    tool: &Path,
    part: (&Path, bool),
    dir: &Path,
) -> anyhow::Result<PathBuf> {
    let after = dir.join("after.ply");
    let sim = l.device.sim;
    let settings = with_tool(l.configs.run.as_deref(), tool, &dir.join("run.toml"))?;
    run_cmd::run(
        run_cmd::RunArgs {
            plan: plan.to_path_buf(),
            device: l.device.clone(),
            cell: None,
            dry_run: false,
            resume: None,
            journal: Some(dir.join("journal.jsonl")),
            part: sim.then(|| part.0.to_path_buf()),
            ground_out: sim.then(|| after.to_path_buf()),
            part_in_reference: sim && part.1,
        },
        Some(&settings),
    )?;
    if sim {
        return Ok(after);
    }
    println!("cycle: scan the part and enter the scan file's path:");
    let mut line = String::new();
    std::io::stdin()
        .lock()
        .read_line(&mut line)
        .context("cycle: reading the next scan's path from stdin")?;
    let next = PathBuf::from(line.trim());
    anyhow::ensure!(
        !line.trim().is_empty(),
        "cycle: no next scan given on stdin (the journal of {} is complete)",
        plan.display()
    );
    anyhow::ensure!(
        next.is_file(),
        "{}: the next scan (read from stdin) is not a file",
        next.display()
    );
    Ok(next)
}

/// Writes the table to stdout and DIR/cycle.html.
fn report(l: &Loop, records: &[IterationRecord], outcome: Outcome) -> anyhow::Result<()> {
    println!("== cycle: {}", outcome.describe());
    print!("{}", table_text(records));
    let html = l.out.join("cycle.html");
    std::fs::write(&html, table_html(records, outcome))
        .with_context(|| format!("{}: cannot write", html.display()))?;
    let json = l.out.join("cycle.json");
    std::fs::write(
        &json,
        serde_json::to_string_pretty(&table_json(records, outcome))?,
    )
    .with_context(|| format!("{}: cannot write", json.display()))?;
    println!("cycle: table in {}", html.display());
    Ok(())
}

/// What the last grind was made from: its inspection (folder and points), plan and tool.
struct Ground {
    inspection_dir: PathBuf,
    inspection: Inspection,
    plan: PathBuf,
    tool: PathBuf,
}

/// Runs the loop and returns how it ended (the table printed and written either way).
pub fn run_loop(l: &Loop) -> anyhow::Result<Outcome> {
    let mut records: Vec<IterationRecord> = Vec::new();
    let mut previous: Option<Ground> = None;
    // every grind's removal evidence so far: k is fitted to all of it
    let mut pooled = Vec::new();
    let mut scan = l.scan.clone();
    // the simulator's virtual part: the first scan, then the ground part itself (its truth
    // file, reference frame), so that it keeps its shape between grinds
    let mut part = (l.scan.clone(), false);
    let mut tool = load_config::<plan::PlanFileConfig>(l.configs.plan.as_deref())?
        .robot
        .tool;
    for k in 1.. {
        let dir = l.out.join(format!("iter-{k}"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        println!("== cycle: iteration {k}: inspect {}", scan.display());
        let (inspection_dir, plan_file) = match (&l.first, k) {
            (Some((i, p)), 1) => (i.clone(), p.clone()),
            _ => (dir.join("inspection"), dir.join("plan.json")),
        };
        if l.first.is_none() || k > 1 {
            inspect_scan(l, &scan, &inspection_dir)?;
        }
        let (measured, inspection) = measure(&inspection_dir)?;
        let mut off_plan = None;
        if let (Some(last), Some(before)) = (records.last_mut(), &previous) {
            last.followed_by(&measured, &before.inspection, &inspection);
            let ids: Vec<i64> = last.planned_regions.iter().map(|&i| i as i64).collect();
            (last.k_fitted, last.agreement, off_plan) = refit(
                before,
                (&inspection_dir, &inspection),
                &ids,
                &dir,
                &mut tool,
                &mut pooled,
            );
        }
        records.push(IterationRecord::new(k, measured));
        let mut outcome = decide(&records, &l.config);
        if let (Outcome::Continue, Some(reason)) = (outcome, &off_plan) {
            println!("cycle: stop: {reason}");
            outcome = Outcome::OffPlan;
        }
        if outcome == Outcome::Continue {
            if l.first.is_none() || k > 1 {
                plan_into(l, &inspection_dir, &plan_file, &tool, &dir)?;
            }
            let plan = Plan::load(&plan_file)?;
            let last = records.last_mut().expect("pushed above");
            last.planned(&inspection, &plan);
            outcome = decide_plan(last);
        }
        if outcome != Outcome::Continue {
            report(l, &records, outcome)?;
            return Ok(outcome);
        }
        println!("== cycle: iteration {k}: grind");
        scan = grind(l, &plan_file, &tool, (&part.0, part.1), &dir)?;
        if l.device.sim {
            part = (super::grind::truth_paths(&scan).0, true);
        }
        previous = Some(Ground {
            inspection_dir,
            inspection,
            plan: plan_file,
            tool: tool.clone(),
        });
        print!("{}", table_text(&records));
    }
    unreachable!("the loop returns")
}

/// Refits k after the last grind from the points of every grind so far (`pooled`, which this
/// grind's points join; `removal_fit::pool`) and, when the fit holds, writes DIR/tool.toml
/// with it and makes it the `tool` of the next plan; re-predicts the grind with the fitted k
/// over the defect points of the regions `ids` against the `after` inspection (folder and
/// points). Returns the fitted k, or None with the reason printed (a rigid plan, too little
/// evidence), the agreement (None for a rigid plan), and the registration's reason to stop
/// (`removal_shift::judge`): k is fitted on the prediction moved by each region's measured
/// shift.
fn refit(
    before: &Ground,
    after: (&Path, &Inspection),
    ids: &[i64],
    dir: &Path,
    tool: &mut PathBuf,
    pooled: &mut Vec<Evidence>,
) -> (Option<f64>, Option<Agreement>, Option<String>) {
    let inputs = Inputs {
        before: before.inspection_dir.clone(),
        after: after.0.to_path_buf(),
        plan: before.plan.clone(),
        tool: before.tool.clone(),
    };
    let written = dir.join("tool.toml");
    let prediction = calib::prediction(&before.plan, &before.tool, &before.inspection);
    let shift_cfg = ShiftConfig::default();
    let mut off_plan = None;
    let prediction = prediction.map(|(p, k)| {
        let shifts = removal_shift::register(&before.inspection, after.1, &p, &shift_cfg);
        shifts
            .iter()
            .for_each(|r| println!("{}", describe_shift(r)));
        off_plan = removal_shift::judge(&shifts, &shift_cfg);
        let moved = removal_shift::shifted_prediction(&before.inspection, &p, &shifts, &shift_cfg);
        (moved, k)
    });
    let fitted = prediction.as_ref().map_err(clone_error).and_then(|(p, k)| {
        let cfg = FitConfig::default();
        let grind = calib::evidence_loaded(&inputs, &before.inspection, after.1, p, *k, &cfg)?;
        pooled.push(grind);
        let fit = fit_pooled(pooled, &cfg)?;
        calib::write_fit(&before.tool, &written, &fit)?;
        Ok(fit.k_mm2_n)
    });
    let k = match fitted {
        Ok(k) => {
            println!("cycle: the next plan uses k from {}", written.display());
            *tool = written;
            Some(k)
        }
        Err(e) => {
            println!(
                "cycle: k not refitted ({}); the next plan keeps {}",
                super::common::one_line(&e),
                tool.display()
            );
            None
        }
    };
    let agreement = prediction.ok().and_then(|(p, plan_k)| {
        removal_fit::agreement(&before.inspection, after.1, &p, k.map(|k| k / plan_k), ids)
    });
    (k, agreement, off_plan)
}

/// One line on a region's registration for the loop's log.
fn describe_shift(r: &RegionShift) -> String {
    let s = r.shift_mm;
    format!(
        "cycle: region {}: removal shift {:.2} mm [{:.2}, {:.2}, {:.2}], depth scale {:.3} \
         (unshifted {:.3}), residual RMS {:.4} -> {:.4} mm over {} points, {} removed where \
         nothing was planned",
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
        r.unplanned
    )
}

/// Prints the last grind's own fit (or why it cannot fit alone, when it has earlier grinds to
/// pool with) and fits k to the points of all grinds in `pooled`, printing that fit with the
/// grinds and points it pooled.
fn fit_pooled(pooled: &[Evidence], cfg: &FitConfig) -> anyhow::Result<RemovalFit> {
    let last = pooled.last().expect("the grind just pushed");
    match removal_fit::pool(std::slice::from_ref(last), cfg) {
        Ok(own) => calib::describe(&own, "cycle: this grind alone")
            .iter()
            .for_each(|line| println!("{line}")),
        // with no earlier grind the pool's refusal below says the same
        Err(m) if pooled.len() > 1 => println!(
            "cycle: this grind alone fits no k ({m}); its {} points join the pool",
            last.points.len()
        ),
        Err(_) => {}
    }
    let fit = removal_fit::pool(pooled, cfg).map_err(|m| anyhow::anyhow!("{m}"))?;
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
    anyhow::anyhow!("{}", super::common::one_line(e))
}

/// Plans from `inspection` into `plan_file` with `plan`'s settings and the tool file `tool`
/// (DIR/plan.toml: the `[plan]` settings with `robot.tool` set).
fn plan_into(
    l: &Loop,
    inspection: &Path,
    plan_file: &Path,
    tool: &Path,
    dir: &Path,
) -> anyhow::Result<()> {
    println!("== cycle: plan");
    let settings = with_tool(l.configs.plan.as_deref(), tool, &dir.join("plan.toml"))?;
    plan::run(
        plan::PlanArgs {
            inspection: inspection.to_path_buf(),
            workcell: None,
            out: plan_file.to_path_buf(),
            export_ros: None,
            require_full_reach: false,
            mode: l.mode,
            cell: None,
        },
        Some(&settings),
    )
}

/// Writes `out`: the settings file `base` (or none) with `[robot] tool` set to `tool`, so that
/// the loop's plan and its run use the tool file the loop fitted (run refuses a plan made
/// with another tool file than the one it is given).
fn with_tool(base: Option<&Path>, tool: &Path, out: &Path) -> anyhow::Result<PathBuf> {
    let mut table: toml::Table = match base {
        Some(f) => std::fs::read_to_string(f)
            .with_context(|| format!("{}: cannot read", f.display()))?
            .parse()
            .map_err(|e| anyhow::anyhow!("{}: {e}", f.display()))?,
        None => toml::Table::new(),
    };
    let robot = table
        .entry("robot")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let Some(r) = robot.as_table_mut() {
        r.insert("tool".into(), tool.display().to_string().into());
    }
    std::fs::write(out, toml::to_string(&table)?)
        .with_context(|| format!("{}: cannot write", out.display()))?;
    Ok(out.to_path_buf())
}

//! `polishbot run --plan plan.json (--port DEV | --i2c DEV | --sim) [--dry-run]
//! [--resume journal.jsonl]`.
use std::path::{Path, PathBuf};

use clap::Args;
use serde::Deserialize;

use super::arm::DeviceArgs;
use super::settings::{self, ConfigFile};
use super::setup_stop;
use crate::bus::{self, Bus, BusConfig, Journal, ResumePoint, Transport};
use crate::cell::{execute, RunConfig};
use crate::cloud::{Geometry, PointCloud};
use crate::inspect::Source;
use crate::motion::file::CheckedPlan;
use crate::motion::{collide, frames, CollisionConfig, Inspection, Plan, ValidationConfig};
use crate::robot::{sha256_hex, CellFiles, RobotConfig};
use crate::sim::virtual_part::{self, Ground, GroundPart, Inspected, PartToGrind};
use crate::sim::SimOptions;

/// Arguments of `run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The plan to stream.
    #[arg(long, value_name = "FILE")]
    pub plan: PathBuf,
    /// Which arm: --port DEV, --i2c DEV [--i2c-address ADDR] or --sim.
    #[command(flatten)]
    pub device: DeviceArgs,
    /// Check the plan and print what would be sent; send nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Cell folder: its dofbot.urdf, tool.toml, servos.toml and workcell.toml (a
    /// `[turntable]` in both lets `run` turn the table) [default: calibration/].
    #[arg(long, value_name = "DIR")]
    pub cell: Option<PathBuf>,
    /// Continue an interrupted run from this journal (appended to).
    #[arg(long, value_name = "FILE")]
    pub resume: Option<PathBuf>,
    /// Journal file [default: journal.jsonl next to the plan, or the --resume file].
    #[arg(long, value_name = "FILE")]
    pub journal: Option<PathBuf>,
    /// With --sim: the part the simulated arm grinds, a point cloud in the frame of the scan
    /// the plan's inspection registered (e.g. that scan.ply).
    #[arg(long, value_name = "FILE", requires = "ground_out")]
    pub part: Option<PathBuf>,
    /// With --part: the part file is already in the reference frame and holds the part's
    /// surface as it is (the `<stem>_truth.ply` an earlier `--ground-out` wrote): it is not
    /// moved by the plan's registration. `cycle` grinds the one
    /// virtual part this way from its second grind on, so that the part keeps its shape
    /// between grinds (a rescan's noise and registration error are the measurement's, not
    /// the part's).
    #[arg(long, requires = "part")]
    pub part_in_reference: bool,
    /// With --part: write the ground part's rescan here (a valid `inspect` scan), and its
    /// removal per point in <stem>_truth.ply beside it.
    #[arg(long, value_name = "FILE", requires = "part")]
    pub ground_out: Option<PathBuf>,
}

/// `--config` TOML of `run`: `[robot]`, `[run]`, `[bus]` (timing; the servo map always comes
/// from servos.toml), `[sim]`, `[validation]`.
#[derive(Debug, Default, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunFileConfig {
    /// Robot description and calibration files.
    pub robot: RobotConfig,
    /// Streaming settings.
    pub run: RunConfig,
    /// Bus driver settings.
    pub bus: BusConfig,
    /// Simulated arm settings.
    pub sim: SimOptions,
    /// Tolerances of the re-validation.
    pub validation: ValidationConfig,
    /// The collision model of the re-check (solids.toml beside the workcell file adds its
    /// solids).
    pub collision: CollisionConfig,
}

/// Longest accepted `[run] settle_ms`, ms (as the driver's waits).
const MAX_SETTLE_MS: f64 = crate::bus::config::MAX_WAIT_MS;
/// Largest `[run] readback_every`, frames (a read-back every 100 s at the 20 ms period).
const MAX_READBACK_EVERY: usize = 5_000;

/// Checks the `[run]` settings: each named by key and line.
fn check_run_settings(file: &ConfigFile, r: &RunConfig) -> anyhow::Result<()> {
    let every = r.readback_every as f64;
    let counts = r.readback_tolerance_counts as f64;
    let max_counts = crate::bus::config::MAX_VERIFY_COUNTS as f64;
    for c in [
        settings::in_range("settle_ms", r.settle_ms, 0.0, MAX_SETTLE_MS, "ms"),
        settings::in_range(
            "readback_every",
            every,
            1.0,
            MAX_READBACK_EVERY as f64,
            "frames",
        ),
        settings::in_range(
            "readback_tolerance_counts",
            counts,
            0.0,
            max_counts,
            "counts",
        ),
    ] {
        c.map_err(|m| file.refuse("run", &m))?;
    }
    Ok(())
}

/// A fresh run refuses to append to a journal of another plan (`--resume` checks its own).
fn check_fresh_journal(path: &Path, sha: &str) -> anyhow::Result<()> {
    let used = std::fs::metadata(path).is_ok_and(|m| m.len() > 0);
    if !used {
        return Ok(());
    }
    let rp = ResumePoint::from_journal(path)?;
    anyhow::ensure!(
        rp.plan_sha256.iter().all(|h| h == sha),
        "{}: the journal holds a run of another plan: give --journal with a new file",
        path.display()
    );
    Ok(())
}

/// Refuses a plan made from other files than `run` is given: each file plan.json's
/// provenance records (the inspection's and the cell's, by role; the cell's as held, `cell`)
/// must have the recorded SHA-256 now; a file the plan did not have must still be absent. A
/// plan without the record (written by hand, or its provenance block removed) is refused.
fn check_made_for(
    plan_path: &Path,
    text: &str,
    plan: &Plan,
    (robot, cell): (&RobotConfig, &CellFiles),
) -> anyhow::Result<()> {
    let value: serde_json::Value = serde_json::from_str(text)?;
    // every plan `plan` writes records its inputs; one without the record cannot be checked
    // against the cell and inspection it was made for, so nothing of it reaches the arm
    let Some(recorded) = value["provenance"]["inputs"].as_array() else {
        anyhow::bail!(
            "{}: refused: no `provenance.inputs` (the files the plan was made from): it cannot \
             be checked against this cell and inspection; re-plan",
            plan_path.display()
        );
    };
    let now = crate::cycle::plan_inputs(Path::new(&plan.inspection), robot);
    for (role, path) in &now {
        let entry = recorded.iter().find(|e| e["role"] == *role);
        let advice = if role.starts_with("inspection") {
            "re-plan from the current inspection"
        } else {
            "re-plan after calibrating"
        };
        let refuse = |what: String| {
            anyhow::anyhow!(
                "{}: refused: {role} {}: {what}: {advice}",
                plan_path.display(),
                path.display()
            )
        };
        let held = cell.by_role().into_iter().find(|(r, _)| r == role);
        let now = match held {
            Some((_, f)) => Ok(f.text.clone().into_bytes()),
            None if role.starts_with("inspection") => std::fs::read(path),
            None => Err(std::io::ErrorKind::NotFound.into()),
        };
        match (entry, now) {
            (None, Err(_)) => {}
            (None, Ok(_)) => return Err(refuse("the plan was made without this file".into())),
            (Some(e), Err(err)) => {
                return Err(refuse(format!(
                    "cannot read it ({err}); the plan was made with {}",
                    e["path"]
                )))
            }
            (Some(e), Ok(bytes)) => {
                let sha = sha256_hex(&bytes);
                if e["sha256"].as_str() != Some(sha.as_str()) {
                    return Err(refuse(format!(
                        "changed since the plan was made (SHA-256 {}, the plan's {} from {})",
                        &sha[..12],
                        e["sha256"].as_str().map_or("?", |h| &h[..h.len().min(12)]),
                        e["path"]
                    )));
                }
            }
        }
    }
    Ok(())
}

/// Where the plan to stream comes from.
pub enum PlanSource<'a> {
    /// A plan file: read, and checked against the files it was made from.
    File,
    /// A plan this process made and wrote to the job's file: its text and the plan.
    Made {
        /// plan.json as written.
        text: &'a str,
        /// The plan.
        plan: &'a Plan,
    },
}

/// One run: a plan streamed to an arm.
pub struct Job<'a> {
    /// plan.json.
    pub plan_file: &'a Path,
    /// The plan, from the file or in memory.
    pub source: PlanSource<'a>,
    /// The part to check collisions against; None: the inspection folder plan.json names.
    pub inspection: Option<&'a Inspection>,
    /// The cell's files (read once by the caller; the loop's with the plan's tool file).
    pub cell: &'a CellFiles,
    /// The arm.
    pub device: &'a DeviceArgs,
    /// Check everything, send nothing.
    pub dry_run: bool,
    /// Continue from this journal.
    pub resume: Option<&'a Path>,
    /// The journal file [default: the resume file, else journal.jsonl beside the plan].
    pub journal: Option<PathBuf>,
    /// A virtual part for the simulated arm.
    pub part: Option<PartToGrind<'a>>,
}

/// The settings of `run` from its `--config` file (checked: link, grinding simulator, `[run]`)
/// with `cell`'s files.
pub fn settings(file: &ConfigFile, cell: Option<&Path>) -> anyhow::Result<RunFileConfig> {
    let mut cfg: RunFileConfig = file.parse()?;
    settings::check_link(file, &cfg.bus, &cfg.sim)?;
    cfg.sim
        .grinding
        .check()
        .map_err(|m| file.refuse("sim.grinding", &m))?;
    check_run_settings(file, &cfg.run)?;
    (cfg.validation.check()).map_err(|m| file.refuse("validation", &m))?;
    if let Some(dir) = cell {
        cfg.robot.use_cell(dir);
    }
    Ok(cfg)
}

/// Runs `run`. `--dry-run` makes every check of a real run (settings, plan, servo map,
/// resume point, journal) and stops before opening the link.
pub fn run(args: RunArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let cfg = settings(&ConfigFile::read(config)?, args.cell.as_deref())?;
    let cell = cfg.robot.read_cell()?;
    let part = match (&args.part, &args.ground_out) {
        (Some(file), Some(out)) => Some(PartToGrind {
            file,
            held: None,
            in_reference: args.part_in_reference,
            ground_out: out,
            scan_to_reference: None,
        }),
        _ => None,
    };
    let run_from = |resume: Option<&Path>| {
        let job = Job {
            plan_file: &args.plan,
            source: PlanSource::File,
            inspection: None,
            cell: &cell,
            device: &args.device,
            dry_run: args.dry_run,
            resume,
            journal: args.journal.clone(),
            part,
        };
        stream_plan(&cfg, &job).map(drop)
    };
    match args.device.sim && part.is_none() {
        true => setup_stop::simulated_operator(run_from, args.resume.as_deref()),
        false => run_from(args.resume.as_deref()),
    }
}

/// Streams `job`'s plan with the settings `cfg`: checks the plan against the cell (joint and
/// servo ranges, collisions), the resume point and the journal, then sends it. Returns the
/// virtual part's ground surface and rescan, as written, when the simulated arm ground one
/// (`job.part`).
pub fn stream_plan(cfg: &RunFileConfig, job: &Job) -> anyhow::Result<Option<GroundPart>> {
    let plan_path = job.plan_file;
    let (text, parsed);
    let (text, plan) = match job.source {
        PlanSource::Made { text, plan } => (text, plan),
        PlanSource::File => {
            // one read: the plan is parsed from the bytes its SHA-256 is taken of
            text = std::fs::read_to_string(plan_path)
                .map_err(|e| anyhow::anyhow!("{}: {e}", plan_path.display()))?;
            parsed = Plan::parse(plan_path, &text)?;
            check_made_for(plan_path, &text, &parsed, (&cfg.robot, job.cell))?;
            (text.as_str(), &parsed)
        }
    };
    let sha = sha256_hex(text.as_bytes());
    // a plan over several setups: the setup this run streams, on that setup's workcell
    let whole = plan;
    let stage = setup_stop::stage(job.resume, &sha, whole)?;
    let plan = stage.plan;
    let robot = super::tool_stop::robot_for(job.cell, stage.tool)?;
    let (table, workcell, solids) = match stage.setup {
        1 => (
            job.cell.turntable()?,
            job.cell.workcell()?,
            collide::solids_of(job.cell.solids.as_ref())?,
        ),
        n => {
            let c = setup_stop::cell_of(&cfg.robot, whole, n)?;
            let table = crate::robot::Turntable::load(&c.servos, &c.workcell)?;
            let wc = crate::robot::Workcell::load(&c.workcell)?;
            (table, wc, collide::solids_beside(&c.workcell)?)
        }
    };
    let checked = plan
        .check_cell(&robot, table.as_ref(), &cfg.validation)
        .map_err(|e| anyhow::anyhow!("{}: refused: {e}", plan_path.display()))?;
    let steps = crate::cell::steps(&checked).len();
    let mut collision = cfg.collision.clone();
    collision.solids.extend(solids);
    let loaded;
    let inspection = match job.inspection {
        Some(i) => i,
        None => {
            loaded = Inspection::load(Path::new(&plan.inspection)).map_err(|e| {
                anyhow::anyhow!(
                    "{}: refused: the part to check collisions against: {e}",
                    plan_path.display()
                )
            })?;
            &loaded
        }
    };
    plan.check_clearance_cell(inspection, &robot, &workcell, table.as_ref(), &collision)
        .map_err(|e| anyhow::anyhow!("{}: refused: {e}", plan_path.display()))?;
    let from = stage.from(job.resume, steps)?;
    let journal_path = (job.journal.clone())
        .or(job.resume.map(Path::to_path_buf))
        .unwrap_or_else(|| plan_path.with_file_name("journal.jsonl"));
    if job.resume.is_none() {
        check_fresh_journal(&journal_path, &sha)?;
    }
    let mut bus_cfg = cfg.bus.clone();
    bus_cfg.servo_map = frames::servo_map(&robot)?;
    bus_cfg.servo_map.validate()?;
    let ground = ground(job, &cfg.sim, inspection)?;
    let sim = super::arm::sim_with_table(&cfg.sim, table.as_ref())?;
    if job.dry_run {
        println!(
            "run: dry run: {} passes, {} frames from frame {from}, {:.2} s at {} ms per frame; nothing sent",
            plan.passes.len(),
            steps,
            (steps - from) as f64 * plan.period,
            checked.time_ms
        );
        return Ok(None);
    }
    let journal = Journal::append(&journal_path)?
        .for_plan(&sha)
        .for_setup(stage.number as u64);
    let then = setup_stop::next_stop(whole, stage.number, &journal_path, plan_path);
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let _ = bus::install_ctrlc(stop.clone());
    if let Some(ground) = ground {
        let map = bus_cfg.servo_map.clone();
        anyhow::ensure!(
            checked.table.is_none(),
            "run: --part: the virtual part's grinding does not follow the turntable; run the plan without --part"
        );
        let arm = ground.arm(&map)?;
        let mut bus = Bus::connect(arm.transport(), bus_cfg, journal)?;
        bus.set_stop_flag(stop);
        let (run, at) = (&cfg.run, &journal_path);
        stream(bus, &checked, plan, from, run, at, then.as_ref())?;
        return ground
            .finish(&arm, &map, &workcell.robot_from_reference)
            .map(Some);
    }
    let link = super::arm::open_link(job.device, &sim, &bus_cfg.servo_map, "run")?;
    let mut bus = Bus::connect(link, bus_cfg, journal)?;
    bus.set_stop_flag(stop);
    stream(
        bus,
        &checked,
        plan,
        from,
        &cfg.run,
        &journal_path,
        then.as_ref(),
    )
    .map(|()| None)
}

/// The virtual part of `--part` / `--ground-out`, checked and loaded before anything moves;
/// only the simulated arm grinds one, from the plan's first frame. Without a scan pose given
/// (`run --part`), the pose is the inspection's registration.json.
fn ground(job: &Job, sim: &SimOptions, inspection: &Inspection) -> anyhow::Result<Option<Ground>> {
    let Some(part) = &job.part else {
        return Ok(None);
    };
    anyhow::ensure!(
        job.device.sim,
        "run: --part and --ground-out need --sim (only the simulated arm grinds a virtual part)"
    );
    anyhow::ensure!(
        job.resume.is_none(),
        "run: --part cannot --resume: the virtual part's removal lives only in one run"
    );
    #[derive(serde::Deserialize)]
    struct Registration {
        scan_to_reference: [[f64; 4]; 4],
    }
    let mut part = *part;
    if !part.in_reference && part.scan_to_reference.is_none() {
        let file = inspection.dir.join("registration.json");
        let read = super::common::read_json::<Registration>(&file)?;
        part.scan_to_reference = Some(read.scan_to_reference);
    }
    let inspected = Inspected {
        dir: &inspection.dir,
        positions: inspection.points.iter().map(|p| p.position).collect(),
        normals: inspection.points.iter().map(|p| p.normal).collect(),
        distances: inspection.points.iter().map(|p| p.distance).collect(),
    };
    Ground::prepare(sim, &part, &inspected).map(Some)
}

fn stream<T: Transport>(
    mut bus: Bus<T>,
    checked: &CheckedPlan,
    plan: &Plan,
    from: usize,
    cfg: &RunConfig,
    journal: &Path,
    then: Option<&setup_stop::OperatorStop>,
) -> anyhow::Result<()> {
    let port = bus.transport().describe();
    match execute(&mut bus, checked, plan.period, from, cfg) {
        Ok(r) => {
            let table = r
                .final_table_raw
                .map_or(String::new(), |t| format!(", table raw {t}"));
            println!(
                "run: {port}: sent frames {}..{} ({} frames), {} read-backs (worst {} counts), final pose {:?}{table} verified; journal {}",
                r.first,
                r.first + r.sent - 1,
                r.sent,
                r.readbacks,
                r.worst_readback_counts,
                r.final_raw,
                journal.display()
            );
            let Some(op) = then else { return Ok(()) };
            bus.operator_stop(&op.kind, op.setup, &op.message)?;
            Err(op.clone().into())
        }
        Err(e) => Err(anyhow::anyhow!(
            "run: {port}: stopped: {e}; journal {} (continue with --resume {})",
            journal.display(),
            journal.display()
        )),
    }
}

/// The loop's arm (`cycle`, `demo`): `run`'s streaming with its settings held in memory; the
/// simulated arm grinds the loop's virtual part and rescans it, a real arm's next scan is
/// asked for on stdin.
pub struct LoopArm {
    /// The arm.
    pub device: DeviceArgs,
    /// `run`'s settings (cycle's `[run]`), checked.
    pub settings: RunFileConfig,
    /// The same as written (cycle's `[run]` table): each iteration's run.toml is it with the
    /// plan's tool file.
    pub table: toml::Table,
    /// The cell of the run settings' `[robot]`, read once: each grind uses it with the plan's
    /// tool file.
    pub cell: CellFiles,
    /// The simulated arm's part as the last grind left it, and the truth file it wrote it to:
    /// the next grind of that file takes it from here.
    pub ground: Option<(PathBuf, PointCloud)>,
}

impl crate::cycle::Executor for LoopArm {
    /// The simulated arm's loaded touch-offs against the cell's `[compliance]` table
    /// (`calibrate_verify::check_loop_arm`); a real arm's is `calibrate verify`'s, made by its
    /// operator before the loop (docs/CALIBRATION.md, section 4).
    fn check_arm(&mut self) -> anyhow::Result<Option<String>> {
        match self.device.sim {
            true => super::calibrate_verify::check_loop_arm(
                &self.cell,
                &self.settings.sim,
                &self.settings.bus,
            ),
            false => Ok(None),
        }
    }

    fn grind(&mut self, job: &crate::cycle::GrindJob) -> anyhow::Result<crate::cycle::Rescan> {
        let after = job.dir.join("after.ply");
        let sim = self.device.sim;
        crate::cycle::with_tool(&self.table, &job.tool.path, &job.dir.join("run.toml"))?;
        let mut cfg = self.settings.clone();
        cfg.robot.tool = job.tool.path.clone();
        let held = (self.ground.as_ref())
            .filter(|(file, _)| job.part_in_reference && file == job.part.as_path())
            .map(|(_, cloud)| cloud)
            .or_else(|| job.part.held_cloud());
        let part = sim.then(|| PartToGrind {
            file: job.part.as_path(),
            held,
            in_reference: job.part_in_reference,
            ground_out: &after,
            scan_to_reference: Some(job.scan_to_reference),
        });
        let run = Job {
            plan_file: job.plan_file,
            source: PlanSource::Made {
                text: &job.planned.text,
                plan: &job.planned.plan,
            },
            inspection: Some(job.inspection),
            cell: &self.cell.with_tool(job.tool),
            device: &self.device,
            dry_run: false,
            resume: None,
            journal: Some(job.dir.join("journal.jsonl")),
            part,
        };
        let ground = stream_plan(&cfg, &run)?;
        if sim {
            let ground =
                ground.ok_or_else(|| anyhow::anyhow!("cycle: the simulated arm ground no part"))?;
            // The rescan is handed on as written: the next inspection does not read it back.
            let part = virtual_part::truth_paths(&after).0;
            self.ground = Some((part.clone(), ground.surface));
            let scan = Geometry::Cloud(ground.rescan);
            return Ok(crate::cycle::Rescan {
                scan: Source::held(after, scan, ground.rescan_ply),
                more_scans: Vec::new(),
                part: Some(part),
            });
        }
        println!(
            "cycle: rescan the ground area: {}",
            crate::inspect::suggest::describe_rescan(job.rescan)
        );
        let mut scans: Vec<Source> = (next_scans(job.plan_file)?.into_iter())
            .map(Source::file)
            .collect();
        Ok(crate::cycle::Rescan {
            scan: scans.remove(0),
            more_scans: scans,
            part: None,
        })
    }
}

/// The next scans' paths (one per setup), asked for on stdin after a real arm's run of `plan`:
/// one path a line, ended by an empty line or the end of the input.
fn next_scans(plan: &Path) -> anyhow::Result<Vec<PathBuf>> {
    use std::io::BufRead;
    println!(
        "cycle: scan the part and enter each scan file's path, one a line (an empty line ends):"
    );
    let mut scans = Vec::new();
    for line in std::io::stdin().lock().lines() {
        let line = line
            .map_err(|e| anyhow::anyhow!("cycle: reading the next scan's path from stdin: {e}"))?;
        let path = PathBuf::from(line.trim());
        if line.trim().is_empty() {
            break;
        }
        anyhow::ensure!(
            path.is_file(),
            "{}: the next scan (read from stdin, line {}) is not a file",
            path.display(),
            scans.len() + 1
        );
        scans.push(path);
    }
    anyhow::ensure!(
        !scans.is_empty(),
        "cycle: no next scan given on stdin (the journal of {} is complete)",
        plan.display()
    );
    Ok(scans)
}

//! `polishbot calibrate (servos | tool | compliance | workcell | turntable | verify) (--port DEV
//! | --i2c DEV | --sim) [--out DIR] [--cell DIR]`:
//! the calibration routines of docs/CALIBRATION.md. Each reads the cell's files from `--out`
//! where they exist there (so servos -> tool -> workcell -> verify chain in one folder), else
//! from `[robot]`, and writes its own file into `--out`.
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use serde::Deserialize;

use super::arm::LinkArgs;
use super::common::say;
use crate::bus::{Bus, BusConfig, Transport, JOINT_COUNT};
use crate::calibrate::jog::{Cell, RawTerminal};
use crate::calibrate::verify::DEFAULT_CHECK_POSES;
use crate::calibrate::{
    self, files, load_targets, CalibError, CalibrationConfig, Fixture, JogTerminal, Scripted,
    TouchSource,
};
use crate::motion::frames;
use crate::robot::units::mm;
use crate::robot::{Robot, RobotConfig};
use crate::sim::SimOptions;

/// Arguments of `calibrate`.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The routine.
    #[command(subcommand)]
    pub routine: Routine,
    /// Which arm, and the journal.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Folder the calibration files are written to, and read from where present
    /// [default: the --cell folder, else calibration].
    #[arg(long, global = true, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Cell folder: its dofbot.urdf, tool.toml, servos.toml and workcell.toml
    /// [default: calibration/].
    #[arg(long, global = true, value_name = "DIR")]
    pub cell: Option<PathBuf>,
}

/// The routines, in the order a new cell runs them.
#[derive(Debug, Subcommand)]
pub enum Routine {
    /// Servo zero offsets: torque off, hold the arm in the zero pose, confirm -> servos.toml.
    Servos {
        /// Do not wait for a confirmation: the arm already is in the zero pose.
        #[arg(long)]
        assume_pose: bool,
        /// Also store the zero pose as each joint servo's mid position (0x1C) and check the
        /// board's offset state (0x1B).
        #[arg(long)]
        store_mid: bool,
    },
    /// Tool tip by the pivot method: touch one fixed point from >= 4 orientations -> tool.toml.
    Tool {
        /// Joint targets to touch from (one pose per line, 5 angles in rad) instead of jogging.
        #[arg(long, value_name = "FILE")]
        targets: Option<PathBuf>,
    },
    /// Joint stiffness, backlash and lumped masses: touch three fixed points from several
    /// tilts under listed loads -> servos.toml's [compliance] (before workcell).
    Compliance,
    /// Workcell: touch the fixture's fiducials -> workcell.toml (robot_from_reference).
    Workcell {
        /// Fixture file: [[fiducial]] name, position (mm, part reference frame).
        #[arg(long, value_name = "FILE")]
        fixture: PathBuf,
        /// Joint targets, one per fiducial in the fixture's order, instead of jogging.
        #[arg(long, value_name = "FILE")]
        targets: Option<PathBuf>,
        /// The part's setup measured (a re-fixturing of a designed cell): 2 on writes
        /// `setup-N/workcell.toml` beside workcell.toml (its `[turntable]` kept).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=9))]
        setup: u64,
    },
    /// Turntable: touch one fiducial on the table at >= 5 table angles -> workcell.toml's
    /// [turntable] axis and centre.
    Turntable {
        /// Table angles to touch the fiducial at, degrees (>= 5, spanning >= 90 degrees).
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            required = true
        )]
        angles: Vec<f64>,
        /// Joint targets, one per table angle in order, instead of jogging.
        #[arg(long, value_name = "FILE")]
        targets: Option<PathBuf>,
    },
    /// Move through check poses, read back, report per-servo and tool-tip error.
    Verify {
        /// Check poses (one per line, 5 angles in rad) [default: five built-in poses].
        #[arg(long, value_name = "FILE")]
        targets: Option<PathBuf>,
        /// Also compare each pose's tool tip with this fixture's fiducial (one pose per
        /// fiducial) placed by workcell.toml.
        #[arg(long, value_name = "FILE", requires = "targets")]
        fixture: Option<PathBuf>,
    },
    /// Preston's k from a grind: two inspections and the plan ground between them ->
    /// tool.toml `[removal] preston_k_mm2_n` (no arm needed).
    Removal {
        /// Inspection folder before the grind (the plan's).
        #[arg(long, value_name = "DIR")]
        before: PathBuf,
        /// Inspection folder of the rescan after the grind.
        #[arg(long, value_name = "DIR")]
        after: PathBuf,
        /// The plan that was ground (made with --mode removal; predicted.csv beside it).
        #[arg(long, value_name = "FILE")]
        plan: PathBuf,
        /// The tool the plan was made with, read and updated in place: a file, or the name
        /// of a tool of the cell's library (`small`: its `tools/small.toml`) [default: the
        /// cell's tool.toml, written into --out].
        #[arg(long, value_name = "FILE|NAME")]
        tool: Option<PathBuf>,
    },
}

/// `--config` TOML of `calibrate`: `[robot]` (files), `[bus]` (timing; the servo map always
/// comes from servos.toml), `[sim]` (the simulated arm, with its hidden `[sim.mechanics]`) and
/// `[calibrate]` (CalibrationConfig).
#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CalibrateFileConfig {
    /// Robot description and calibration files.
    pub robot: RobotConfig,
    /// Bus driver settings.
    pub bus: BusConfig,
    /// Simulated arm settings.
    pub sim: SimOptions,
    /// Routine settings.
    pub calibrate: CalibrationConfig,
}

/// `DIR/name` when it exists, else `fallback`.
/// The workcell file setup `n` is calibrated from and the one written (setup 1: `workcell_in`
/// and `out`/workcell.toml; further setups their `setup-N/workcell.toml`, read from
/// `workcell_in`'s when it has none yet: the same `[turntable]`).
fn setup_files(workcell_in: &Path, out: &Path, n: usize) -> Result<(PathBuf, PathBuf), CalibError> {
    use crate::motion::setups::setup_file;
    let file = setup_file(&out.join("workcell.toml"), n);
    if let Some(dir) = file.parent() {
        std::fs::create_dir_all(dir).map_err(|e| CalibError::file(dir, e))?;
    }
    let input = [
        setup_file(&out.join("workcell.toml"), n),
        setup_file(workcell_in, n),
    ]
    .into_iter()
    .find(|p| p.is_file())
    .unwrap_or_else(|| workcell_in.to_path_buf());
    Ok((input, file))
}

fn input(out: &Path, name: &str, fallback: &Path) -> PathBuf {
    let p = out.join(name);
    if p.exists() {
        p
    } else {
        fallback.to_path_buf()
    }
}

/// Runs `calibrate`.
pub fn run(args: CalibrateArgs, config: Option<&Path>) -> anyhow::Result<()> {
    let file = super::settings::ConfigFile::read(config)?;
    let mut cfg: CalibrateFileConfig = file.parse()?;
    super::settings::check_link(&file, &cfg.bus, &cfg.sim)?;
    if let Some(dir) = &args.cell {
        cfg.robot.use_cell(dir);
    }
    let out = args
        .out
        .clone()
        .or(args.cell.clone())
        .unwrap_or_else(|| PathBuf::from("calibration"));
    let tool_in = input(&out, "tool.toml", &cfg.robot.tool);
    if let Routine::Removal {
        before,
        after,
        plan,
        tool,
    } = &args.routine
    {
        let tool = tool
            .as_ref()
            .map(|t| crate::robot::tool_library::resolve(&tool_in, t));
        let inputs = super::calibrate_removal::RefitInputs {
            before: before.clone(),
            after: after.clone(),
            plan: plan.clone(),
            tool: tool.clone().unwrap_or(tool_in),
        };
        let written = tool.clone().unwrap_or_else(|| out.join("tool.toml"));
        return super::calibrate_removal::run(&inputs, &written);
    }
    let servos_in = input(&out, "servos.toml", &cfg.robot.servos);
    let robot = Robot::load(&cfg.robot.urdf, &tool_in, &servos_in)?;
    let mut bus_cfg = cfg.bus.clone();
    bus_cfg.servo_map = frames::servo_map(&robot)?;
    let gripper_deg = frames::gripper_hold_deg(&robot)?;
    let map = bus_cfg.servo_map.clone();
    let name = routine_name(&args.routine);
    // Checks that need no arm come first: nothing moves on bad input.
    let fixture = match &args.routine {
        Routine::Workcell { fixture, .. } => {
            let f = Fixture::load(fixture)?;
            calibrate::workcell::check_fixture(&f, &cfg.calibrate)
                .map_err(|e| anyhow::anyhow!("{}: {e}", fixture.display()))?;
            Some(f)
        }
        Routine::Verify {
            fixture: Some(fixture),
            ..
        } => Some(Fixture::load(fixture)?),
        _ => None,
    };
    let workcell_in = input(&out, "workcell.toml", &cfg.robot.workcell);
    let table = match &args.routine {
        Routine::Turntable { angles, targets } => Some(super::calibrate_table::prepare(
            &servos_in,
            &workcell_in,
            angles,
            targets.as_deref(),
            &cfg.calibrate,
        )?),
        Routine::Verify { .. } => {
            super::calibrate_verify::prepare(&servos_in, &workcell_in, &cfg.calibrate)?
        }
        _ => None,
    };
    let targets = match &args.routine {
        Routine::Tool { targets }
        | Routine::Workcell { targets, .. }
        | Routine::Turntable { targets, .. } => targets.as_deref().map(load_targets).transpose()?,
        Routine::Verify { targets, .. } => Some(match targets {
            Some(t) => load_targets(t)?,
            None => DEFAULT_CHECK_POSES.to_vec(),
        }),
        Routine::Servos { .. } | Routine::Removal { .. } | Routine::Compliance => None,
    };
    let prefix = format!("calibrate {name}");
    let sim = super::arm::sim_with_table(&cfg.sim, table.as_ref())?;
    let mut bus = args.link.connect(&prefix, bus_cfg, &sim).map_err(|e| {
        let line = super::common::one_line(&e);
        match line.starts_with(&prefix) {
            true => anyhow::anyhow!(line),
            false => anyhow::anyhow!("{prefix}: {line}"),
        }
    })?;
    // Ctrl-C stops motion sending (in the jog terminal it is a key that aborts).
    let _ = crate::bus::install_ctrlc(bus.stop_flag());
    let cell = Cell {
        robot: &robot,
        map: &map,
        gripper_deg,
        cfg: &cfg.calibrate,
    };
    let ctx = Ctx {
        out: &out,
        tool_in: &tool_in,
        servos_in: &servos_in,
        workcell_in,
        table,
        sim: args.link.device.sim.then_some(&cfg.sim.grinding),
    };
    routine(&mut bus, &cell, &args.routine, fixture, targets, &ctx)
        .map_err(|e| anyhow::anyhow!("calibrate {name}: {e}"))
}

fn routine_name(r: &Routine) -> &'static str {
    match r {
        Routine::Servos { .. } => "servos",
        Routine::Tool { .. } => "tool",
        Routine::Compliance => "compliance",
        Routine::Workcell { .. } => "workcell",
        Routine::Turntable { .. } => "turntable",
        Routine::Verify { .. } => "verify",
        Routine::Removal { .. } => "removal",
    }
}

/// Where a routine reads and writes its files.
struct Ctx<'a> {
    out: &'a Path,
    tool_in: &'a Path,
    servos_in: &'a Path,
    workcell_in: PathBuf,
    /// The cell's turntable (`calibrate turntable`, and `verify` on a cell with one).
    table: Option<crate::robot::Turntable>,
    /// The simulated arm's mechanics with `--sim` (`calibrate compliance`'s simulated
    /// operator touches with them).
    sim: Option<&'a crate::sim::GrindConfig>,
}

/// The touch source: the script, or the jog terminal on standard input and output.
fn source<T: Transport>(
    targets: Option<Vec<[f64; JOINT_COUNT]>>,
    cfg: &CalibrationConfig,
) -> Box<dyn TouchSource<T>> {
    match targets {
        Some(t) => Box::new(Scripted::new(t)),
        None => Box::new(JogTerminal::new(
            std::io::stdin(),
            std::io::stdout(),
            cfg.jog_step_deg,
        )),
    }
}

fn routine(
    bus: &mut Bus<Box<dyn Transport>>,
    cell: &Cell,
    which: &Routine,
    fixture: Option<Fixture>,
    targets: Option<Vec<[f64; JOINT_COUNT]>>,
    ctx: &Ctx,
) -> Result<(), CalibError> {
    // Raw keys only while a routine may read them (restored on return, also on errors).
    let interactive = match which {
        Routine::Servos { assume_pose, .. } => !assume_pose,
        Routine::Tool { .. } | Routine::Workcell { .. } | Routine::Turntable { .. } => {
            targets.is_none()
        }
        Routine::Compliance => ctx.sim.is_none(),
        Routine::Verify { targets, .. } => {
            targets.is_none() && ctx.sim.is_none() && cell.robot.servos.compliance.is_some()
        }
        Routine::Removal { .. } => false,
    };
    let _raw = interactive.then(RawTerminal::enable).flatten();
    match which {
        Routine::Servos {
            assume_pose,
            store_mid,
        } => servos(bus, cell, *assume_pose, *store_mid, ctx),
        Routine::Tool { .. } => {
            let mut src = source(targets, cell.cfg);
            let fit = calibrate::tool_tip(bus, cell, src.as_mut())?;
            let file = ctx.out.join("tool.toml");
            files::write_tool(ctx.tool_in, &file, fit.tip_offset)?;
            let t = fit.tip_offset.map(mm);
            say(&format!(
                "calibrate tool: {} touches, orientation spread {:.1} deg; residual per touch [mm]: {}; RMS {:.3} mm",
                fit.touches.len(),
                fit.spread_deg,
                calibrate::pivot::list_mm(&fit.residuals_mm),
                fit.rms_mm
            ));
            say(&format!(
                "calibrate tool: tip_offset [mm] {:.3} {:.3} {:.3} (flange frame; {:.3} mm off the wrist-roll axis), pivot [mm] {:.2} {:.2} {:.2}; wrote {}",
                t[0],
                t[1],
                t[2],
                t[0].hypot(t[1]),
                mm(fit.pivot[0]),
                mm(fit.pivot[1]),
                mm(fit.pivot[2]),
                file.display()
            ));
            Ok(())
        }
        Routine::Compliance => {
            let out = ctx.out.join("servos.toml");
            super::calibrate_compliance::run(bus, cell, ctx.sim, ctx.servos_in, &out)
        }
        Routine::Workcell {
            fixture: path,
            setup,
            ..
        } => {
            let fixture = fixture.expect("loaded in run");
            let mut src = source(targets, cell.cfg);
            let fit = calibrate::workcell(bus, cell, &fixture, src.as_mut())?;
            let per: Vec<String> = fixture
                .fiducials
                .iter()
                .zip(&fit.residuals_mm)
                .map(|(f, r)| format!("{} {r:.3}", f.name))
                .collect();
            let (input, file) = setup_files(&ctx.workcell_in, ctx.out, *setup as usize)?;
            let header = format!(
                "Written by `polishbot calibrate workcell` from {} touched fiducials of {}.\n\
                 Residual per fiducial [mm]: {}; RMS {:.3} mm.",
                fixture.fiducials.len(),
                path.display(),
                per.join(", "),
                fit.rms_mm
            );
            files::update_workcell(&input, &file, &fit.robot_from_reference, &header)?;
            say(&format!(
                "calibrate workcell: residual per fiducial [mm]: {}; RMS {:.3} mm; wrote {}",
                per.join(", "),
                fit.rms_mm,
                file.display()
            ));
            Ok(())
        }
        Routine::Removal { .. } => Err(CalibError::Refused(
            "the removal fit needs no arm and runs before connecting".into(),
        )),
        Routine::Turntable { angles, .. } => turntable(bus, cell, angles, targets, ctx),
        Routine::Verify {
            targets: scripted, ..
        } => {
            let poses = targets.expect("set in run");
            let table = ctx.table.as_ref();
            let w = &ctx.workcell_in;
            let worst =
                super::calibrate_verify::run(bus, cell, table, &poses, fixture.as_ref(), w)?;
            match scripted {
                None => super::calibrate_verify::check_table(
                    bus,
                    cell,
                    (ctx.sim, "calibrate verify"),
                    ctx.servos_in,
                )?,
                Some(_) if cell.robot.servos.compliance.is_some() => say(&format!(
                    "calibrate verify: [compliance] of {} not checked (scripted --targets make \
                     no loaded touch-offs; run verify without --targets to check it)",
                    ctx.servos_in.display()
                )),
                Some(_) => {}
            }
            let file = ctx.out.join("tool.toml");
            files::write_verified_tip(ctx.tool_in, &file, worst)?;
            say(&format!(
                "calibrate verify: worst tool tip {worst:.3} mm recorded in {} (`[removal] \
                 verified_tip_error_mm`: the plans' Monte Carlo tip error)",
                file.display()
            ));
            Ok(())
        }
    }
}

/// `calibrate turntable` (cli/calibrate_table.rs) with this routine's files.
fn turntable(
    bus: &mut Bus<Box<dyn Transport>>,
    cell: &Cell,
    angles: &[f64],
    targets: Option<Vec<[f64; JOINT_COUNT]>>,
    ctx: &Ctx,
) -> Result<(), CalibError> {
    let mut src = source(targets, cell.cfg);
    let out = ctx.out.join("workcell.toml");
    let table = ctx.table.as_ref();
    let input = &ctx.workcell_in;
    super::calibrate_table::run(bus, cell, table, angles, src.as_mut(), input, &out)
}

fn servos(
    bus: &mut Bus<Box<dyn Transport>>,
    cell: &Cell,
    assume_pose: bool,
    store_mid: bool,
    ctx: &Ctx,
) -> Result<(), CalibError> {
    let mut confirm = || -> Result<(), CalibError> {
        let text = "calibrate servos: torque is off. Move the arm by hand into the zero pose \
                    (every joint straight up, the wrist roll at its zero) and hold it still.";
        if assume_pose {
            say(&format!("{text} --assume-pose: reading now."));
            return Ok(());
        }
        JogTerminal::new(std::io::stdin(), std::io::stdout(), 1.0).confirm(text)
    };
    let r = calibrate::servo_offsets(bus, cell.map, cell.cfg, &mut confirm, store_mid)?;
    let zero: Vec<(u8, f64)> = r.servos.iter().map(|s| (s.id, s.zero_offset_deg)).collect();
    let file = ctx.out.join("servos.toml");
    files::write_servos(ctx.servos_in, &file, &zero)?;
    for s in &r.servos {
        say(&format!(
            "calibrate servos: servo {} ({}): raw {:.2} (spread {} counts over {} reads) -> zero_offset_deg {:.3} (was {:.3}, change {:+.3})",
            s.id,
            s.joint,
            s.raw_mean,
            s.spread_counts,
            r.reads,
            s.zero_offset_deg,
            s.previous_deg,
            s.zero_offset_deg - s.previous_deg
        ));
    }
    let stored = if r.stored_mid {
        "; mid positions stored on the servos (offset state ok)"
    } else {
        ""
    };
    say(&format!(
        "calibrate servos: wrote {}{stored}",
        file.display()
    ));
    Ok(())
}

//! The loop's engine: [`run_cycle`] inspects, plans, has the executor grind and rescan, refits
//! k, and again, until the stop rule ends it. The stages are called in memory (the inspection
//! the plan is made from, the plan the run streams, the prediction the fit compares with);
//! their files are outputs only. One iteration is [`Loop::iteration`].
use std::borrow::Cow;
use std::path::{Path, PathBuf};

use anyhow::Context;

use super::config::CycleConfig;
use super::figures;
use super::ledger::Ledger;
use super::plan_stage::{plan_into, Planned};
use super::record::{
    decide, decide_plan, table_html, table_json, table_text, IterationRecord, Measured, Outcome,
};
use super::refit::{one_line, refit, PlannedGrind};
use crate::cloud::transform::isometry_to_rows;
use crate::inspect::suggest::RescanSetup;
use crate::inspect::{self, FileInput, PoseSource, Source};
use crate::motion::aim::Aim;
use crate::removal::fit::{Evidence, GrindPair};
use crate::repair::{Inspection, SurfacePoint};
use crate::report::Figure;
use crate::robot::{CellFiles, ToolText};

/// What the loop starts from.
pub struct LoopInputs {
    /// Reference file (or the reference the caller wrote, held).
    pub reference: Source,
    /// The first scan (or the scan the caller wrote, held).
    pub scan: Source,
    /// Units and format of the reference and the scans.
    pub files: FileInput,
    /// Output folder: iter-1, iter-2, ..., cycle.html and cycle.json.
    pub out: PathBuf,
    /// The plan's cell (the files the plan settings' `[robot]` names), read once by the
    /// caller: each plan parses it from memory, with the loop's refitted tool.
    pub cell: CellFiles,
    /// Iteration 1's inspection and plan when the caller made them already (demo).
    pub first: Option<First>,
}

/// Iteration 1's inspection and plan, made by the caller.
pub struct First {
    /// The inspection of the first scan.
    pub found: inspect::Findings,
    /// Its folder.
    pub inspection_dir: PathBuf,
    /// The plan made from it (a `plan::plan_into` output).
    pub plan_file: PathBuf,
    /// What was planned and written.
    pub planned: Planned,
}

/// One grind the executor makes.
pub struct GrindJob<'a> {
    /// plan.json.
    pub plan_file: &'a Path,
    /// The plan and the bytes written to `plan_file`.
    pub planned: &'a Planned,
    /// The inspection the plan was made from (the part to check collisions against).
    pub inspection: &'a Inspection,
    /// The inspected scan's pose, scan to reference, 4x4 row-major (registration.json's).
    pub scan_to_reference: [[f64; 4]; 4],
    /// The tool file the plan was made with, as held in memory.
    pub tool: &'a ToolText,
    /// A simulated arm's part: the first scan, then the part it ground.
    pub part: &'a Source,
    /// Whether `part` is already in the reference frame (a ground part's truth file).
    pub part_in_reference: bool,
    /// The iteration's folder (journal, run settings, a simulated rescan).
    pub dir: &'a Path,
    /// The setups and table angles whose scans see the area this plan grinds (issue 53's rule,
    /// [`inspect::suggest::rescan_setups`]): a real arm's operator is told them; a simulated
    /// rescan resamples the ground part at the first scan's points, which hold that area.
    pub rescan: &'a [RescanSetup],
}

/// What a grind left: the next scan, and with a simulated arm the ground part itself.
pub struct Rescan {
    /// The scan of the ground part (a simulated rescan held as written: not read back).
    pub scan: Source,
    /// Further scans of it (other setups), inspected together with `scan`.
    pub more_scans: Vec<Source>,
    /// The ground part in the reference frame (a simulated arm's truth file), the next grind's
    /// part; None for a real part.
    pub part: Option<PathBuf>,
}

/// The arm the loop grinds with: streams a plan and brings the next scan.
pub trait Executor {
    /// Grinds `job`'s plan and returns the rescan.
    fn grind(&mut self, job: &GrindJob) -> anyhow::Result<Rescan>;

    /// Checks, before the loop's first grind, that the arm is the one the cell was calibrated
    /// on: Some(why) when it contradicts the calibration (the loop then stops before anything
    /// is ground). The default checks nothing.
    fn check_arm(&mut self) -> anyhow::Result<Option<String>> {
        Ok(None)
    }
}

/// How the loop ended, its records and its page.
pub struct CycleOutcome {
    /// How it ended.
    pub outcome: Outcome,
    /// One record per inspection.
    pub records: Vec<IterationRecord>,
    /// cycle.html.
    pub html: PathBuf,
}

/// Runs the loop from `inputs` with `cfg`, grinding with `executor`; writes iter-K folders,
/// cycle.html and cycle.json into `inputs.out` and returns how it ended.
pub fn run_cycle(
    cfg: &CycleConfig,
    inputs: LoopInputs,
    executor: &mut dyn Executor,
) -> anyhow::Result<CycleOutcome> {
    let mut state = Loop {
        tool: None,
        scan: inputs.scan.clone(),
        more_scans: Vec::new(),
        part: (inputs.scan.clone(), false),
        inputs,
        cfg,
        records: Vec::new(),
        previous: None,
        pooled: Vec::new(),
        figures: Vec::new(),
        aim: Aim::default(),
        ledger: None,
    };
    for k in 1.. {
        if let Some(outcome) = state.iteration(k, executor)? {
            return state.finish(outcome);
        }
    }
    unreachable!("the loop returns")
}

/// The loop's state between iterations.
struct Loop<'a> {
    cfg: &'a CycleConfig,
    inputs: LoopInputs,
    records: Vec<IterationRecord>,
    /// What the last grind was made from.
    previous: Option<PlannedGrind>,
    /// Every grind's removal evidence so far: k is fitted to all of it.
    pooled: Vec<Evidence>,
    /// The scan to inspect next.
    scan: Source,
    /// Further scans (other setups) inspected with it.
    more_scans: Vec<Source>,
    /// The simulator's virtual part: the first scan, then the ground part itself (its truth
    /// file, reference frame), so that it keeps its shape between grinds.
    part: (Source, bool),
    /// The tool file of the next plan, held in memory: refitted after each grind; None until
    /// the first refit (the cell's tool file, `LoopInputs::cell`).
    tool: Option<ToolText>,
    /// cycle.html's figures of the grinds so far (drawn when each grind is judged).
    figures: Vec<Figure>,
    /// Where the next plan aims: the removal shift measured and carried so far (none before
    /// the first grind, `motion::aim`).
    aim: Aim,
    /// The removal ledger (`super::ledger`): opened on the first inspection, each grind's
    /// predicted removal entered after its rescan; None with `ledger_from_grind` None.
    ledger: Option<Ledger>,
}

impl Loop<'_> {
    /// Iteration `k`: inspect the scan, judge the last grind and refit k, decide, plan and
    /// grind. Returns how the loop ended, or None to go on.
    fn iteration(
        &mut self,
        k: usize,
        executor: &mut dyn Executor,
    ) -> anyhow::Result<Option<Outcome>> {
        let dir = self.inputs.out.join(format!("iter-{k}"));
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        println!(
            "== cycle: iteration {k}: inspect {}",
            self.scan.as_path().display()
        );
        let (found, inspection_dir, made) = match self.inputs.first.take() {
            Some(f) => (f.found, f.inspection_dir, Some((f.plan_file, f.planned))),
            None => {
                let into = dir.join("inspection");
                (self.inspect(&into)?, into, None)
            }
        };
        let inspection = planner_input(&found, &inspection_dir);
        self.open_ledger(&inspection);
        let measured = Measured::of(found.regions.verdict, &inspection);
        let mut off_plan = None;
        if let (Some(last), Some(before)) = (self.records.last_mut(), &self.previous) {
            // the grind's two inspections matched once, for the record, the refit and figures
            let pair = GrindPair::new(&before.inspection, &inspection);
            last.followed_by(&measured, &pair);
            let ids: Vec<i64> = last.planned_regions.iter().map(|&i| i as i64).collect();
            let done = refit(
                before,
                (&inspection_dir, &pair),
                &ids,
                &dir,
                (&mut self.tool, &mut self.aim),
                &mut self.pooled,
            );
            (last.k_fitted, last.agreement, off_plan) = (done.k, done.agreement, done.off_plan);
            if let (Some(ledger), Some((moved, plan_k))) = (self.ledger.as_mut(), &done.moved) {
                ledger.enter(
                    &before.inspection,
                    moved,
                    done.k.map_or(1.0, |k| k / plan_k),
                );
            }
            let carried: Vec<(usize, [f64; 3])> = (done.shifts.iter())
                .filter_map(|s| Some((usize::try_from(s.region).ok()?, s.carried_mm)))
                .collect();
            if let Some((predicted, shifts)) = done.seen {
                let ground = self.inputs.out.join(format!("iter-{}", last.iteration));
                self.figures.extend(figures::grind(
                    &ground,
                    last.iteration,
                    &pair,
                    &last.planned_regions,
                    &predicted,
                    (&shifts, &carried),
                ));
            }
            last.shifts = done.shifts;
        }
        self.records.push(IterationRecord::new(k, measured));
        let mut outcome = decide(&self.records, self.cfg);
        if let (Outcome::Continue, Some(reason)) = (outcome, off_plan) {
            println!("cycle: stop: {reason}");
            outcome = self.stop(Outcome::OffPlan, reason);
        }
        if outcome != Outcome::Continue {
            return Ok(Some(outcome));
        }
        let (plan_file, planned) = match made {
            Some(made) => made,
            // a later grind's plan that fails (its own path check, an unreachable aim) ends
            // the loop on the part as measured, recorded; the first plan's failure is the
            // settings' or the part's and is the caller's error, as `plan`'s
            None if k > 1 => {
                match self.plan(&self.ledger_view(&inspection, k), &found, (&dir, k)) {
                    Ok(made) => made,
                    Err(e) => {
                        let why = format!("grind {k}'s plan failed: {}", one_line(&e));
                        println!("cycle: stop: {why}");
                        return Ok(Some(self.stop(Outcome::PlanFailed, why)));
                    }
                }
            }
            None => self.plan(&inspection, &found, (&dir, k))?,
        };
        let last = self.records.last_mut().expect("pushed above");
        last.planned(&inspection, &planned.plan);
        let outcome = decide_plan(last);
        if outcome != Outcome::Continue {
            return Ok(Some(outcome));
        }
        if self.previous.is_none() {
            if let Some(why) = executor.check_arm()? {
                println!("cycle: stop: {why}");
                return Ok(Some(self.stop(Outcome::ArmMismatch, why)));
            }
        }
        println!("== cycle: iteration {k}: grind");
        let setups = rescan_setups(&inspection, &last.planned_regions, &found, self.cfg);
        let rescan = executor.grind(&GrindJob {
            plan_file: &plan_file,
            planned: &planned,
            inspection: &inspection,
            scan_to_reference: pose_rows(&found.pose),
            tool: &planned.tool,
            part: &self.part.0,
            part_in_reference: self.part.1,
            dir: &dir,
            rescan: &setups,
        })?;
        self.scan = rescan.scan;
        self.more_scans = rescan.more_scans;
        if let Some(part) = rescan.part {
            self.part = (Source::file(part), true);
        }
        self.previous = Some(PlannedGrind {
            inspection,
            plan_file,
            planned,
        });
        print!("{}", table_text(&self.records));
        Ok(None)
    }

    /// Opens the removal ledger on the loop's first inspection (`inspection`, the planner's
    /// view), unless it is open, off, or would start after the loop's last grind.
    fn open_ledger(&mut self, inspection: &Inspection) {
        let read = (self.cfg.ledger_from_grind).is_some_and(|g| g <= self.cfg.max_iterations);
        if read && self.ledger.is_none() {
            self.ledger = Some(Ledger::open(inspection));
        }
    }

    /// `inspection` as grind `grind`'s plan reads it: from the loop's `ledger_from_grind` on
    /// at the removal ledger's values where they are lower (`Ledger::bound`, said in a line),
    /// else as it is.
    fn ledger_view<'i>(&self, inspection: &'i Inspection, grind: usize) -> Cow<'i, Inspection> {
        let from = self.cfg.ledger_from_grind.unwrap_or(usize::MAX);
        let Some(ledger) = self.ledger.as_ref().filter(|_| grind >= from) else {
            return Cow::Borrowed(inspection);
        };
        let (view, done) = ledger.bound(inspection.clone());
        if done.points > 0 {
            println!(
                "cycle: the removal ledger reads {} core points below their rescan's reading \
                 (by up to {:.3} mm): the grinds so far were predicted to take more off them",
                done.points, done.most_mm
            );
        }
        Cow::Owned(view)
    }

    /// Ends the loop with `outcome` for the reason `why` (one line), recorded on the last
    /// inspection's record (cycle.json's `stopped`, cycle.html's outcome).
    fn stop(&mut self, outcome: Outcome, why: String) -> Outcome {
        if let Some(last) = self.records.last_mut() {
            last.stopped = Some(why);
        }
        outcome
    }

    /// Inspects the scan into `into` with the loop's inspection settings, also read at its
    /// `footprint_radius_mm` when set; an incomplete verdict ends the loop with the
    /// inspection's error.
    fn inspect(&self, into: &Path) -> anyhow::Result<inspect::Findings> {
        let inputs = inspect::Inputs {
            reference: self.inputs.reference.clone(),
            scan: self.scan.clone(),
            more_scans: self.more_scans.clone(),
            files: self.inputs.files,
            pose: None,
            core: None,
            inspect_area: None,
            registration_error: None,
            fine_radius: self.cfg.footprint_radius_mm,
        };
        inspect::inspect_into(&self.cfg.inspect, &inputs, into)
    }

    /// Plans grind `grind` from `inspection` into DIR/plan.json with the loop's plan settings
    /// and its tool file (written as DIR/plan.toml, an output: the `[plan]` settings with
    /// `robot.tool`, the carried `aim` and `finish.grind` set: grind 2 on is planned as a
    /// finish, `motion::finish`).
    fn plan(
        &self,
        inspection: &Inspection,
        found: &inspect::Findings,
        (dir, grind): (&Path, usize),
    ) -> anyhow::Result<(PathBuf, Planned)> {
        println!("== cycle: plan");
        let cell = match &self.tool {
            Some(t) => self.inputs.cell.with_tool(t),
            None => self.inputs.cell.clone(),
        };
        let tool = &cell.tool;
        let settings = dir.join("plan.toml");
        let mut cfg = self.cfg.plan.clone();
        cfg.robot.tool = tool.path.clone();
        cfg.plan.aim = self.aim.clone();
        cfg.plan.finish.grind = grind;
        // the carried shift and the grind, so that `plan --config plan.toml` makes this plan
        // again
        let mut table = self.cfg.plan_table.clone();
        let plan = table
            .entry("plan")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let Some(p) = plan.as_table_mut() {
            let aim = (!self.aim.is_empty()).then(|| toml::Value::try_from(&self.aim));
            if let Some(Ok(aim)) = aim {
                p.insert("aim".into(), aim);
            }
            if let Ok(finish) = toml::Value::try_from(&cfg.plan.finish) {
                p.insert("finish".into(), finish);
            }
        }
        with_tool(&table, &tool.path, &settings)?;
        let refuse = |m: &str| anyhow::anyhow!("{}: [plan] {m}", settings.display());
        let plan_file = dir.join("plan.json");
        let found = Some(found);
        let planned = plan_into(&cfg, &cell, found, inspection, &plan_file, None, &refuse)?;
        Ok((plan_file, planned))
    }

    /// Writes cycle.html and cycle.json and hands the records back.
    fn finish(self, outcome: Outcome) -> anyhow::Result<CycleOutcome> {
        let out = &self.inputs.out;
        let html = out.join("cycle.html");
        let table = table_html(&self.records, outcome);
        let page = figures::page(&table, out, &self.records, &self.figures);
        std::fs::write(&html, page).with_context(|| format!("{}: cannot write", html.display()))?;
        let json = out.join("cycle.json");
        std::fs::write(
            &json,
            serde_json::to_string_pretty(&table_json(&self.records, outcome))?,
        )
        .with_context(|| format!("{}: cannot write", json.display()))?;
        Ok(CycleOutcome {
            outcome,
            records: self.records,
            html,
        })
    }
}

/// Radius of the loop's second reading of each inspection, the one its planner then reads,
/// as measured, mm (`cycle --footprint-radius`, off by default: below, 2 ideal-arm runs
/// gouged with it). 0.6: the tool's patch radius, half its 1.2 mm footprint; at the simulated
/// scans' 8 points/mm^2 a cylinder holds about 9 scan points, a mean within 0.005 mm of the
/// 0.015 mm noise. The adaptive comparison grows its cylinders to 1.8-3.7 mm where the noise asks,
/// wider than what a grind leaves: it read a grind's narrow loss at a conform rim point at
/// 0.13-0.19 of its depth (survey case 161, cell 29, documented arm: true -0.030/-0.052 mm
/// after grinds 2/3 read -0.004/-0.010 mm), this radius at 0.7-0.8 (py4dgeo's M3C2 there:
/// -0.024/-0.020 mm at the point and its neighbour; 0.9 mm read -0.012/-0.007, 0.4 mm -0.054
/// at 0.02-0.04 mm LoD); tests/compare's ground dip: 0.29 against 0.60 of the depth. Read this
/// way (the verdict, the reports and the regions still the adaptive comparison's) the 30-run
/// survey's median share within tolerance rose 29.8 -> 44.8 % on the documented arm (none
/// gouged), 26.5 -> 42.0 % on the ideal arm, where 2 runs ground a region point to
/// -0.063/-0.065 mm, and k after grind 1 was within 10 % in 4 and 2 runs, not 16 and 10
/// (docs/ALGORITHMS.md, "The loop reads at the tool's footprint").
pub const FINE_RADIUS_MM: f64 = 0.6;

/// The planner's view of an inspection held in memory, its folder `dir`: the values
/// deviations.csv and regions.json carry, as `plan::Inspection::load` reads them back, each
/// core point's distance the reading at the tool's footprint where the inspection made one
/// (`Findings::fine`, [`FINE_RADIUS_MM`]; the adaptive distance where that reading has too few
/// points), and those readings as `Inspection::fine`.
pub fn planner_input(found: &inspect::Findings, dir: &Path) -> Inspection {
    let dev = &found.deviations;
    let points = (dev.points.iter().zip(&dev.normals))
        .zip(dev.values.iter().zip(&found.regions.labels))
        .map(|((p, n), (v, &region))| SurfacePoint {
            position: *p,
            normal: n / n.norm(),
            distance: v.distance,
            uncertainty: v.uncertainty,
            region,
        })
        .collect();
    Inspection {
        dir: dir.to_path_buf(),
        tolerance: Some(found.regions.tolerance),
        regions: found.regions.regions.clone(),
        points,
        fine: Vec::new(),
    }
    .read_at_footprint(found.fine.clone())
}

/// The setups and table angles a rescan needs to see the points of the regions `planned` (the
/// area the plan grinds), from the scan's pose and the inspection's `[suggest]` cell.
fn rescan_setups(
    inspection: &Inspection,
    planned: &[usize],
    found: &inspect::Findings,
    cfg: &CycleConfig,
) -> Vec<RescanSetup> {
    let positions: Vec<_> = inspection.points.iter().map(|p| p.position).collect();
    let normals: Vec<_> = inspection.points.iter().map(|p| p.normal).collect();
    let wanted: Vec<bool> = (inspection.points.iter())
        .map(|p| usize::try_from(p.region).is_ok_and(|r| planned.contains(&r)))
        .collect();
    let pose = found.pose.pose();
    inspect::suggest::rescan_setups(
        (&positions, &normals),
        None,
        &wanted,
        &pose,
        &cfg.inspect.suggest,
    )
}

/// The scan's pose as registration.json records it.
pub fn pose_rows(pose: &PoseSource) -> [[f64; 4]; 4] {
    match pose {
        PoseSource::Registered(reg) => reg.scan_to_reference,
        PoseSource::Given { pose, .. } => isometry_to_rows(pose),
    }
}

/// Writes `out`: the settings `base` with `[robot] tool` set to `tool`, so that the loop's
/// plan and its run use the tool file the loop fitted (run refuses a plan made with another
/// tool file than the one it is given).
pub fn with_tool(base: &toml::Table, tool: &Path, out: &Path) -> anyhow::Result<()> {
    let mut table = base.clone();
    let robot = table
        .entry("robot")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let Some(r) = robot.as_table_mut() {
        r.insert("tool".into(), tool.display().to_string().into());
    }
    std::fs::write(out, toml::to_string(&table)?)
        .with_context(|| format!("{}: cannot write", out.display()))
}

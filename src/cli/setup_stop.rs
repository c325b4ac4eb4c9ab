//! The operator stops of `run` (issue 51): a plan over several setups streams setup 1, then
//! ends with an operator stop (journaled, exit [`OPERATOR_STOP_EXIT`]) asking to re-fixture
//! the part and measure the new placement; `run --resume` continues with the next setup's
//! plan only on the cell's workcell file of that setup with the placement the plan was made
//! for. One stop for every kind: `refixture`, and `tool_change` (`super::tool_stop`) between
//! the tools of a cell's tool library within a setup.
//!
//! A run streams the plan in stages: per setup (1 first) its plan, and in a plan with a tool
//! library (`tools[]`) per setup one stage per tool in the plan's tool sequence. The journal
//! numbers the stages (its `setup` field); in a plan without a tool library a stage is a setup
//! and its number the setup's.
use std::path::{Path, PathBuf};

use crate::bus::ResumePoint;
use crate::motion::file::ToolPart;
use crate::motion::setups::{placement_sha256, setup_file};
use crate::motion::Plan;
use crate::robot::{RobotConfig, Workcell};

/// Exit code of a run that ended at an operator stop (the plan is not finished; the
/// operator acts, then `run --resume`).
pub const OPERATOR_STOP_EXIT: u8 = 5;

/// The run ended for the operator: what to do before `run --resume`.
#[derive(Debug, Clone)]
pub struct OperatorStop {
    /// The stop's kind (`refixture`, `tool_change`).
    pub kind: String,
    /// The stage the run continues with (journal `setup`; a setup's number when the plan has
    /// no tool library).
    pub setup: u64,
    /// What the operator does next, one line.
    pub message: String,
    /// The journal the stop is written to (`run --resume` reads it).
    pub journal: PathBuf,
}

impl std::fmt::Display for OperatorStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "operator stop ({}): {}", self.kind, self.message)
    }
}

impl std::error::Error for OperatorStop {}

/// One stage of a plan as listed (its plan None when the setup or tool grinds nothing).
#[derive(Clone, Copy)]
pub struct StagePart<'a> {
    /// The setup (1 first).
    pub setup: usize,
    /// The library tool (None: the plan has no tool library).
    pub tool: Option<&'a ToolPart>,
    /// Its plan.
    pub plan: Option<&'a Plan>,
}

/// The stages of `plan` in the order a run streams them (the stage number is the index + 1).
pub fn stages(plan: &Plan) -> Vec<StagePart<'_>> {
    let setups = (1..=plan.setups.len().max(1)).map(|n| (n, setup_plan(plan, n)));
    let mut out = Vec::new();
    for (setup, p) in setups {
        let tools = p.map_or(&[][..], |p| &p.tools[..]);
        if tools.is_empty() {
            out.push(StagePart {
                setup,
                tool: None,
                plan: p,
            });
        }
        for (k, t) in tools.iter().enumerate() {
            let plan = if k == 0 { p } else { t.plan.as_deref() };
            out.push(StagePart {
                setup,
                tool: Some(t),
                plan,
            });
        }
    }
    out
}

/// Which part of the plan a run streams: its stage, that stage's plan and the first frame.
pub struct Stage<'a> {
    /// The stage's number (1 first; the journal's `setup`).
    pub number: usize,
    /// The setup (1 first).
    pub setup: usize,
    /// The library tool it grinds with (None: the plan has no tool library).
    pub tool: Option<&'a ToolPart>,
    /// Its plan (stage 1: the plan itself).
    pub plan: &'a Plan,
    /// The first frame to send; None: checked against the frames by the caller ([`from`]).
    resume: Option<ResumePoint>,
}

impl Stage<'_> {
    /// The first frame to send of the stage's `frames`: 0, or where the journal's run of this
    /// setup stood (its last frame written or whose write failed).
    pub fn from(&self, journal: Option<&Path>, frames: usize) -> anyhow::Result<usize> {
        let (Some(rp), Some(j)) = (&self.resume, journal) else {
            return Ok(0);
        };
        let from = rp.resume_from();
        anyhow::ensure!(
            from < frames as u64,
            "{}: --resume: the journal says frame {from} of stage {} (setup {}) was sent, but its plan has {frames} frames (arm and table)",
            j.display(),
            self.number,
            self.setup
        );
        Ok(from as usize)
    }
}

/// The stage a run of `plan` (file SHA-256 `sha`) streams: stage 1 from frame 0, or with
/// `--resume` the journal's (which must belong to this plan): after an operator stop the
/// stage it names from frame 0, else the stage it was streaming from where it stood.
pub fn stage<'a>(resume: Option<&Path>, sha: &str, plan: &'a Plan) -> anyhow::Result<Stage<'a>> {
    let all = stages(plan);
    let Some(j) = resume else {
        return Ok(Stage {
            number: 1,
            setup: 1,
            tool: all.first().and_then(|s| s.tool),
            plan,
            resume: None,
        });
    };
    let rp = ResumePoint::from_journal(j)?;
    match rp.plan_sha256.as_slice() {
        [h] if h == sha => {}
        [] => anyhow::bail!(
            "{}: --resume: the journal records no plan SHA-256 (not written by `run` of this \
             version): cannot tell which plan it belongs to",
            j.display()
        ),
        hashes => {
            anyhow::bail!(
            "{}: --resume: the journal belongs to another plan (SHA-256 {}), this plan's is {sha}",
            j.display(),
            hashes.iter().find(|h| *h != sha).map_or("?", |h| h.as_str())
        )
        }
    }
    let (number, resume) = match &rp.operator_stop {
        Some((_, next)) => (*next as usize, None),
        None => (rp.setup as usize, Some(rp)),
    };
    let part = number.checked_sub(1).and_then(|k| all.get(k));
    let Some(&StagePart {
        setup,
        tool,
        plan: Some(plan),
    }) = part
    else {
        anyhow::bail!("{}: --resume: the plan has no stage {number}", j.display())
    };
    Ok(Stage {
        number,
        setup,
        tool,
        plan,
        resume,
    })
}

/// Setup `n`'s plan (1: `plan` itself).
fn setup_plan(plan: &Plan, n: usize) -> Option<&Plan> {
    if n <= 1 {
        return Some(plan);
    }
    plan.setups.get(n - 1)?.plan.as_deref()
}

/// `robot` with the workcell of `setup` (its `setup-N/workcell.toml`), after checking that its
/// placement is the one `plan` was made for in that setup (plan.json `setups[].placement_sha256`).
pub fn cell_of(robot: &RobotConfig, plan: &Plan, setup: usize) -> anyhow::Result<RobotConfig> {
    let mut out = robot.clone();
    if setup <= 1 {
        return Ok(out);
    }
    out.workcell = setup_file(&robot.workcell, setup);
    let recorded = &plan.setups[setup - 1].placement_sha256;
    let now = placement_sha256(&Workcell::load(&out.workcell)?);
    anyhow::ensure!(
        &now == recorded,
        "{}: refused: setup {setup}'s placement is not the one the plan was made for (SHA-256 {}, the plan's {}): measure the re-fixtured part with `polishbot calibrate workcell --setup {setup}`; if it was measured, re-plan",
        out.workcell.display(),
        &now[..12],
        &recorded[..recorded.len().min(12)]
    );
    Ok(out)
}

/// The operator stop after stage `done` of `plan` (file `plan_file`, journal `journal`): the
/// next stage with a plan, or None when none is left: a tool change within the setup
/// ([`super::tool_stop::message`]), else a re-fixture (naming the tool to mount when it
/// changes too). `run` journals it after the stage's last frame (`Bus::operator_stop`) and
/// ends with it: the one path of every operator stop.
pub fn next_stop(
    plan: &Plan,
    done: usize,
    journal: &Path,
    plan_file: &Path,
) -> Option<OperatorStop> {
    let all = stages(plan);
    let was = all.get(done.checked_sub(1)?)?;
    let (k, now) = (all.iter().enumerate().skip(done)).find(|(_, s)| s.plan.is_some())?;
    let next = k + 1;
    let resume = format!(
        "`polishbot run --plan {} --resume {} ...`",
        plan_file.display(),
        journal.display()
    );
    let (kind, message) = if now.setup == was.setup {
        let mount = super::tool_stop::message(now.tool, was.tool);
        (
            super::tool_stop::TOOL_CHANGE,
            format!("setup {}: {mount}, then {resume}", now.setup),
        )
    } else {
        let part = &plan.setups[now.setup - 1];
        let tool = match (now.tool, was.tool) {
            (Some(t), Some(w)) if t.tool != w.tool => {
                format!("; {}", super::tool_stop::message(now.tool, was.tool))
            }
            _ => String::new(),
        };
        let message = format!(
            "setup {} done; re-fixture the part as setup {} (mounted as {} places it; {} region(s) left for it){tool}, run `polishbot calibrate workcell --setup {} ...` if that placement is not measured yet, then {resume}",
            was.setup,
            now.setup,
            part.workcell,
            part.regions.len(),
            now.setup,
        );
        ("refixture", message)
    };
    Some(OperatorStop {
        kind: kind.into(),
        setup: next as u64,
        message,
        journal: journal.to_path_buf(),
    })
}

/// Most tool changes the simulated operator makes in one `run --sim` (a plan changes tools
/// at most once per tool and setup; a library holds at most 16 tools and a cell 9 setups).
const MAX_SIMULATED_CHANGES: usize = 16 * 9;

/// `run --sim`'s operator: runs `stream` (a run from the start, then with the journal to
/// resume from) and, while it ends at a tool change, mounts the tool asked for (prints it)
/// and resumes; any other stop or error ends it.
pub fn simulated_operator(
    mut stream: impl FnMut(Option<&Path>) -> anyhow::Result<()>,
    resume: Option<&Path>,
) -> anyhow::Result<()> {
    let mut from = resume.map(Path::to_path_buf);
    for _ in 0..=MAX_SIMULATED_CHANGES {
        match stream(from.as_deref()) {
            Err(e) => match e.downcast::<OperatorStop>() {
                Ok(stop) if stop.kind == super::tool_stop::TOOL_CHANGE => {
                    println!("run: simulated operator: {}", stop.message);
                    from = Some(stop.journal);
                }
                Ok(stop) => return Err(stop.into()),
                Err(e) => return Err(e),
            },
            done => return done,
        }
    }
    anyhow::bail!("run: the simulated operator made more than {MAX_SIMULATED_CHANGES} tool changes")
}

//! The operator stops of `run` (issue 51): a plan over several setups streams setup 1, then
//! ends with an operator stop (journaled, exit [`OPERATOR_STOP_EXIT`]) asking to re-fixture
//! the part and measure the new placement; `run --resume` continues with the next setup's
//! plan only on the cell's workcell file of that setup with the placement the plan was made
//! for. One stop for every kind (`refixture`; a tool change is the next).
use std::path::Path;

use crate::bus::ResumePoint;
use crate::motion::setups::{placement_sha256, setup_file};
use crate::motion::Plan;
use crate::robot::{RobotConfig, Workcell};

/// Exit code of a run that ended at an operator stop (the plan is not finished; the
/// operator acts, then `run --resume`).
pub const OPERATOR_STOP_EXIT: u8 = 5;

/// The run ended for the operator: what to do before `run --resume`.
#[derive(Debug, Clone)]
pub struct OperatorStop {
    /// The stop's kind (`refixture`).
    pub kind: String,
    /// The setup the run continues with.
    pub setup: u64,
    /// What the operator does next, one line.
    pub message: String,
}

impl std::fmt::Display for OperatorStop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "operator stop ({}): {}", self.kind, self.message)
    }
}

impl std::error::Error for OperatorStop {}

/// Which part of the plan a run streams: its setup, that setup's plan and the first frame.
pub struct Stage<'a> {
    /// The setup (1 first).
    pub setup: usize,
    /// Its plan (setup 1: the plan itself).
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
            "{}: --resume: the journal says frame {from} of setup {} was sent, but its plan has {frames} frames (arm and table)",
            j.display(),
            self.setup
        );
        Ok(from as usize)
    }
}

/// The stage a run of `plan` (file SHA-256 `sha`) streams: setup 1 from frame 0, or with
/// `--resume` the journal's (which must belong to this plan): after an operator stop the
/// setup it names from frame 0, else the setup it was streaming from where it stood.
pub fn stage<'a>(resume: Option<&Path>, sha: &str, plan: &'a Plan) -> anyhow::Result<Stage<'a>> {
    let Some(j) = resume else {
        return Ok(Stage {
            setup: 1,
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
    let (setup, resume) = match &rp.operator_stop {
        Some((_, next)) => (*next as usize, None),
        None => (rp.setup as usize, Some(rp)),
    };
    let plan = setup_plan(plan, setup).ok_or_else(|| {
        anyhow::anyhow!("{}: --resume: the plan has no setup {setup}", j.display())
    })?;
    Ok(Stage {
        setup,
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

/// The operator stop after setup `done` of `plan` (file `plan_file`, journal `journal`): the
/// next setup with a plan, or None when none is left. `run` journals it after the setup's
/// last frame (`Bus::operator_stop`) and ends with it: the one path of every operator stop.
pub fn next_stop(
    plan: &Plan,
    done: usize,
    journal: &Path,
    plan_file: &Path,
) -> Option<OperatorStop> {
    let next = (done + 1..=plan.setups.len()).find(|&n| setup_plan(plan, n).is_some())?;
    let part = &plan.setups[next - 1];
    let message = format!(
        "setup {done} done; re-fixture the part as setup {next} (mounted as {} places it; {} region(s) left for it), run `polishbot calibrate workcell --setup {next} ...` if that placement is not measured yet, then `polishbot run --plan {} --resume {} ...`",
        part.workcell,
        part.regions.len(),
        plan_file.display(),
        journal.display()
    );
    Some(OperatorStop {
        kind: "refixture".into(),
        setup: next as u64,
        message,
    })
}

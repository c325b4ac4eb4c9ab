//! The loop's one settings struct: the stop rule and the settings of the stages it calls.
use super::plan_stage::PlanFileConfig;
use crate::inspect::InspectConfig;

/// Default least share of the planned excess volume an iteration must remove to go on: a
/// rigid depth-layer pass at the nominal k takes about 0.03 mm off a 0.14 mm region's mean
/// (20 % of its excess, measured in tests/grind_sim.rs), while a rescan and a new
/// registration alone move a region's volume by a few per cent; 5 % separates an iteration
/// that ground from one that only re-measured the same part.
pub const DEFAULT_MIN_PROGRESS: f64 = 0.05;

/// Default number of grinding iterations (issue 29: "after `--max-iterations` (3)").
pub const DEFAULT_MAX_ITERATIONS: usize = 3;

/// Largest `--footprint-radius`, mm (5: the adaptive comparison's widest cylinders are about
/// 3.7 mm; a wider second reading smooths more than the first, not less).
pub const MAX_FOOTPRINT_RADIUS_MM: f64 = 5.0;

/// Default first grind planned on the removal ledger (`super::ledger`) where it reads lower than
/// the rescan (4). 8-grind surveys (ten cases x cell seeds 29-31, true k 1.3 x, main 175a683):
/// no run's grinds 1-3 took a true point below -tolerance on either arm, while grinds 4-8 did
/// in 10 (documented arm) and 5 (ideal arm) of 30 runs, through small losses at points the
/// rescans read 0.04-0.15 mm above their truth; the ledger from grind 2 on held every run of
/// 52 above -0.035 mm but stopped the loop for no progress at a median share of 16 / 13 %
/// (30 / 27 % after grind 3 without it). From grind 4 on, grinds 1-3 are planned as before and
/// the loop stopped for no progress after grind 4 in 25 / 26 runs (after grind 5 in 2 / 1),
/// none gouged.
pub const LEDGER_FROM_GRIND: usize = 4;

/// Settings of the loop: its stop rule and the settings every iteration's inspection and plan
/// are made with (the run's are its executor's, [`super::Executor`]).
#[derive(Debug, Clone)]
pub struct CycleConfig {
    /// Most grinding iterations (default [`DEFAULT_MAX_ITERATIONS`]).
    pub max_iterations: usize,
    /// Least share of the planned excess volume an iteration must remove (default
    /// [`DEFAULT_MIN_PROGRESS`]).
    pub min_progress: f64,
    /// Radius of the second reading of every inspection that the planner reads, mm
    /// (`--footprint-radius`; default None: the planner reads the adaptive comparison; the
    /// tool's patch radius, `super::FINE_RADIUS_MM`, is what was measured: docs/ALGORITHMS.md,
    /// "The loop reads at the tool's footprint").
    pub footprint_radius_mm: Option<f64>,
    /// The first grind planned at the removal ledger's values where they are lower than the
    /// rescan's (`super::ledger`; default [`LEDGER_FROM_GRIND`]; None: never,
    /// `--no-removal-ledger`); at least 2.
    pub ledger_from_grind: Option<usize>,
    /// Every inspection's settings (`inspect`'s).
    pub inspect: InspectConfig,
    /// Every plan's settings (`plan`'s); the loop sets `robot.tool` to the tool file it fitted.
    pub plan: PlanFileConfig,
    /// The plan settings as the user wrote them (cycle's `[plan]` table), written with the
    /// fitted tool to iter-K/plan.toml so that `plan --config` can make the plan again.
    pub plan_table: toml::Table,
}

impl Default for CycleConfig {
    fn default() -> Self {
        CycleConfig {
            max_iterations: DEFAULT_MAX_ITERATIONS,
            min_progress: DEFAULT_MIN_PROGRESS,
            footprint_radius_mm: None,
            ledger_from_grind: Some(LEDGER_FROM_GRIND),
            inspect: InspectConfig::default(),
            plan: PlanFileConfig::default(),
            plan_table: toml::Table::new(),
        }
    }
}

impl CycleConfig {
    /// Checks the settings; the message names the flag.
    pub fn check(&self) -> Result<(), String> {
        if self.max_iterations == 0 {
            return Err("--max-iterations must be at least 1".into());
        }
        if !(0.0..=1.0).contains(&self.min_progress) {
            return Err(format!(
                "--min-progress must be a share between 0 and 1, not {}",
                self.min_progress
            ));
        }
        if self.ledger_from_grind.is_some_and(|g| g < 2) {
            return Err("the removal ledger starts at grind 2 at the earliest".into());
        }
        if let Some(r) = self.footprint_radius_mm {
            if !(r.is_finite() && r > 0.0 && r <= MAX_FOOTPRINT_RADIUS_MM) {
                return Err(format!(
                    "--footprint-radius must be a radius in mm above 0 and at most \
                     {MAX_FOOTPRINT_RADIUS_MM}, not {r}"
                ));
            }
        }
        Ok(())
    }
}

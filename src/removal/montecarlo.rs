//! The arm's position error propagated into the predicted residual by Monte Carlo: every draw
//! displaces each contact by its servo quantisation (per contact), backlash and a tool-tip
//! error (both systematic within a draw) and scales Preston's k; a displacement along the
//! normal changes the contact's penetration (its preload and the part's deviation there,
//! `press.rs`), hence the force and the Hertz patch; along the surface it moves the patch, and
//! on a spring-loaded spindle the normal part slides it too (`press::axial_give`).
use nalgebra::{DMatrix, DVector, Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::influence::{Contact, Influence, Reach};
use super::tool::{ComplianceDirection, ToolModel};

/// Radius of the core points gathered once per contact for all draws, as a multiple of its
/// nominal reach (patch radius + half its piece) (2): a draw moves a contact by about a tenth
/// of a millimetre and changes its patch by a few percent, well inside twice the reach; a draw
/// that leaves it queries the index itself, so the factor sets the speed only, not the answer.
const CANDIDATE_REACH_FACTOR: f64 = 2.0;

/// Relative slack for rounding when a draw's reach is compared with the gathered radius.
const ROUNDING: f64 = 1e-9;

/// Tool-tip error of a cell with no record, mm per axis (0.12): 0.119 mm, the worst tool tip
/// `calibrate verify --sim` measured on the ideal simulated cell when this was set; a cell
/// with backlash or sag shows more, which is why its own record (tool.toml's
/// `verified_tip_error_mm`) replaces it.
pub const DEFAULT_TIP_ERROR_MM: f64 = 0.12;

/// The tip error the Monte Carlo draws from and where it comes from.
#[derive(Debug, Clone, PartialEq)]
pub struct TipError {
    /// Half-width per axis, mm.
    pub mm: f64,
    /// Its source in words (plan.json's `tip_error_source`).
    pub source: String,
}

/// The tip error of the cell: `tool`'s `verified_tip_error_mm` (the worst tool tip
/// `calibrate verify` measured) when recorded, else `config.tip_error_mm` with the reason.
pub fn tip_error(tool: &ToolModel, config: &MonteCarloConfig) -> TipError {
    match tool.verified_tip_error_mm {
        Some(mm) => TipError {
            mm,
            source: "tool.toml [removal] verified_tip_error_mm (calibrate verify's worst tool tip)"
                .into(),
        },
        None => TipError {
            mm: config.tip_error_mm,
            source: format!(
                "[monte_carlo] tip_error_mm (the cell has no calibrate verify record; default \
                 {DEFAULT_TIP_ERROR_MM} mm: calibrate verify --sim on the ideal simulated cell)"
            ),
        },
    }
}

/// Settings of the Monte Carlo.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MonteCarloConfig {
    /// Draws (50).
    pub draws: usize,
    /// Seed of the draws (28): a plan is reproducible.
    pub seed: u64,
    /// Backlash per servo not already in `tip_error_mm`, degrees (0: `calibrate verify`
    /// moves to its poses the way a plan does and measures the tip there, so what backlash
    /// the cell shows is in its tip error; DOFBOT.md's "up to 1 deg per servo" is a
    /// worst case kept for a cell that was not verified); each draw puts every joint
    /// uniformly within +-half of it.
    pub backlash_deg: f64,
    /// Tool-tip error when the cell has no record of its own, mm per axis
    /// ([`DEFAULT_TIP_ERROR_MM`]); each draw shifts the tip uniformly within +-the tip error
    /// on every axis. The cell's record wins: tool.toml's `[removal] verified_tip_error_mm`,
    /// the worst tool tip `calibrate verify` measured ([`tip_error`]).
    pub tip_error_mm: f64,
    /// Share of the 95th percentile taken as the verdict (0.95).
    pub quantile: f64,
}

impl Default for MonteCarloConfig {
    fn default() -> Self {
        MonteCarloConfig {
            draws: 50,
            seed: 28,
            backlash_deg: 0.0,
            tip_error_mm: DEFAULT_TIP_ERROR_MM,
            quantile: 0.95,
        }
    }
}

impl MonteCarloConfig {
    /// Checks the settings against their ranges; the message names the first key outside its
    /// range with its value.
    pub fn check(&self) -> Result<(), String> {
        use crate::settings::in_range;
        if !(1..=MAX_DRAWS).contains(&self.draws) {
            let n = self.draws;
            return Err(format!(
                "`monte_carlo.draws` = {n} is outside 1..={MAX_DRAWS}"
            ));
        }
        let backlash = self.backlash_deg;
        in_range(
            "monte_carlo.backlash_deg",
            backlash,
            0.0,
            MAX_BACKLASH_DEG,
            "deg",
        )?;
        let tip = self.tip_error_mm;
        in_range(
            "monte_carlo.tip_error_mm",
            tip,
            0.0,
            super::tool::MAX_TIP_ERROR_MM,
            "mm",
        )?;
        match (0.5..1.0).contains(&self.quantile) {
            true => Ok(()),
            false => Err(format!(
                "`monte_carlo.quantile` = {:?} is outside 0.5..1 (1 excluded)",
                self.quantile
            )),
        }
    }
}

/// Most draws (`monte_carlo.draws`): 200 times the default 50; each draw re-evaluates every
/// contact's patch, so more only costs time without changing the 95th percentile.
const MAX_DRAWS: usize = 10_000;

/// Largest backlash per servo drawn (`monte_carlo.backlash_deg`), degrees: ten times
/// DOFBOT.md's worst case of 1 degree; more is a worn-out arm, not a tolerance.
const MAX_BACKLASH_DEG: f64 = 10.0;

/// How one contact's joints move its tip: `sensitivity` (3 x dof, mm per rad, the frame of
/// the contact points) and each joint's quantisation half-step, rad (half a raw count).
#[derive(Debug, Clone, PartialEq)]
pub struct JointError {
    /// Tip displacement per joint angle, mm/rad.
    pub sensitivity: DMatrix<f64>,
    /// Half a raw count per joint, rad.
    pub half_count: Vec<f64>,
}

/// The predicted residual's spread per core point.
#[derive(Debug, Clone, PartialEq)]
pub struct Spread {
    /// Residual per draw and core point, mm: `draws[d][j]`.
    pub draws: Vec<Vec<f64>>,
}

impl Spread {
    /// The `1 - quantile` low quantile of the residual at every core point, mm (the deepest
    /// cut that `quantile` of the draws stay above).
    pub fn low(&self, quantile: f64) -> Vec<f64> {
        let n = self.draws.first().map_or(0, Vec::len);
        (0..n)
            .map(|j| {
                let mut v: Vec<f64> = self.draws.iter().map(|d| d[j]).collect();
                v.sort_by(f64::total_cmp);
                let k = ((1.0 - quantile) * (v.len() - 1) as f64).round() as usize;
                v[k]
            })
            .collect()
    }
}

/// Contact `c` with the commanded ball centre moved by `shift` mm: its part along the normal
/// changes the contact's penetration (its preload and the part's deviation there,
/// `press.rs`), its part along the surface moves the patch; a spring-loaded spindle
/// (`compliance_direction = "spindle_axis"`) also slides the patch by the normal part times
/// tan(tilt) and changes the force as `press::axial_give` says.
fn displaced(tool: &ToolModel, c: &Contact, shift: &Vector3<f64>) -> Contact {
    let along_normal = shift.dot(&c.normal);
    let across = shift - c.normal * along_normal;
    if tool.compliance_direction == ComplianceDirection::SpindleAxis {
        let (per_mm, slide) = super::press::axial_give(tool, c);
        return Contact {
            point: c.point + across + slide * along_normal,
            force_ratio: (c.force_ratio - per_mm * along_normal).max(0.0),
            ..*c
        };
    }
    // the tool moved outward by `along_normal` presses that much less than the contact's own
    // penetration (the part's deviation counted, `press.rs`)
    let penetration = c.force_ratio * tool.preload_mm - along_normal;
    Contact {
        point: c.point + (shift - c.normal * along_normal),
        force_ratio: tool.force_ratio(penetration),
        ..*c
    }
}

/// Residuals of `dwell` over `cores` (positions, normals, deviations) under `config`'s draws:
/// `tool` on a ball of `ball_mm`, `joints[i]` the error model of contact i.
pub fn spread(
    tool: &ToolModel,
    ball_mm: f64,
    contacts: &[Contact],
    joints: &[JointError],
    dwell: &[f64],
    cores: &[(Point3<f64>, Vector3<f64>, f64)],
    config: &MonteCarloConfig,
) -> Spread {
    let geometry: Vec<(Point3<f64>, Vector3<f64>)> = cores.iter().map(|c| (c.0, c.1)).collect();
    let reach = Reach::new(&geometry);
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let dof = joints.first().map_or(0, |j| j.half_count.len());
    let half_backlash = 0.5 * config.backlash_deg.to_radians();
    let tip_half = tip_error(tool, config).mm;
    // Preston's k uniform with the model's standard deviation: half-width sqrt(3) sd
    let k_half = 3f64.sqrt() * tool.preston_k_rel_sd;
    let nominal = Influence::new(tool, ball_mm);
    let gathered: Vec<(f64, Vec<usize>)> = contacts
        .iter()
        .map(|c| {
            let extent = nominal.reach_at(c.force_ratio);
            let radius = CANDIDATE_REACH_FACTOR * (extent + 0.5 * c.length);
            (radius, reach.candidates(&c.centre(), radius))
        })
        .collect();
    let draws = (0..config.draws)
        .map(|_| {
            let backlash = DVector::from_fn(dof, |_, _| rng.gen_range(-1.0..=1.0) * half_backlash);
            let tip = Vector3::from_fn(|_, _| rng.gen_range(-1.0..=1.0) * tip_half);
            let k_scale = 1.0 + k_half * rng.gen_range(-1.0..=1.0);
            let drawn = ToolModel {
                preston_k_mm2_n: tool.preston_k_mm2_n * k_scale.max(0.0),
                ..tool.clone()
            };
            let influence = Influence::new(&drawn, ball_mm);
            let mut removal = vec![0.0; cores.len()];
            let each = contacts.iter().zip(joints).zip(dwell).zip(&gathered);
            for (((c, je), t), (radius, near)) in each {
                let quant =
                    DVector::from_fn(dof, |i, _| rng.gen_range(-1.0..=1.0) * je.half_count[i]);
                let d = &je.sensitivity * (&backlash + quant);
                let shift = Vector3::new(d[0], d[1], d[2]) + tip;
                let moved = displaced(tool, c, &shift);
                if moved.force_ratio <= 0.0 {
                    continue;
                }
                let needs = (moved.point - c.point).norm() + influence.reach_at(moved.force_ratio);
                let column = match needs + 0.5 * c.length <= *radius * (1.0 - ROUNDING) {
                    true => reach.column_among(&influence, &moved, near),
                    false => reach.column(&influence, &moved),
                };
                for (j, v) in column {
                    removal[j] += v * t;
                }
            }
            cores.iter().zip(removal).map(|(c, r)| c.2 - r).collect()
        })
        .collect();
    Spread { draws }
}

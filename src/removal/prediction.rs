//! The part predicted after a removal plan, as data: the dwell map and the predicted
//! deviation per region (plan.json's `removal`), and one row per core point (predicted.csv,
//! read back by the k fit through `matching::parse_predicted`).
use serde::{Deserialize, Serialize};

use super::Stats;

/// One contact of the dwell map in plan.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DwellPoint {
    /// Contact point (middle of its piece of stroke), reference frame, mm.
    pub surface_mm: [f64; 3],
    /// Time the trajectory spends on the piece, s, plus the dwell-equivalent of a press into
    /// or out of it (`press_dwell`).
    pub dwell_s: f64,
    /// Mean speed over the piece, mm/s.
    pub feed_mm_s: f64,
}

/// The removal planned over one region and the part predicted after it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionPrediction {
    /// Region id.
    pub region: usize,
    /// Allowance the robust solve settled on, mm.
    pub allowance_mm: f64,
    /// The dwell map, one entry per contact in program order.
    pub dwell: Vec<DwellPoint>,
    /// Core points of the region and its neighbours in the tool's reach.
    pub core_points: usize,
    /// Deviation before grinding over those points.
    pub before: Stats,
    /// Predicted deviation after grinding (nominal model).
    pub after: Stats,
    /// Lowest 5th-percentile residual of the Monte Carlo, mm (below -tolerance: over-grind).
    pub after_low_p95_mm: f64,
}

/// The removal part of plan.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RemovalReport {
    /// Contact force at the preload, N.
    pub force_n: f64,
    /// The preload: how far the ball is pressed inside the surface while it grinds, mm
    /// (`run` re-checks the grinding samples with it).
    pub preload_mm: f64,
    /// Tolerance, mm: over-grind is a residual below -tolerance.
    pub tolerance_mm: f64,
    /// The Monte Carlo's tool-tip error, mm per axis (`montecarlo::tip_error`). Absent in
    /// plans from before 2026-12-05: 0.
    #[serde(default)]
    pub tip_error_mm: f64,
    /// Where that tip error comes from: the cell's `calibrate verify` record, or the default
    /// and why. Absent in older plans: empty.
    #[serde(default)]
    pub tip_error_source: String,
    /// Per planned region.
    pub regions: Vec<RegionPrediction>,
    /// One row per core point (predicted.csv; not in plan.json).
    #[serde(skip)]
    pub rows: Vec<PredictedRow>,
}

/// One row of predicted.csv.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PredictedRow {
    /// Core point, reference frame, mm.
    pub position: [f64; 3],
    /// Deviation before grinding, mm.
    pub deviation: f64,
    /// Predicted residual (nominal model), mm.
    pub residual: f64,
    /// Width of the Monte Carlo's residual between its median and its low quantile, mm.
    pub spread_p95: f64,
}

/// predicted.csv: a header and one row per core point, `spread_p95` empty when the Monte
/// Carlo drew nothing.
pub fn predicted_csv(report: &RemovalReport, mc: &super::montecarlo::MonteCarloConfig) -> String {
    let mut out = String::from("x,y,z,deviation,predicted_residual,spread_p95\n");
    for r in &report.rows {
        let spread = if mc.draws > 0 {
            format!("{:.6}", r.spread_p95)
        } else {
            String::new()
        };
        out.push_str(&format!(
            "{:.6},{:.6},{:.6},{:.6},{:.6},{spread}\n",
            r.position[0], r.position[1], r.position[2], r.deviation, r.residual
        ));
    }
    out
}

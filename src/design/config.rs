//! The cell design's settings ([`DesignConfig`]) and the table axes its grid tries.
use std::f64::consts::FRAC_1_SQRT_2;

/// Table axes of the grid (robot frame; the fixture is on the lower side, so none points
/// down): vertical, horizontal across and along the arm plane, tilted 45 degrees on a
/// bracket towards, away from and across the arm plane.
pub const AXES: [[f64; 3]; 6] = [
    [0.0, 0.0, 1.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -FRAC_1_SQRT_2, FRAC_1_SQRT_2],
    [0.0, FRAC_1_SQRT_2, FRAC_1_SQRT_2],
    [FRAC_1_SQRT_2, 0.0, FRAC_1_SQRT_2],
];

/// Settings of the cell design. Every field has a documented default.
#[derive(Debug, Clone)]
pub struct DesignConfig {
    /// Articular-surface samples scored per candidate in the coarse grid (80: the grid has
    /// thousands of candidates; 80 samples tell a 90 % mounting from a 60 % one).
    pub coarse_samples: usize,
    /// Samples scored per candidate in the ranking and refinement stages (250).
    pub samples: usize,
    /// Samples of the final score printed and drawn (1,500: about 3 per square centimetre of a
    /// femoral articular surface, 0.1 % steps).
    pub final_samples: usize,
    /// Points of the part's collision model (6,000: about 1.7 mm apart on a femoral component,
    /// under the 3 mm ball radius the second-face test needs).
    pub part_points: usize,
    /// Table angle step of the coarse grid, degrees (30).
    pub coarse_step_deg: f64,
    /// Table angle step of the later stages, degrees (10).
    pub step_deg: f64,
    /// Shank lengths tried (ball centre to flange), metres (19.3 mm, the shipped tool; 35 and
    /// 50 mm, stock long-shank burrs).
    pub shanks_m: Vec<f64>,
    /// Distances of the table centre from the base axis along the arm plane, metres.
    pub distances_m: Vec<f64>,
    /// Heights of the table centre above the base plane, metres.
    pub heights_m: Vec<f64>,
    /// Candidates of the coarse grid kept for ranking (16).
    pub keep: usize,
    /// Rounds of local refinement around the best candidate (3).
    pub rounds: usize,
    /// Seed of the surface samples (1).
    pub seed: u64,
    /// Table axes of the grid, robot frame (default: vertical; horizontal across and along
    /// the arm plane; tilted 45 degrees on a bracket towards, away from and across it).
    pub axes: Vec<[f64; 3]>,
    /// Fixturings of the part scored for the designed cell, the first included (2: one
    /// re-fixturing brings the faces along the table axis into reach; 1: the part is mounted
    /// once). Scored after the search, which designs the cell for the first.
    pub setups: usize,
}

impl Default for DesignConfig {
    fn default() -> Self {
        DesignConfig {
            coarse_samples: 80,
            samples: 250,
            final_samples: 1500,
            part_points: 6000,
            coarse_step_deg: 30.0,
            step_deg: 10.0,
            shanks_m: vec![0.0193, 0.035, 0.05],
            distances_m: vec![0.14, 0.19, 0.24],
            heights_m: vec![0.06, 0.11, 0.16, 0.21],
            keep: 16,
            rounds: 3,
            seed: 1,
            axes: AXES.to_vec(),
            setups: 2,
        }
    }
}

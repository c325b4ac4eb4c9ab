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
    /// Table angle step of the ranking and refinement stages, degrees (10).
    pub step_deg: f64,
    /// Table angle step of the final score, the further setups and the family, degrees (5:
    /// the planner's candidate table angles are 5 degrees apart, `motion::table`, so a
    /// sample reached only between two 10-degree steps is reached by the planner too).
    pub final_step_deg: f64,
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
    /// Candidates of the ranking stage (best first) whose setups are scored at the end of the
    /// search beside the refined winner, on the ranking's samples (8): the cell is the one
    /// whose setups reach most together, since the part is re-fixtured anyway (0: the refined
    /// winner of setup 1 alone, as before).
    pub finalists: usize,
    /// Seed of the surface samples (1).
    pub seed: u64,
    /// Table axes of the grid, robot frame (default: vertical; horizontal across and along
    /// the arm plane; tilted 45 degrees on a bracket towards, away from and across it).
    pub axes: Vec<[f64; 3]>,
    /// Fixturings of the part scored for the designed cell, the first included (2: one
    /// re-fixturing brings the faces along the table axis into reach; 1: the part is mounted
    /// once). Scored after the search, which designs the cell for the first.
    pub setups: usize,
    /// Angles between a further setup's mounting and the first one's, degrees (60, 75, 90:
    /// at 90 the faces along the first axis turn fully into the plane the table rotates the
    /// part in; 60 and 75 keep more of what the first setup reached in reach as well).
    pub setup_tilts_deg: Vec<f64>,
    /// Step of the further mountings' direction about the first mounting, degrees (30: 12
    /// per tilt, each scored on the final samples).
    pub setup_azimuth_step_deg: f64,
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
            final_step_deg: 5.0,
            shanks_m: vec![0.0193, 0.035, 0.05],
            distances_m: vec![0.14, 0.19, 0.24],
            heights_m: vec![0.06, 0.11, 0.16, 0.21],
            keep: 16,
            rounds: 3,
            finalists: 8,
            seed: 1,
            axes: AXES.to_vec(),
            setups: 2,
            setup_tilts_deg: vec![60.0, 75.0, 90.0],
            setup_azimuth_step_deg: 30.0,
        }
    }
}

//! The merge stage's settings ([`MergeConfig`]).
use serde::{Deserialize, Serialize};

/// Default angle tolerance, degrees: a turntable's angles are known to a few degrees at
/// worst (the synthetic table errs by up to 3); a match needing more is a wrong match. Views
/// are corrected against the first view, whose angle errs too: corrections may reach twice
/// the tolerance and span twice it about the axis.
pub const DEFAULT_ANGLE_TOLERANCE: f64 = 5.0;

/// Settings of the merge stage (lengths in mm, angles in degrees).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MergeConfig {
    /// Table axis direction in the views' frame. The table turns the part by +angle about
    /// it, so view i's start pose is the rotation by -(angle_i - angle_0). Default none: the
    /// axis is estimated from the first neighbouring pair that registers.
    pub axis: Option<[f64; 3]>,
    /// A point on the table axis (default: the estimated axis' point at the height of the
    /// first view's centroid, or that centroid when the axis is given).
    pub centre: Option<[f64; 3]>,
    /// Most points of a moving view used by the pairwise ICP (evenly strided; default 10,000).
    pub icp_max_points: usize,
    /// Most points of a view used as the ICP target, with PCA normals (evenly strided;
    /// default 30,000).
    pub icp_target_points: usize,
    /// First ICP correspondence distance in multiples of the mean spacing mr (default 30).
    pub start_distance: f64,
    /// Final ICP correspondence distance and fitness distance, in mr (default 3).
    pub final_distance: f64,
    /// Iteration cap of each ICP stage (default 30).
    pub icp_max_iterations: usize,
    /// Least share of a view's points within the final distance of its neighbour for an
    /// alignment to count (default 0.3).
    pub min_fitness: f64,
    /// Skip a view that cannot be aligned instead of failing (default false).
    pub skip_bad: bool,
    /// The table's stated angle accuracy a, degrees (default 5): each true table angle is
    /// within a of its nominal one. A view's pose is its turn from the first view, so a match
    /// is rejected when its rotation against the nominal pose exceeds 2a, or when the accepted
    /// views' corrections about the axis (the first view's 0 among them) would span more
    /// than 2a with it.
    pub angle_tolerance: f64,
    /// Refine all poses jointly over every overlapping pair after placing them (default true).
    pub global: bool,
    /// Refine each placed view by a short-range ICP onto the union of the placed views it
    /// overlaps (default false: on the 36-view synthetic turn the refinement moved views
    /// 25-29 by 0.01-0.8 degrees off their pairwise pull, which was within 0.002 of the truth,
    /// and the error grew along the turn; the global step ties the views together instead).
    pub model_refine: bool,
    /// Voxel of the joined cloud (default: the first view's mean spacing).
    pub voxel: Option<f64>,
    /// Statistical outlier filter on the joined cloud (default false).
    pub sor: bool,
    /// Estimate normals of the joined cloud (default true).
    pub normals: bool,
}

impl Default for MergeConfig {
    fn default() -> Self {
        MergeConfig {
            axis: None,
            centre: None,
            icp_max_points: 10_000,
            icp_target_points: 30_000,
            start_distance: 30.0,
            final_distance: 3.0,
            icp_max_iterations: 30,
            min_fitness: 0.3,
            skip_bad: false,
            angle_tolerance: DEFAULT_ANGLE_TOLERANCE,
            global: true,
            model_refine: false,
            voxel: None,
            sor: false,
            normals: true,
        }
    }
}

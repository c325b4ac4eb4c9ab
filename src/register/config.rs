//! The registration stage's settings.
use serde::{Deserialize, Serialize};

/// Default coarse voxel in units of the cloud resolution mr. 15 mr leaves about 6k / 7.6k
/// points of a 400k / 300k femoral case. Against 10 mr (the fine ICP on 40,000 points both
/// times), on the 20 synth cases of tests/register.rs: the final poses are as close to the
/// truth (worst 0.0014 deg / 0.0009 mm), the coarse ones stay well inside the fine ICP's
/// reach (worst 0.64 deg / 0.36 mm against 0.23 deg / 0.18 mm), and registration of the
/// 400k / 300k bench case takes 0.57-0.59 s instead of 0.70-0.71 s (FPFH 0.10 s instead of
/// 0.18 s). 5 mr took 1.6-2.2 s on an older machine where 10 mr took 1.0-1.4 s.
pub const VOXEL_SPACINGS: f64 = 15.0;

/// Settings of the registration stage. Lengths in mm; `None` lengths derive from the cloud
/// resolution `mr` (mean nearest-neighbour spacing, the larger of the two clouds').
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegisterConfig {
    /// Voxel size of the coarse stage (default [`VOXEL_SPACINGS`] mr).
    pub voxel: Option<f64>,
    /// Normal estimation radius on the voxel clouds (default 2 voxel), at most 30 neighbours.
    pub normal_radius: Option<f64>,
    /// FPFH radius (default 5 voxel), at most `feature_max_nn` neighbours.
    pub feature_radius: Option<f64>,
    /// Neighbour cap of the FPFH search (default 100, as Open3D's tutorial).
    pub feature_max_nn: usize,
    /// Most scan points that get a descriptor (evenly strided over the voxel cloud; the
    /// reference is described everywhere; default 8,000).
    pub max_keypoints: usize,
    /// Keep only mutual nearest feature matches (default true).
    pub mutual: bool,
    /// Cap on correspondences, smallest feature distance first (default 3000).
    pub max_correspondences: usize,
    /// Compatibility scale d_cs (default 1 voxel).
    pub compat_sigma: Option<f64>,
    /// First-order graph cut on exp(-d²/(2 d_cs²)) (default 0.6, i.e. d ≤ 1.01 d_cs).
    pub compat_min_score: f64,
    /// Inlier threshold tau of the hypothesis score (default 1.5 voxel).
    pub inlier_threshold: Option<f64>,
    /// Smallest clique (default 3).
    pub min_clique: usize,
    /// Cap on maximal cliques enumerated (default 30,000; each start vertex gets at least
    /// an equal share, and no more than max(share, 64)). Against 100,000: the clique search
    /// of the bench case 0.10 s instead of 0.14 s; on tests/register.rs the same final poses,
    /// the worst coarse one 0.67 deg / 0.38 mm instead of 0.64 deg / 0.36 mm.
    pub max_cliques: usize,
    /// Time budget of the clique search in seconds (default 30): a guard against a
    /// pathological graph, not a tuning. The clique cap (`max_cliques`) is what bounds the
    /// search: about 0.1 s on the bench case on an idle machine. The old default of 2 s was
    /// reached at a load of 15 on 2 cores (0.8x to 1x the cap's cliques found), so the coarse
    /// pose, and on synth seed 3 the deviations, depended on the machine's load; 30 s leaves a
    /// 300x margin.
    pub clique_time_budget: f64,
    /// Cliques kept after node-guided selection (default 200).
    pub top_k: usize,
    /// Distinct hypotheses ranked by a short ICP (default 5).
    pub rank_candidates: usize,
    /// Most scan points used by the fine ICP (evenly strided; default 40,000). Against
    /// 100,000, on the 20 synth cases of tests/register.rs: worst final error 0.0014 deg /
    /// 0.0009 mm instead of 0.0010 deg / 0.0008 mm, in half the time (bench case: 0.11 s
    /// instead of 0.21 s); `pose_std`, and so the registration error, grows as 1/√n (0.0005
    /// → 0.0007 mm there), still covering the actual error on every case.
    pub icp_max_points: usize,
    /// Fine ICP correspondence distance (default 2 voxel).
    pub icp_max_distance: Option<f64>,
    /// Fine ICP iteration cap (default 100).
    pub icp_max_iterations: usize,
    /// Fine ICP relative tolerance on fitness and inlier RMSE (default 1e-7).
    pub icp_relative_tolerance: f64,
    /// Fixed Geman–McClure scale of the fine ICP; default adaptive (3 × robust sigma).
    pub icp_kernel_scale: Option<f64>,
    /// Distance within which a scan point counts as fitting the reference in the reported
    /// fitness and inlier RMSE (default 3 x the reference's mean spacing).
    pub fitness_distance: Option<f64>,
    /// Below this final fitness the registration fails (default 0.2).
    pub min_fitness: f64,
    /// Below this many inlying correspondences the coarse stage fails (default 8).
    pub min_inliers: usize,
}

impl Default for RegisterConfig {
    fn default() -> Self {
        RegisterConfig {
            voxel: None,
            normal_radius: None,
            feature_radius: None,
            feature_max_nn: 100,
            max_keypoints: 8_000,
            mutual: true,
            max_correspondences: 3000,
            compat_sigma: None,
            compat_min_score: 0.6,
            inlier_threshold: None,
            min_clique: 3,
            max_cliques: 30_000,
            clique_time_budget: 30.0,
            top_k: 200,
            rank_candidates: 5,
            icp_max_points: 40_000,
            icp_max_distance: None,
            icp_max_iterations: 100,
            icp_relative_tolerance: 1e-7,
            icp_kernel_scale: None,
            fitness_distance: None,
            min_fitness: 0.2,
            min_inliers: 8,
        }
    }
}

/// Largest length setting accepted (`voxel`, the radii, the thresholds, the ICP's distances),
/// mm: a metre, beyond any part the cell holds (the arm reaches about 0.3 m); past it a value
/// is a unit slip, not a part.
pub const MAX_LENGTH_MM: f64 = 1000.0;

/// Longest clique search accepted (`clique_time_budget`), s: an hour, 120 times the default
/// guard of 30 s (itself a 300x margin on the 0.1 s search); a budget past it never bounds
/// the search, and `inf`, NaN or 1e308 s cannot be a timer.
pub const MAX_CLIQUE_TIME_BUDGET_S: f64 = 3600.0;

/// Smallest clique (`min_clique`): three correspondences fix a rigid pose, fewer leave it free.
pub const MIN_CLIQUE: usize = 3;

/// Most FPFH neighbours (`feature_max_nn`): 100 times the default 100 (Open3D's); the work
/// per described point grows with it, and the radius bounds the neighbourhood anyway.
pub const MAX_FEATURE_NN: usize = 10_000;

/// Largest point cap (`max_keypoints`, `icp_max_points`): a hundred million points, 250 times
/// the 400k-point bench scan; a cap above a cloud's size takes all of it.
pub const MAX_POINTS_CAP: usize = 100_000_000;

/// Most correspondences (`max_correspondences`; also the most `min_clique` and `min_inliers`
/// can ask for): 333 times the default 3,000; the compatibility graph is shrunk to its work
/// cap long before.
pub const MAX_CORRESPONDENCES: usize = 1_000_000;

/// Most maximal cliques enumerated (`max_cliques`): 333 times the default 30,000; each is held
/// until the `top_k` selection.
pub const MAX_CLIQUES: usize = 10_000_000;

/// Most cliques kept (`top_k`): 500 times the default 200; each is scored against every
/// correspondence.
pub const MAX_TOP_K: usize = 100_000;

/// Most hypotheses ranked by a short ICP (`rank_candidates`): 200 times the default 5; each is
/// an ICP run, and no more can come out than `top_k` cliques.
pub const MAX_RANK_CANDIDATES: usize = 1_000;

/// Most fine ICP iterations (`icp_max_iterations`): 100 times the default 100; ICP converges in
/// tens, and at a relative tolerance of 0 the cap is what stops it.
pub const MAX_ICP_ITERATIONS: usize = 10_000;

impl RegisterConfig {
    /// Checks every setting: a refusal is one line naming the key in backticks with its range
    /// (for `ConfigFile::refuse`). What needs the clouds (the voxel against their extent) the
    /// stage checks when it runs.
    pub fn check(&self) -> Result<(), String> {
        use crate::settings::{above, count_in, in_range};
        let lengths = [
            ("voxel", self.voxel),
            ("normal_radius", self.normal_radius),
            ("feature_radius", self.feature_radius),
            ("compat_sigma", self.compat_sigma),
            ("inlier_threshold", self.inlier_threshold),
            ("icp_max_distance", self.icp_max_distance),
            ("icp_kernel_scale", self.icp_kernel_scale),
            ("fitness_distance", self.fitness_distance),
        ];
        for (key, v) in lengths {
            if let Some(v) = v {
                above(key, v, 0.0, MAX_LENGTH_MM, "mm")?;
            }
        }
        let (points, pairs) = (MAX_POINTS_CAP, MAX_CORRESPONDENCES);
        let counts = [
            (
                "feature_max_nn",
                self.feature_max_nn,
                1,
                MAX_FEATURE_NN,
                "neighbours",
            ),
            ("max_keypoints", self.max_keypoints, 1, points, "points"),
            (
                "max_correspondences",
                self.max_correspondences,
                1,
                pairs,
                "pairs",
            ),
            ("min_clique", self.min_clique, MIN_CLIQUE, pairs, "pairs"),
            ("max_cliques", self.max_cliques, 1, MAX_CLIQUES, "cliques"),
            ("top_k", self.top_k, 1, MAX_TOP_K, "cliques"),
            (
                "rank_candidates",
                self.rank_candidates,
                1,
                MAX_RANK_CANDIDATES,
                "poses",
            ),
            ("icp_max_points", self.icp_max_points, 1, points, "points"),
            (
                "icp_max_iterations",
                self.icp_max_iterations,
                1,
                MAX_ICP_ITERATIONS,
                "iterations",
            ),
            ("min_inliers", self.min_inliers, 0, pairs, "pairs"),
        ];
        for (key, n, min, max, unit) in counts {
            count_in(key, n, min, max, unit)?;
        }
        let budget = MAX_CLIQUE_TIME_BUDGET_S;
        above(
            "clique_time_budget",
            self.clique_time_budget,
            0.0,
            budget,
            "s",
        )?;
        in_range(
            "compat_min_score",
            self.compat_min_score,
            0.0,
            1.0,
            "(score)",
        )?;
        in_range("min_fitness", self.min_fitness, 0.0, 1.0, "(share)")?;
        let tol = self.icp_relative_tolerance;
        in_range("icp_relative_tolerance", tol, 0.0, 1.0, "(relative)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_pass_and_each_bad_value_names_its_key() {
        assert_eq!(RegisterConfig::default().check(), Ok(()));
        let refused = |set: fn(&mut RegisterConfig)| {
            let mut c = RegisterConfig::default();
            set(&mut c);
            c.check().unwrap_err()
        };
        let e = refused(|c| c.clique_time_budget = f64::INFINITY);
        assert!(e.starts_with("`clique_time_budget` = inf s"), "{e}");
        let e = refused(|c| c.feature_max_nn = 0);
        assert!(e.starts_with("`feature_max_nn` = 0 neighbours"), "{e}");
        let e = refused(|c| c.voxel = Some(f64::NAN));
        assert!(e.starts_with("`voxel` = NaN mm"), "{e}");
        let e = refused(|c| c.min_fitness = 2.0);
        assert!(e.starts_with("`min_fitness`"), "{e}");
    }
}

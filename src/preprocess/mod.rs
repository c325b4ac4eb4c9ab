//! Preprocessing: statistical outlier filter, voxel and curvature-aware down-sampling, normals.
//!
//! [`preprocess`] chains the steps for `polishbot filter` and `inspect`; each step also has its
//! own front function.
mod sor;

pub use sor::{mean_distances, statistical_outlier_filter, SorConfig, SorResult};

//! Preprocessing: statistical outlier filter, voxel and curvature-aware down-sampling, normals.
//!
//! [`preprocess`] chains the steps for `polishbot filter` and `inspect`; each step also has its
//! own front function.
mod curvature;
mod normals;
mod pipeline;
mod sor;
mod voxel;

pub use curvature::{curvature_sample, CurvatureSample, CurvatureSampleConfig};
pub use normals::{
    estimate_normals, orient_sheets, pca_normal, NormalConfig, NormalEstimate, Orientation,
};
pub use pipeline::{preprocess, PreprocessConfig, Preprocessed};
pub use sor::{
    check_coordinates, check_settings as check_sor_settings, mean_distances,
    statistical_outlier_filter, SorConfig, SorResult, MAX_K as MAX_SOR_K,
};
pub use voxel::{
    check_voxel, check_voxel_value, mean_spacing, mean_spacing_in, voxel_downsample,
    MAX_VOXELS_ACROSS,
};

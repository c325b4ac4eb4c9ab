//! Where an inspected scan's pose came from: its registration to the reference, or a file.
use std::path::PathBuf;

use nalgebra::Isometry3;

use crate::cloud;
use crate::register::{self, RegisterConfig, Registration};

/// Where the pose came from.
#[derive(Debug, Clone)]
pub enum PoseSource {
    /// Found by registration (its diagnostics).
    Registered(Box<Registration>),
    /// Read from a file.
    Given {
        /// The pose, scan to reference.
        pose: Isometry3<f64>,
        /// The file it came from.
        source: PathBuf,
    },
}

/// Registers the filtered scan onto the reference with a progress bar.
pub fn register_scan(
    scan: &cloud::PointCloud,
    reference: &cloud::PointCloud,
    cfg: &RegisterConfig,
) -> Result<Registration, register::RegisterError> {
    crate::progress::stepped(register::PROGRESS_STEPS, "register", |step| {
        register::register_with_progress(scan, reference, cfg, step)
    })
}

impl PoseSource {
    /// Scan to reference.
    pub fn pose(&self) -> Isometry3<f64> {
        match self {
            PoseSource::Registered(reg) => reg.pose,
            PoseSource::Given { pose, .. } => *pose,
        }
    }

    /// The report's line on the pose.
    pub(super) fn line(&self) -> String {
        match self {
            PoseSource::Registered(reg) => format!(
                "FPFH + MAC + ICP: fitness {:.4}, inlier RMSE {:.4} mm, point-to-plane RMSE {:.4} mm, registration error {:.5} mm, {:.2} s",
                reg.fitness,
                reg.inlier_rmse,
                reg.fine.map_or(f64::NAN, |f| f.plane_rmse),
                reg.registration_error,
                reg.times.total
            ),
            PoseSource::Given { source, .. } => format!("pose given in {}", source.display()),
        }
    }
}

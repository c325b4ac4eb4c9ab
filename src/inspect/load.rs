//! Loading an inspection's inputs: the reference as a cloud with outward normals, the scan, and
//! the core points, each checked, with the report's line on where they came from.
use anyhow::{Context, Result};

use super::checks;
use super::config::{FileInput, Inputs, InspectConfig, Source, DEFAULT_REFERENCE_POINTS};
use crate::cloud::{self, Geometry, PointCloud};
use crate::compare::{self, CoreConfig, Method};

/// A loaded cloud and the report's line on it.
pub struct Loaded {
    /// The cloud.
    pub cloud: PointCloud,
    /// Where its points or normals came from.
    pub note: String,
}

/// The core points and a warning about them, if any.
pub struct Core {
    /// Core points with outward normals.
    pub cloud: PointCloud,
    /// A warning for the user.
    pub notice: Option<String>,
}

/// Reference and scan, both at once (parsing is single-threaded); notices go to `notices`.
pub fn inputs(
    cfg: &InspectConfig,
    inputs: &Inputs,
    notices: &mut Vec<String>,
) -> Result<(Loaded, PointCloud)> {
    let samples = if cfg.reference_points == 0 {
        DEFAULT_REFERENCE_POINTS
    } else {
        cfg.reference_points
    };
    let f = inputs.files;
    let (reference, scan) = rayon::join(
        || reference(&inputs.reference, f, samples),
        || inputs.scan.load_cloud(f),
    );
    let ((reference, notice), scan) = (reference?, scan?);
    notices.extend(notice);
    Ok((reference, scan))
}

/// The reference as a cloud with outward normals, and a notice when its normals were turned
/// round or estimated.
fn reference(
    source: &Source,
    input: FileInput,
    samples: usize,
) -> Result<(Loaded, Option<String>)> {
    let path = source.as_path();
    let loaded = |cloud, note| Loaded { cloud, note };
    match source.load(input)? {
        Geometry::Mesh { mesh, .. } => Ok((
            loaded(
                compare::mesh_reference(&mesh, samples, 1)?,
                format!("{samples} points sampled from the mesh, with its facet normals"),
            ),
            None,
        )),
        Geometry::Cloud(mut c) if c.normals.is_some() => {
            checks::check_unit_normals(path, "reference", &c)?;
            Ok(match checks::orient_outward(path, &mut c)? {
                Some(note) => {
                    let line = format!("the reference cloud's own normals, {note}");
                    (loaded(c, line), Some(format!("inspect: notice: {note}")))
                }
                None => (loaded(c, "the reference cloud's own normals".into()), None),
            })
        }
        Geometry::Cloud(c) => {
            let (c, note) = compare::cloud_reference(c)
                .with_context(|| format!("{}: reference normals", path.display()))?;
            let notice = format!(
                "inspect: notice: {}: the reference cloud has no normals: estimated ({note})",
                path.display()
            );
            Ok((loaded(c, note), Some(notice)))
        }
    }
}

/// The core points (from `inputs.core`, or a sample of the reference) and the report's line
/// on them.
pub fn core(
    cfg: &InspectConfig,
    inputs: &Inputs,
    reference: &PointCloud,
    scan_points: usize,
) -> Result<(Core, String)> {
    let core = match &inputs.core {
        Some(path) => {
            let c = cloud::load_cloud(path, inputs.files.format, inputs.files.units)?;
            checks::check_unit_normals(path, "--core file", &c)?;
            compare::core_points(
                &c,
                scan_points,
                &CoreConfig {
                    selection: compare::CoreSelection::All,
                    ..cfg.core.clone()
                },
            )
            .with_context(|| format!("{}", path.display()))?
        }
        None => compare::core_points(reference, scan_points, &cfg.core)?,
    };
    let every_point = inputs.core.is_none() && core.len() == reference.len();
    let notice = (every_point && cfg.compare.method == Method::Adaptive).then(|| {
        format!(
            "inspect: warning: every one of the {} reference points is a core point: \
             densification has none left to add around a defect's top, so defects narrower \
             than about twice their spacing may be missed; give a denser reference",
            reference.len()
        )
    });
    let line = match (&inputs.core, every_point) {
        (Some(path), _) => format!("{} from {}", core.len(), path.display()),
        (None, true) => format!("all {} reference points", core.len()),
        (None, false) => format!("{} of {} reference points", core.len(), reference.len()),
    };
    Ok((
        Core {
            cloud: core,
            notice,
        },
        line,
    ))
}

//! Inspection as a library function: a scan measured against its reference, from the files to
//! the verdict. [`run`] reads top to bottom: load and check -> outlier filter -> register (or a
//! given pose) -> core points -> compare -> regions and verdict. It prints nothing and writes
//! nothing; [`files::inspect_into`] (called by `polishbot inspect`, `demo` and the loop) writes
//! its [`Findings`] to files.
pub mod area;
pub mod checks;
mod config;
pub mod files;
mod load;
mod orientation;
mod pose;
pub mod scans;
pub mod suggest;

pub use files::{inspect_into, Incomplete, INCOMPLETE_EXIT};
pub use pose::{register_scan, PoseSource};

pub use config::{
    FileInput, Inputs, InspectConfig, Source, DEFAULT_REFERENCE_POINTS, MAX_REFERENCE_POINTS,
};

use std::time::Instant;

use anyhow::Result;

use crate::cloud;
use crate::compare::{self, CompareConfig, Deviations};
use crate::regions::{self, Regions};

/// The outcome of [`run`].
#[derive(Debug)]
pub struct Findings {
    /// The pose of the scan and where it came from.
    pub pose: PoseSource,
    /// The poses of the further scans (`Inputs::more_scans`), in order.
    pub more_poses: Vec<PoseSource>,
    /// With further scans, per core point the scans that supported its measurement (bit k:
    /// scan k, the first scan 0; [`scans::support`]); empty with one scan.
    pub support: Vec<u32>,
    /// Per core point: distance, uncertainty, significance.
    pub deviations: Deviations,
    /// Per core point of `deviations`, the classic M3C2 distance at `Inputs::fine_radius`
    /// (NaN where its cylinders hold too few points); empty when none was asked.
    pub fine: Vec<f64>,
    /// Defect regions and the verdict.
    pub regions: Regions,
    /// Lines for the report's provenance (label, text): reference normals, registration...
    pub provenance: Vec<(String, String)>,
    /// Notices and warnings for the user, in the order they arose.
    pub notices: Vec<String>,
    /// Wall time per stage.
    pub times: StageTimes,
    /// With an incomplete verdict, the views that would measure the rest ([`suggest`]).
    pub suggestion: Option<suggest::Suggestion>,
    /// Per core point whether it lies in the area to inspect (None: no area given, all do).
    pub in_area: Option<Vec<bool>>,
    /// regions.json and deviations.csv as [`inspect_into`] wrote them (size, SHA-256), for
    /// the plan's provenance; empty from [`run`], which writes nothing.
    pub written: Vec<crate::report::provenance::InputFile>,
    /// report.html's text as [`inspect_into`] wrote it (the plan adds its link to it in
    /// memory); None from [`run`].
    pub report_html: Option<String>,
}

/// Inspects `inputs` with `cfg`. A registration failure is returned as the
/// [`crate::register::RegisterError`] (its diagnostics inside), other errors name the file at
/// fault.
pub fn run(cfg: &InspectConfig, inputs: &Inputs) -> Result<Findings> {
    let mut times = StageTimes::default();
    let mut notices = Vec::new();
    let spin = crate::progress::spinner("load");
    let (reference, scan) = load::inputs(cfg, inputs, &mut notices)?;
    spin.finish_and_clear();
    times.lap("load");

    let more = scans::load_more(&inputs.more_scans, inputs.files)?;
    let reference_in = (inputs.reference.as_path(), &reference.cloud);
    let first = scans::prepare(
        cfg,
        reference_in,
        inputs.scan.as_path(),
        &scan,
        inputs.pose.as_deref(),
    )?;
    let rest = inputs
        .more_scans
        .iter()
        .zip(&more)
        .map(|(path, s)| {
            // A further scan's failed registration is no record of the first scan's.
            scans::prepare(cfg, reference_in, path.as_path(), s, None)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.as_path().display()))
        })
        .collect::<Result<Vec<_>>>()?;
    times.lap("filter and register");

    let mut provenance = vec![
        ("reference normals".to_string(), reference.note),
        ("registration".to_string(), first.pose.line()),
        ("outlier filter".to_string(), first.filter_line),
    ];
    for (k, (path, s)) in inputs.more_scans.iter().zip(&rest).enumerate() {
        let what = format!("scan {} ({})", k + 2, path.as_path().display());
        provenance.push((format!("{what}: registration"), s.pose.line()));
        provenance.push((format!("{what}: outlier filter"), s.filter_line.clone()));
    }
    let clouds: Vec<&cloud::PointCloud> = std::iter::once(&first.cloud)
        .chain(rest.iter().map(|s| &s.cloud))
        .collect();
    let pooled;
    let scan_cloud = match clouds.len() {
        1 => &first.cloud,
        _ => {
            pooled = scans::pool(&clouds);
            &pooled
        }
    };
    let pose = first.pose.clone();
    let more_poses: Vec<PoseSource> = rest.iter().map(|s| s.pose.clone()).collect();
    let (core, core_line) = load::core(cfg, inputs, &reference.cloud, scan_cloud.len())?;
    notices.extend(core.notice);
    provenance.push(("core point sample".to_string(), core_line));
    times.lap("core points");

    let compare_cfg = compare_settings(cfg, inputs, std::iter::once(&pose).chain(&more_poses));
    let deviations = compare::compare(&core.cloud, &reference.cloud, scan_cloud, &compare_cfg)?;
    let fine = match inputs.fine_radius {
        Some(radius) => fine_reading(
            &deviations,
            (&reference.cloud, scan_cloud),
            &compare_cfg,
            radius,
        )?,
        None => Vec::new(),
    };
    let support = match clouds.len() {
        1 => Vec::new(),
        _ => scans::support(&deviations, &clouds),
    };
    times.lap("compare");

    let in_area = match &inputs.inspect_area {
        Some(path) => Some(area::core_points_in(path, inputs.files, &deviations)?),
        None => None,
    };
    let regions = regions::find_regions_in(&deviations, &cfg.regions, in_area.as_deref());
    let suggestion = (regions.verdict == regions::Verdict::Incomplete)
        .then(|| suggest::suggest(&deviations, in_area.as_deref(), &pose.pose(), &cfg.suggest));
    times.lap("regions");
    Ok(Findings {
        pose,
        more_poses,
        support,
        deviations,
        fine,
        regions,
        provenance,
        notices,
        times,
        suggestion,
        in_area,
        written: Vec::new(),
        report_html: None,
    })
}

/// The classic M3C2 distance at every core point of `deviations` with cylinders of `radius`
/// mm (the comparison's other settings as `cfg`'s), between the `reference` and the registered
/// `scan`: a reading of spots narrower than the adaptive radius (the closed loop's rim).
fn fine_reading(
    deviations: &Deviations,
    (reference, scan): (&cloud::PointCloud, &cloud::PointCloud),
    cfg: &CompareConfig,
    radius: f64,
) -> Result<Vec<f64>> {
    let core = cloud::PointCloud {
        points: deviations.points.clone(),
        normals: Some(deviations.normals.clone()),
        fields: Vec::new(),
    };
    let classic = CompareConfig {
        method: compare::Method::Classic,
        radius: Some(radius),
        ..cfg.clone()
    };
    let read = compare::compare(&core, reference, scan, &classic)?;
    Ok(read.values.iter().map(|v| v.distance).collect())
}

/// The comparison's settings for this run: the registration error of the level of detection
/// (the flag's, else the largest of the poses' own uncertainties, else the setting's) and the
/// tolerance's thresholds.
fn compare_settings<'a>(
    cfg: &InspectConfig,
    inputs: &Inputs,
    poses: impl Iterator<Item = &'a PoseSource>,
) -> CompareConfig {
    let mut c = cfg.compare.clone();
    // The registration error of the level of detection is the pose's own uncertainty on the
    // surface (`Registration::registration_error`), not a residual RMSE: those hold the scan
    // noise, which the LoD already counts, and the reference's sampling spacing.
    let registered = poses
        .filter_map(|pose| match pose {
            PoseSource::Registered(reg) => Some(reg.registration_error),
            PoseSource::Given { .. } => None,
        })
        .reduce(f64::max);
    c.registration_error = inputs
        .registration_error
        .or(registered)
        .unwrap_or(c.registration_error);
    // The comparison works to the regions' tolerance (peaks, densification, narrow defects).
    c.tolerance = cfg.regions.tolerance;
    c
}

/// Wall time per stage of an inspection, for the closing `times:` line.
#[derive(Debug)]
pub struct StageTimes {
    last: Instant,
    laps: Vec<(&'static str, f64)>,
}

impl Default for StageTimes {
    fn default() -> Self {
        StageTimes {
            last: Instant::now(),
            laps: Vec::new(),
        }
    }
}

impl StageTimes {
    /// Ends the stage `name` now.
    pub fn lap(&mut self, name: &'static str) {
        let now = Instant::now();
        self.laps
            .push((name, now.duration_since(self.last).as_secs_f64()));
        self.last = now;
    }

    /// "load 0.12 s, filter 0.30 s, ...".
    pub fn line(&self) -> String {
        let parts: Vec<String> = self
            .laps
            .iter()
            .map(|(name, s)| format!("{name} {s:.2} s"))
            .collect();
        parts.join(", ")
    }
}

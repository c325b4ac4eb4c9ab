//! The inspection's files: [`inspect_into`] runs [`super::run`] and writes registration.json
//! (one per scan), deviations.csv, deviations.ply, regions.json and report.html into a folder,
//! then prints the summary table (docs/FORMATS.md). `polishbot inspect`, `demo` and the closed
//! loop (`crate::cycle`) call it.
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use rayon::prelude::*;
use serde_json::{json, Value};

use super::{suggest, Findings, Inputs, InspectConfig, PoseSource};
use crate::cloud::{self, transform, PlyPrecision};
use crate::compare;
use crate::regions::{self, Regions};
use crate::register::{RegisterError, Registration};
use crate::report::inspection::{
    peak_text, touch_mark, verdict_line, write_inspection_page, LOWER_BOUND_NOTE, UNMEASURED_NOTE,
};
use crate::report::provenance::{InputFile, Provenance};
use crate::report::{ReportConfig, Unmeasured};

/// Writes `value` as pretty JSON to `path`: with `provenance` added as its last key
/// ([`Provenance::stamp`], in memory: the file is never read back), else ending in a newline.
fn write_json(
    path: &Path,
    value: &impl serde::Serialize,
    provenance: Option<&Provenance>,
) -> Result<()> {
    write_text(path, &json_text(path, value, provenance)?)
}

/// The text [`write_json`] writes to `path`.
fn json_text(
    path: &Path,
    value: &impl serde::Serialize,
    provenance: Option<&Provenance>,
) -> Result<String> {
    let text = serde_json::to_string_pretty(value)?;
    Ok(match provenance {
        Some(p) => p.stamp(&text, path)?,
        None => text + "\n",
    })
}

/// Writes `text` to `path`.
fn write_text(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("{}: cannot write", path.display()))
}

/// Writes `text` to `path` and returns its record as written (size, SHA-256; `role` its
/// role), for the plan's provenance: the file is not read back.
fn write_recorded(role: &str, path: &Path, text: &str) -> Result<InputFile> {
    write_text(path, text)?;
    Ok(InputFile::held(role, path, text.as_bytes()))
}

/// Runs [`super::run`] and writes its files into `out` (created), then prints the summary
/// table; returns the inspection, or for an incomplete verdict the error [`Incomplete`].
pub fn inspect_into(cfg: &InspectConfig, inputs: &Inputs, out: &Path) -> Result<Findings> {
    let start = Instant::now();
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let reg_file = out.join("registration.json");
    let files = (inputs.scan.as_path(), inputs.reference.as_path());
    let (found, provenance) = rayon::join(|| super::run(cfg, inputs), || provenance(cfg, inputs));
    let mut found = match found {
        Ok(found) => found,
        Err(e) => match e.downcast::<RegisterError>() {
            Ok(failed) => {
                // The failure is the error to report; a record without provenance is still a
                // record.
                return Err(record_failure(
                    failed,
                    &reg_file,
                    files,
                    provenance.as_ref().ok(),
                ));
            }
            Err(e) => return Err(e),
        },
    };
    // After the inspection's own errors: it names a missing or unreadable input first.
    let provenance = provenance?;
    for notice in &found.notices {
        eprintln!("{notice}");
    }
    match &found.pose {
        PoseSource::Registered(reg) => record_ok(reg, &reg_file, files, Some(&provenance))?,
        PoseSource::Given { pose, source } => write_json(
            &reg_file,
            &json!({
                "status": "given",
                "scan_to_reference": transform::isometry_to_rows(pose),
                "source": source.display().to_string(),
                "fitness": null,
                "inlier_rmse": null,
                "coarse": null,
                "fine": null,
            }),
            Some(&provenance),
        )?,
    }
    for (k, pose) in found.more_poses.iter().enumerate() {
        let file = out.join(format!("registration_scan{}.json", k + 2));
        if let PoseSource::Registered(reg) = pose {
            let scan = inputs.more_scans[k].as_path();
            record_ok(
                reg,
                &file,
                (scan, inputs.reference.as_path()),
                Some(&provenance),
            )?;
        }
    }
    let lines = std::mem::take(&mut found.provenance);
    let support = std::mem::take(&mut found.support);
    let suggestion = found.suggestion.as_ref().map(suggestion_line);
    let written = Written {
        dev: &found.deviations,
        found: &found.regions,
        support: &support,
        unmeasured: suggestion.as_ref().map(|words| Unmeasured {
            in_area: found.in_area.as_deref(),
            suggestion: words.clone(),
        }),
    };
    let (files, page) = write_outputs(out, written, lines, &provenance)?;
    if !found.fine.is_empty() {
        let path = out.join(FOOTPRINT_FILE);
        std::fs::write(&path, footprint_text(&found.fine))
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    (found.written, found.report_html) = (files, Some(page));
    found.times.lap("files and report");
    print_summary(
        &found.deviations,
        &found.regions,
        start.elapsed().as_secs_f64(),
    );
    println!("times: {}", found.times.line());
    if let Some(words) = &suggestion {
        println!("suggested views: {words}");
    }
    match found.regions.verdict {
        regions::Verdict::Incomplete => Err(Incomplete {
            coverage: found.regions.coverage,
            shortfall: found.regions.shortfall,
            min_coverage: found.regions.min_coverage,
        }
        .into()),
        _ => Ok(found),
    }
}

/// What [`write_outputs`] writes: the deviations, the regions and, with several scans, the
/// scans that supported each core point.
struct Written<'a> {
    dev: &'a compare::Deviations,
    found: &'a Regions,
    support: &'a [u32],
    /// With an incomplete verdict, the report's picture of the unmeasured area.
    unmeasured: Option<Unmeasured<'a>>,
}

/// The inspection folder's file of the readings at the tool's footprint (`Findings::fine`,
/// docs/FORMATS.md; read back by `repair::Inspection::load`, which names it too, as it reads
/// deviations.csv with its own parser).
const FOOTPRINT_FILE: &str = "footprint.csv";

/// [`FOOTPRINT_FILE`]'s text for the readings `fine`: the header `footprint_distance`, then
/// one number per core point in deviations.csv's order (`NaN`: too few points).
fn footprint_text(fine: &[f64]) -> String {
    let mut text = String::from("footprint_distance\n");
    for f in fine {
        text.push_str(&format!("{f}\n"));
    }
    text
}

/// Writes deviations.csv, deviations.ply, regions.json and the report, all four at once
/// (formatting is most of their time, and each is single-threaded); returns the records of
/// regions.json and deviations.csv as written ([`Findings::written`]) and the report's text.
fn write_outputs(
    out: &Path,
    written: Written,
    report_summary: Vec<(String, String)>,
    provenance: &Provenance,
) -> Result<(Vec<InputFile>, String)> {
    let Written {
        dev,
        found,
        support,
        unmeasured,
    } = written;
    let table = compare::to_cloud(dev, &found.labels);
    // deviations.csv keeps its columns (a contract); the PLY also maps what was measured and,
    // with several scans, which supported each row.
    let mut ply_table = table.clone();
    compare::add_coverage_fields(dev, &mut ply_table);
    if !support.is_empty() {
        ply_table.set_field("scans", support.iter().map(|&m| m as f64).collect());
    }
    let write_regions = || -> Result<InputFile> {
        let path = out.join("regions.json");
        write_recorded(
            "regions",
            &path,
            &json_text(&path, found, Some(provenance))?,
        )
    };
    let ((csv, ply), (regions, report)) = rayon::join(
        || {
            rayon::join(
                || {
                    let path = out.join("deviations.csv");
                    write_recorded("deviations", &path, &cloud::csv_text(&table))
                },
                || {
                    let path = out.join("deviations.ply");
                    cloud::write_ply(&path, &ply_table, None, PlyPrecision::F64)
                },
            )
        },
        || {
            rayon::join(write_regions, || {
                write_inspection_page(out, (dev, found), report_summary, provenance, unmeasured)
            })
        },
    );
    ply?;
    let page = report?;
    Ok((vec![regions?, csv?], page))
}

fn print_summary(dev: &compare::Deviations, found: &Regions, seconds: f64) {
    println!(
        "inspect: core points {}, method {:?}, tolerance {} mm, {:.2} s",
        dev.summary(),
        dev.method,
        found.tolerance,
        seconds
    );
    println!(
        "{:>6} {:>10} {:>10} {:>11} {:>7} {:>9}  kind",
        "region", "peak mm", "area mm2", "volume mm3", "points", "measured"
    );
    for r in &found.regions {
        let kind = if r.repairable {
            "excess (repairable)"
        } else {
            "pit (not repairable)"
        };
        println!(
            "{:>6} {:>10} {:>10.3} {:>11.5} {:>7} {:>6.1} %{} {kind}",
            r.id,
            peak_text(r),
            r.area,
            r.volume,
            r.points,
            100.0 * r.measured_share,
            touch_mark(r),
        );
    }
    if found.regions.iter().any(|r| r.peak_lower_bound) {
        println!("* {}", LOWER_BOUND_NOTE);
    }
    if found.regions.iter().any(|r| r.touches_unmeasured) {
        println!("† {}", UNMEASURED_NOTE);
    }
    println!("verdict: {}", verdict_line(found));
}

/// The suggested views of an incomplete inspection in words (printed after "suggested
/// views: " and under the report's picture of the unmeasured area).
fn suggestion_line(sg: &suggest::Suggestion) -> String {
    let angles: Vec<String> = sg
        .table_angles
        .iter()
        .map(|(deg, share)| format!("{deg:.0} deg ({:.1} %)", 100.0 * share))
        .collect();
    let here = match angles.is_empty() {
        true => "no table angle of this setup faces it".to_string(),
        false => format!(
            "this setup faces it at table angles {} (where those views exist the part hid it)",
            angles.join(", ")
        ),
    };
    format!(
        "{:.1} % of the area to inspect not measured; {here}; {:.1} % faces \
         no table angle of this setup: scan it in a second setup, the part turned over \
         ([suggest] in --config: table axis and scanner direction)",
        100.0 * sg.unmeasured,
        100.0 * sg.other_setup
    )
}
/// The provenance of an inspection: its input files, units and effective settings.
pub fn provenance(cfg: &InspectConfig, inputs: &Inputs) -> Result<Provenance> {
    let mut sources = vec![("reference", &inputs.reference), ("scan", &inputs.scan)];
    sources.extend(inputs.more_scans.iter().map(|s| ("scan", s)));
    let optional = [
        ("pose", &inputs.pose),
        ("core points", &inputs.core),
        ("area to inspect", &inputs.inspect_area),
    ];
    let files: Vec<(&str, &Path)> = optional
        .iter()
        .filter_map(|(r, p)| p.as_deref().map(|p| (*r, p)))
        .collect();
    // A file this process wrote is recorded from the bytes it holds, never read back.
    let hashed = (sources.par_iter())
        .map(|(role, s)| match s.held_bytes() {
            Some(bytes) => Ok(InputFile::held(role, s.as_path(), bytes)),
            None => InputFile::hash(role, s.as_path()),
        })
        .chain(files.par_iter().map(|(role, p)| InputFile::hash(role, p)))
        .collect::<Result<Vec<_>>>()?;
    let units = match inputs.files.units {
        Some(u) => format!("results in mm, reference frame; inputs read as {u:?}"),
        None => "results in mm, reference frame; inputs in mm (no --units)".to_string(),
    };
    let config = serde_json::json!({
        "inspect": cfg,
        "input_units": inputs.files.units,
        "input_format": inputs.files.format.map(|f| format!("{f:?}")),
        "registration_error": inputs.registration_error,
        "report": ReportConfig::default(),
    });
    Provenance::of_inputs("inspect", &units, hashed, &config)
}

/// Exit code of `inspect` when the verdict is incomplete (1 is an error, 2 a usage error).
pub const INCOMPLETE_EXIT: u8 = 3;

/// The error `inspect` ends with when the verdict is incomplete (exit [`INCOMPLETE_EXIT`]).
#[derive(Debug)]
pub struct Incomplete {
    /// Resolved share of the area to inspect.
    pub coverage: f64,
    /// Where the rest went.
    pub shortfall: crate::regions::Shortfall,
    /// Share needed for a verdict.
    pub min_coverage: f64,
}

impl std::fmt::Display for Incomplete {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "inspect: verdict incomplete: resolved {:.1} % of the area to inspect, below the \
             {:.1} % needed ([regions] min_coverage): {} (docs/ALGORITHMS.md, \"Coverage and \
             resolution\")",
            100.0 * self.coverage,
            100.0 * self.min_coverage,
            self.shortfall.describe()
        )
    }
}

impl std::error::Error for Incomplete {}

/// registration.json of a registration with `"status"`, `"reason"` and the two files.
fn with_status<T: serde::Serialize>(
    reg: &T,
    status: &str,
    reason: Option<&str>,
    files: (&Path, &Path),
) -> Result<Value> {
    let mut v = serde_json::to_value(reg)?;
    v["status"] = json!(status);
    v["reason"] = json!(reason);
    v["scan"] = json!(files.0.display().to_string());
    v["reference"] = json!(files.1.display().to_string());
    Ok(v)
}

/// Records a registration that succeeded in `out` (registration.json, `"status": "ok"`, with
/// `provenance` when given); `files` are the scan's and the reference's.
pub fn record_ok(
    reg: &Registration,
    out: &Path,
    files: (&Path, &Path),
    provenance: Option<&Provenance>,
) -> Result<()> {
    write_json(out, &with_status(reg, "ok", None, files)?, provenance)
}

/// Records a registration that failed in `out` (`"status": "failed"` with the diagnostics,
/// and `provenance` when given) and returns the one-line error that says so.
pub fn record_failure(
    err: RegisterError,
    out: &Path,
    files: (&Path, &Path),
    provenance: Option<&Provenance>,
) -> anyhow::Error {
    let RegisterError::Failed {
        reason,
        diagnostics,
    } = err
    else {
        return err.into();
    };
    let value = with_status(&*diagnostics, "failed", Some(&reason), files);
    if let Err(e) = value.and_then(|v| write_json(out, &v, provenance)) {
        return e;
    }
    anyhow::anyhow!(
        "registration failed: {reason} (correspondences {}, inlier ratio {:.3}, cliques {}, hypotheses {}, fitness {:.3}; diagnostics in {})",
        diagnostics.coarse.correspondences,
        diagnostics.coarse.inlier_ratio,
        diagnostics.coarse.mac.cliques_found,
        diagnostics.coarse.mac.hypotheses,
        diagnostics.fitness,
        out.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloud::{Geometry, PointCloud};
    use crate::inspect::{FileInput, Source};
    use nalgebra::Point3;

    /// A cloud of a few millimetre-sized points, as a rescan has them.
    fn cloud() -> PointCloud {
        PointCloud::from_points(
            (0..50)
                .map(|i| Point3::new(i as f64 * 0.37, (i * i) as f64 * 0.011, 3.0 - i as f64))
                .collect(),
        )
    }

    #[test]
    fn a_held_input_is_loaded_and_recorded_as_written_without_reading_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let c = cloud();
        let bytes = cloud::write_ply_bytes(&c, None, PlyPrecision::F64);
        let written = dir.path().join("after.ply");
        std::fs::write(&written, &bytes).unwrap();
        // Held under a path that is not there: loading it must not read the file.
        let gone = dir.path().join("removed.ply");
        let held = Source::held(&gone, Geometry::Cloud(c.clone()), bytes.clone());
        let files = FileInput::default();
        assert_eq!(held.load_cloud(files).unwrap(), c);
        // What the file reads back as (the parser, not the held copy) is the held cloud.
        assert_eq!(Source::file(&written).load_cloud(files).unwrap(), c);
        let err = Source::file(&gone).load_cloud(files).unwrap_err();
        assert!(format!("{err:#}").contains("removed.ply"), "{err:#}");
        // The provenance of the held input: the file's size and SHA-256, hashed from disk.
        let inputs = Inputs {
            reference: held.clone(),
            scan: held,
            more_scans: Vec::new(),
            files,
            pose: None,
            core: None,
            inspect_area: None,
            registration_error: None,
            fine_radius: None,
        };
        let p = provenance(&InspectConfig::default(), &inputs).unwrap();
        let on_disk = InputFile::hash("scan", &written).unwrap();
        assert_eq!(p.inputs.len(), 2);
        for f in &p.inputs {
            assert_eq!((f.bytes, &f.sha256), (on_disk.bytes, &on_disk.sha256));
            assert_eq!(f.path, gone.display().to_string());
        }
    }
}

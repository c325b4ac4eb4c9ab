//! The report part of `inspect`: turns deviations and regions into report.html and figures.
use std::path::Path;

use anyhow::Result;

use crate::compare::Deviations;
use crate::regions::{Region, Regions, Verdict};
use crate::report::{self, ReportConfig, ReportInput, Table};

/// The verdict as users read it.
pub fn verdict_text(v: Verdict) -> &'static str {
    match v {
        Verdict::WithinTolerance => "within tolerance",
        Verdict::Repairable => "repairable",
        Verdict::Reject => "reject",
    }
}

/// What a peak marked `*` ([`peak_text`]) means.
pub const LOWER_BOUND_NOTE: &str = "lower bound: read by single point pairs under a defect \
     too narrow for a model (no scan point near its top); the true peak is at least this large";

/// A region's signed peak with 4 decimals, followed by `*` when it is a lower bound
/// ([`Region::peak_lower_bound`]), else by a space (so the digits stay in columns).
pub fn peak_text(r: &Region) -> String {
    format!(
        "{:+.4}{}",
        r.peak,
        if r.peak_lower_bound { '*' } else { ' ' }
    )
}

/// Writes `dir/report.html` with its figures; `summary` lines come first (registration...).
pub fn write(
    dir: &Path,
    dev: &Deviations,
    found: &Regions,
    mut summary: Vec<(String, String)>,
) -> Result<()> {
    let distances: Vec<f64> = dev.values.iter().map(|v| v.distance).collect();
    summary.splice(
        0..0,
        [
            (
                "verdict".to_string(),
                format!(
                    "{} ({} regions)",
                    verdict_text(found.verdict),
                    found.regions.len()
                ),
            ),
            ("tolerance".to_string(), format!("{} mm", found.tolerance)),
            ("method".to_string(), format!("{:?} M3C2", dev.method)),
            ("core points".to_string(), dev.summary()),
        ],
    );
    let rows = found
        .regions
        .iter()
        .map(|r| {
            vec![
                r.id.to_string(),
                if r.repairable {
                    "excess (repairable)"
                } else {
                    "pit (not repairable)"
                }
                .to_string(),
                peak_text(r),
                format!("{:+.4}", r.mean),
                format!("{:.3}", r.area),
                format!("{:.5}", r.volume),
                r.points.to_string(),
                format!(
                    "{:.2}, {:.2}, {:.2}",
                    r.centroid[0], r.centroid[1], r.centroid[2]
                ),
            ]
        })
        .collect();
    if found.regions.iter().any(|r| r.peak_lower_bound) {
        summary.push(("peaks marked *".to_string(), LOWER_BOUND_NOTE.to_string()));
    }
    let header = [
        "id",
        "kind",
        "peak mm",
        "mean mm",
        "area mm²",
        "volume mm³",
        "points",
        "centroid mm",
    ];
    let input = ReportInput {
        title: "polishbot inspection".into(),
        points: &dev.points,
        normals: &dev.normals,
        distances: &distances,
        tolerance: found.tolerance,
        summary,
        tables: vec![Table {
            title: "defect regions".into(),
            header: header.iter().map(|s| s.to_string()).collect(),
            rows,
        }],
    };
    report::write_report(dir, &input, &ReportConfig::default())?;
    Ok(())
}

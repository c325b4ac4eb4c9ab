//! The inspection's page: deviations and regions as report.html and its figures, and the
//! verdict and region texts that the inspection's printed summary shares with it.
use std::path::Path;

use anyhow::Result;

use super::provenance::Provenance;
use super::{RegionMark, ReportConfig, ReportInput, Table};
use crate::compare::Deviations;
use crate::regions::{Region, Regions, Verdict};

/// The verdict as users read it.
pub fn verdict_text(v: Verdict) -> &'static str {
    match v {
        Verdict::WithinTolerance => "within tolerance",
        Verdict::Repairable => "repairable",
        Verdict::Reject => "reject",
        Verdict::Incomplete => "incomplete",
        Verdict::Undecided => "undecided: rescan at a higher resolution",
    }
}

/// The verdict line: the verdict, the number of regions and the measured share of the area
/// to inspect beside it ("within tolerance" holds over the measured part only).
pub fn verdict_line(found: &Regions) -> String {
    let why = match found.verdict {
        Verdict::Incomplete => format!(
            ", below the {:.1} % needed for a verdict",
            100.0 * found.min_coverage
        ),
        Verdict::Undecided => format!("; {}", found.decision.undecided_reason()),
        _ => String::new(),
    };
    let iso = match &found.decision {
        d if d.rule.is_empty() => String::new(),
        d if d.undecided_regions.is_empty() => format!("; {}", d.describe()),
        d => format!(
            "; {}; regions with no non-conform member (not evidence): {:?}",
            d.describe(),
            d.undecided_regions
        ),
    };
    let rest = match found.shortfall.describe() {
        w if w.is_empty() => String::new(),
        w => format!(": {w}"),
    };
    format!(
        "{} ({} regions; resolved {:.1} % of the area to inspect{rest}{why}{iso})",
        verdict_text(found.verdict),
        found.regions.len(),
        100.0 * found.coverage,
    )
}

/// What a region marked `†` ([`Region::touches_unmeasured`]) means.
pub const UNMEASURED_NOTE: &str = "touches an unmeasured area (a hole or the border of the \
     scan): the defect may extend into it, so its peak, area and volume are lower bounds";

/// `†` for a region touching an unmeasured area, else a space.
pub fn touch_mark(r: &Region) -> char {
    if r.touches_unmeasured {
        '†'
    } else {
        ' '
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

/// A region as the report's figures show it: its kind, peak, area and marks in the caption.
pub fn region_mark(r: &Region) -> RegionMark {
    let kind = if r.repairable { "excess" } else { "pit" };
    RegionMark {
        id: r.id,
        centroid: r.centroid,
        normal: nalgebra::Vector3::from(r.normal),
        peak: r.peak,
        caption: format!(
            "{kind}, peak {} mm, area {:.3} mm², {} points{}",
            peak_text(r).trim_end(),
            r.area,
            r.points,
            if r.touches_unmeasured { " †" } else { "" }
        ),
    }
}

/// Writes `dir/report.html` with its figures; `summary` lines come first (registration...).
/// With an incomplete verdict `unmeasured` adds the picture of the unmeasured area. Returns
/// the page's text as written.
pub fn write_inspection_page(
    dir: &Path,
    (dev, found): (&Deviations, &Regions),
    mut summary: Vec<(String, String)>,
    provenance: &Provenance,
    unmeasured: Option<super::Unmeasured>,
) -> Result<String> {
    let distances: Vec<f64> = dev.values.iter().map(|v| v.distance).collect();
    let uncertainties: Vec<f64> = dev.values.iter().map(|v| v.uncertainty).collect();
    summary.splice(
        0..0,
        [
            ("verdict".to_string(), verdict_line(found)),
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
                format!("{:.1} %{}", 100.0 * r.measured_share, touch_mark(r)),
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
    if found.regions.iter().any(|r| r.touches_unmeasured) {
        summary.push(("regions marked †".to_string(), UNMEASURED_NOTE.to_string()));
    }
    summary.push((
        "not measured".to_string(),
        "grey in the colour map: no distance (a hole or the border of the scan)".to_string(),
    ));
    let header = [
        "id",
        "kind",
        "peak mm",
        "mean mm",
        "area mm²",
        "volume mm³",
        "points",
        "measured around",
        "centroid mm",
    ];
    let input = ReportInput {
        title: "polishbot inspection".into(),
        points: &dev.points,
        normals: &dev.normals,
        distances: &distances,
        uncertainties: &uncertainties,
        tolerance: found.tolerance,
        summary,
        tables: vec![Table {
            title: "defect regions".into(),
            header: header.iter().map(|s| s.to_string()).collect(),
            rows,
        }],
        labels: &found.labels,
        regions: found.regions.iter().map(region_mark).collect(),
        provenance: Some(provenance),
        unmeasured,
    };
    Ok(super::write_report(dir, &input, &ReportConfig::default())?.page)
}

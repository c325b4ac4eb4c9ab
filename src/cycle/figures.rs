//! cycle.html's figures from what the loop holds in memory (issue 50, "show it"): after each
//! grind, the inspection before it, the plan's predicted removal and the measured shifts (from
//! the refit, `super::refit`) and the next inspection become `report::cycle_page`'s figures in
//! the grind's folder; at the end the records become the convergence plot. Nothing is read
//! back from a file.
use std::path::Path;

use nalgebra::{Point3, Vector3};

use super::record::IterationRecord;
use crate::cell::removal_shift::RegionShift;
use crate::removal::matching::GrindPair;
use crate::report::cycle_page::{self, Convergence, GrindView, RegionGrind};
use crate::report::inspection::region_mark;
use crate::report::{Figure, ReportInput};

/// Least predicted removal at a core point for the scatter, mm (the removal fit's least
/// predicted removal, `removal_shift::ShiftConfig::planned_mm`'s 0.005: below it the plan
/// removes nothing there).
const LEAST_PREDICTED_MM: f64 = 0.005;

/// The figures of the grind of iteration `iteration` (its folder `dir`): the regions
/// `planned` of `pair.before`, the plan's `predicted` removal per core point of `pair.before`,
/// the measured `shifts` and, per region, the correction `carried` into the next plan (region
/// id, mm; empty: none carried), the removal achieved by `pair.after`. A figure that cannot be
/// drawn is said on stderr and left out (the figures are a view; the loop goes on).
pub fn grind(
    dir: &Path,
    iteration: usize,
    pair: &GrindPair,
    planned: &[usize],
    predicted: &[f64],
    (shifts, carried): (&[RegionShift], &[(usize, [f64; 3])]),
) -> Vec<Figure> {
    let before = pair.before;
    let pts = &before.points;
    let points: Vec<Point3<f64>> = pts.iter().map(|p| p.position).collect();
    let normals: Vec<Vector3<f64>> = pts.iter().map(|p| p.normal).collect();
    let distances: Vec<f64> = pts.iter().map(|p| p.distance).collect();
    let labels: Vec<i64> = pts.iter().map(|p| p.region).collect();
    let removal = (0..pts.len())
        .filter(|&i| predicted.get(i).is_some_and(|p| *p >= LEAST_PREDICTED_MM))
        .filter_map(|i| {
            let achieved = pair.removal(i)?;
            let region = usize::try_from(pts[i].region).ok()?;
            achieved
                .is_finite()
                .then_some((region, predicted[i], achieved))
        })
        .filter(|p| planned.contains(&p.0))
        .collect();
    let view = GrindView {
        iteration,
        before: ReportInput {
            title: String::new(),
            points: &points,
            normals: &normals,
            distances: &distances,
            uncertainties: &[],
            tolerance: before.tolerance.unwrap_or(0.0),
            summary: Vec::new(),
            tables: Vec::new(),
            labels: &labels,
            regions: (before.regions.iter())
                .filter(|r| planned.contains(&r.id))
                .map(region_mark)
                .collect(),
            provenance: None,
            unmeasured: None,
        },
        shifts: (shifts.iter())
            .filter_map(|s| {
                let region = usize::try_from(s.region).ok()?;
                Some(RegionGrind {
                    region,
                    shift_mm: s.shift_mm,
                    scale: s.scale,
                    carried_mm: (carried.iter())
                        .find(|c| c.0 == region)
                        .map(|c| Vector3::from(c.1)),
                })
            })
            .collect(),
        removal,
    };
    cycle_page::draw_grind(dir, &view).unwrap_or_else(|e| {
        eprintln!("cycle: notice: grind {iteration}'s figures: {e:#}; left out of cycle.html");
        Vec::new()
    })
}

/// cycle.html: the records' table page with the convergence plot (written as
/// `out/convergence.png`) and the grinds' `figures`.
pub fn page(table: &str, out: &Path, records: &[IterationRecord], figures: &[Figure]) -> String {
    let convergence = Convergence {
        volume_mm3: records.iter().map(|r| r.measured.volume_mm3).collect(),
        peak_mm: records.iter().map(|r| r.measured.peak_mm).collect(),
        k: records.iter().map(|r| r.k_fitted).collect(),
    };
    let path = out.join("convergence.png");
    let drawn = match cycle_page::draw_convergence(&path, &convergence) {
        Ok(()) => Some(path.as_path()),
        Err(e) => {
            eprintln!("cycle: notice: {e:#}; the convergence plot is left out of cycle.html");
            None
        }
    };
    let section = cycle_page::figures_html(out, drawn, figures);
    cycle_page::with_section(table, &section)
}

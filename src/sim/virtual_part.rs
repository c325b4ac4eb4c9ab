//! The virtual part of `run --sim --part FILE --ground-out OUT` and of the loop's simulated
//! arm: loaded from a part file and checked against the inspected surface ([`Ground::prepare`]),
//! ground by the grinding simulator over the run's virtual time and rescanned into OUT (synth's
//! scanner model, a new random pose) with the removal per point in OUT's `_truth.ply` and
//! `_truth.json` beside it ([`Ground::finish`]).
use std::path::{Path, PathBuf};

use anyhow::Context;
use nalgebra::{Matrix4, Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use super::grind::{grind, GrindReport, ServoTrace, VirtualPart};
use super::{SimArm, SimOptions};
use crate::bus::ServoMap;
use crate::cloud::{self, PlyPrecision, PointCloud, ScalarField};
use crate::preprocess::{estimate_normals, NormalConfig, Orientation};
use crate::spatial::Neighbours;

/// Farthest a point of the part file may lie from the inspected surface (along the nearest
/// core point's normal, past its measured deviation), mm: 30 times synth's scan noise, twice
/// the tallest defect of the cases, and under the 1 mm that synth's nearest outliers
/// keep from the surface.
const OFF_SURFACE_MM: f64 = 0.5;
/// Least share of the part file's points within [`OFF_SURFACE_MM`] of the inspected surface:
/// a scan of the inspected part keeps all but its outliers (synth's 1 %, a real scanner's
/// few percent) and the part beyond the inspected area; another part kept 0.1-1 % (issue 52).
const MIN_ON_SURFACE_SHARE: f64 = 0.5;

/// A virtual part for the simulated arm to grind (`--part`, `--ground-out`).
#[derive(Clone, Copy)]
pub struct PartToGrind<'a> {
    /// The part's points.
    pub file: &'a Path,
    /// `file`'s cloud when this process holds it (the surface an earlier grind left and wrote
    /// there): used instead of reading the file back.
    pub held: Option<&'a PointCloud>,
    /// Whether they are in the reference frame already (`--part-in-reference`).
    pub in_reference: bool,
    /// Where the rescan goes.
    pub ground_out: &'a Path,
    /// The inspected scan's pose (registration.json's), 4x4 row-major; None only with
    /// `in_reference`.
    pub scan_to_reference: Option<[[f64; 4]; 4]>,
}

/// The inspected surface a virtual part is checked against and oriented by: the inspection's
/// core points (reference frame, mm), their unit outward normals and measured deviations (mm,
/// NaN where none); `dir`, the inspection's folder, names it in messages.
pub struct Inspected<'a> {
    /// The inspection's folder.
    pub dir: &'a Path,
    /// Core points.
    pub positions: Vec<Point3<f64>>,
    /// Their normals.
    pub normals: Vec<Vector3<f64>>,
    /// Their deviations.
    pub distances: Vec<f64>,
}

/// A virtual part ready to be ground, and where its rescan goes.
pub struct Ground {
    part: VirtualPart,
    options: SimOptions,
    out: PathBuf,
    source: PathBuf,
}

/// What `<out>_truth.json` holds.
#[derive(Serialize)]
struct GroundTruth<'a> {
    /// The part file ground.
    part: String,
    /// Maps the rescan's points (OUT) into the reference frame, 4x4 row-major.
    scan_to_reference: [[f64; 4]; 4],
    /// Indices of the rescan's outliers.
    outliers: Vec<usize>,
    /// What the grind did.
    grind: &'a GrindReport,
    /// The simulated cell's truth used.
    settings: &'a super::GrindConfig,
}

/// The truth files beside `out`: `<stem>_truth.ply` and `<stem>_truth.json`.
pub fn truth_paths(out: &Path) -> (PathBuf, PathBuf) {
    let stem = out
        .file_stem()
        .map_or("ground".into(), |s| s.to_string_lossy());
    (
        out.with_file_name(format!("{stem}_truth.ply")),
        out.with_file_name(format!("{stem}_truth.json")),
    )
}

impl Ground {
    /// Loads the part `given`: the file's points in the reference frame (by the inspected
    /// scan's pose, or as they are when `in_reference`), those on the inspected surface only
    /// (outliers dropped), with PCA normals turned outward as the nearest core point's.
    pub fn prepare(
        options: &SimOptions,
        given: &PartToGrind,
        inspection: &Inspected,
    ) -> anyhow::Result<Ground> {
        let (part, in_reference, out) = (given.file, given.in_reference, given.ground_out);
        let mut cloud = match given.held {
            Some(held) => held.clone(),
            None => cloud::load_cloud(part, None, None)?,
        };
        if !in_reference {
            let rows = given.scan_to_reference.with_context(|| {
                format!("{}: no scan_to_reference given", inspection.dir.display())
            })?;
            let pose = cloud::transform::isometry_from_rows(&rows)
                .with_context(|| format!("{}: scan_to_reference", inspection.dir.display()))?;
            cloud.transform(&pose);
        }
        let index = Neighbours::new(&inspection.positions);
        // the part's surface: points within OFF_SURFACE_MM of where the inspection measured
        // the surface (the core point's plane moved by its deviation); outliers lie farther
        // (each point's test is its own: a parallel filter keeps the order and the answer)
        let on_surface: Vec<usize> = (0..cloud.len())
            .into_par_iter()
            .filter(|&i| {
                let p = cloud.points[i];
                index.nearest(&p).is_some_and(|nb| {
                    let (c, n) = (inspection.positions[nb.index], inspection.normals[nb.index]);
                    let d = inspection.distances[nb.index];
                    let d = if d.is_finite() { d } else { 0.0 };
                    (n.dot(&(p - c)) - d).abs() <= OFF_SURFACE_MM
                })
            })
            .collect();
        anyhow::ensure!(
            !on_surface.is_empty(),
            "{}: --part: no point lies within {OFF_SURFACE_MM} mm of the inspected surface \
             (is it the scan the plan's inspection registered{}?)",
            part.display(),
            if in_reference {
                ", in the reference frame"
            } else {
                ""
            }
        );
        let kept = on_surface.len() as f64 / cloud.len() as f64;
        anyhow::ensure!(
            kept >= MIN_ON_SURFACE_SHARE,
            "{}: --part: only {:.2} % of its {} points lie within {OFF_SURFACE_MM} mm of the \
             inspected surface (need {:.0} %): it is not the part the plan's inspection measured{}",
            part.display(),
            100.0 * kept,
            cloud.len(),
            100.0 * MIN_ON_SURFACE_SHARE,
            if in_reference {
                " (in the reference frame)"
            } else {
                " (give the scan that inspection registered)"
            }
        );
        // normals of the surface as it is now, also for a truth file: the normals it holds
        // are those the last grind started from, off by the slope it took away (with them,
        // seed 101's second grind removed 0.46 mm at its peak instead of 0.25)
        let mut cloud = cloud.select(&on_surface);
        cloud.normals = None;
        let cfg = NormalConfig {
            orientation: Orientation::Unoriented,
            ..NormalConfig::default()
        };
        let mut normals = estimate_normals(&cloud, &cfg)?.normals;
        (cloud.points.par_iter())
            .zip(normals.par_iter_mut())
            .for_each(|(p, n)| {
                let outward = index
                    .nearest(p)
                    .map_or(Vector3::z(), |nb| inspection.normals[nb.index]);
                if n.dot(&outward) < 0.0 {
                    *n = -*n;
                }
            });
        Ok(Ground {
            part: VirtualPart::new(cloud.points, normals, &options.grinding),
            options: options.clone(),
            out: out.to_path_buf(),
            source: part.to_path_buf(),
        })
    }

    /// A simulated arm for the run (the options the replay uses).
    pub fn arm(&self, map: &ServoMap) -> anyhow::Result<SimArm> {
        Ok(SimArm::new(&self.options, map)?)
    }

    /// After the run on `arm`: grinds the part (placed in the robot's base frame by the cell's
    /// `robot_from_reference`, workcell.toml's) over the run's virtual time, writes the rescan
    /// and its truth, prints one line and returns what it wrote ([`GroundPart`]).
    pub fn finish(
        mut self,
        arm: &SimArm,
        map: &ServoMap,
        robot_from_reference: &Matrix4<f64>,
    ) -> anyhow::Result<GroundPart> {
        let g = &self.options.grinding;
        let home = map.home_raw(self.options.home_gripper_deg)?;
        let mut trace = ServoTrace::new(&self.options, home, arm.received());
        let report = grind(
            &mut self.part,
            &mut trace,
            arm.time(),
            robot_from_reference,
            g,
        );
        let normals = self.part.normals().to_vec();
        let surface = PointCloud {
            points: self.part.current_points(),
            normals: Some(normals),
            fields: vec![
                ScalarField {
                    name: "removal".into(),
                    values: self.part.removal().to_vec(),
                },
                ScalarField {
                    name: "true_k".into(),
                    values: self.part.true_k().to_vec(),
                },
            ],
        };
        let (scan, outliers, pose) = crate::synth::rescan(
            &surface,
            g.rescan_noise_mm,
            g.rescan_outliers,
            g.rescan_max_translation_mm,
            g.seed,
        )?;
        // F64 PLY: the file reads back exactly as `scan`, which the caller holds instead.
        let scan_ply = cloud::write_ply_bytes(&scan, None, PlyPrecision::F64);
        std::fs::write(&self.out, &scan_ply)
            .with_context(|| format!("{}: cannot write", self.out.display()))?;
        let (ply, json) = truth_paths(&self.out);
        cloud::write_ply(&ply, &surface, None, PlyPrecision::F64)?;
        let truth = GroundTruth {
            part: self.source.display().to_string(),
            scan_to_reference: cloud::transform::isometry_to_rows(&pose),
            outliers: outliers
                .scattered
                .iter()
                .chain(&outliers.clustered)
                .copied()
                .collect(),
            grind: &report,
            settings: g,
        };
        let text = serde_json::to_string_pretty(&truth)?;
        std::fs::write(&json, text).with_context(|| format!("{}: cannot write", json.display()))?;
        println!(
            "run: sim ground the part: {} of {} points, peak removal {:.4} mm, peak force {:.2} N, {} of {} steps in contact; rescan {}, truth {}",
            report.points_ground,
            surface.points.len(),
            report.peak_removal_mm,
            report.peak_force_n,
            report.contact_steps,
            report.steps,
            self.out.display(),
            ply.display()
        );
        Ok(GroundPart {
            surface,
            rescan: scan,
            rescan_ply: scan_ply,
        })
    }
}

/// What [`Ground::finish`] wrote, held: the ground surface (the truth PLY's cloud) and the
/// rescan (its cloud and the bytes of its PLY file).
pub struct GroundPart {
    /// The ground surface, reference frame, mm.
    pub surface: PointCloud,
    /// The rescan, scan frame, mm.
    pub rescan: PointCloud,
    /// The rescan's file as written.
    pub rescan_ply: Vec<u8>,
}

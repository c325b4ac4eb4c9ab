//! The repair work the planners consume: an inspection folder's `regions.json` and
//! `deviations.csv` (file contracts in DESIGN.md and docs/FORMATS.md), read and cross-checked.
//! A leaf below motion and removal planning; its one error is a bad input file.
//!
//! Front function: [`Inspection::load`]; no config.
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use serde::Deserialize;

/// An inspection file is unreadable or holds a bad value: the file, the place (line, row,
/// region) and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {place}: {message}", file.display())]
pub struct InputError {
    /// The file.
    pub file: PathBuf,
    /// Line, key or record at fault.
    pub place: String,
    /// What is wrong.
    pub message: String,
}

impl InputError {
    /// A bad value at `place` of `file`.
    pub fn new(file: &Path, place: impl Into<String>, message: impl Into<String>) -> Self {
        InputError {
            file: file.to_path_buf(),
            place: place.into(),
            message: message.into(),
        }
    }
}

/// One defect region of `regions.json`: the regions stage's own type (the file's contract).
pub use crate::regions::Region as RegionInfo;

#[derive(Deserialize)]
struct RegionsFile {
    #[serde(default)]
    tolerance: Option<f64>,
    /// Core-point spacing, mm (absent in hand-made files: the area check is skipped).
    #[serde(default)]
    spacing: Option<f64>,
    /// Connection distance of the regions, mm (absent: the extent check is skipped).
    #[serde(default)]
    gap: Option<f64>,
    regions: Vec<RegionInfo>,
}

/// Largest difference between a region's mean (or centroid coordinate) in regions.json and
/// the value its rows in deviations.csv give, mm: both files carry shortest round-trip
/// numbers, so only summation order differs (about 1e-15 relative).
const AGREEMENT_MM: f64 = 1e-6;
/// Accepted ratio between a region's area and its point count × spacing² (each way): the
/// area per core point varies with densification near defect tops (down to about 1/16 of the
/// median) and at sparse borders, never by this much.
const AREA_RATIO_LIMIT: f64 = 1000.0;

/// One core point of `deviations.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Position on the reference surface, mm.
    pub position: Point3<f64>,
    /// Outward unit normal.
    pub normal: Vector3<f64>,
    /// Signed distance along the normal, mm (+ = material in excess); NaN where the
    /// comparison had too few points.
    pub distance: f64,
    /// Expanded uncertainty of `distance` (the comparison's LoD95), mm: the `uncertainty`
    /// column of deviations.csv; 0 where the file has no such column (hand-made files: the
    /// distance is taken as exact); NaN where the comparison gave none. A plan removes only
    /// where `distance` exceeds the tolerance by more than it (`removal::targets`).
    pub uncertainty: f64,
    /// Region id, -1 for none.
    pub region: i64,
}

/// An inspection folder read for planning.
#[derive(Debug, Clone)]
pub struct Inspection {
    /// The folder.
    pub dir: PathBuf,
    /// Tolerance the regions were found with, mm (if regions.json says).
    pub tolerance: Option<f64>,
    /// Every region.
    pub regions: Vec<RegionInfo>,
    /// Every core point.
    pub points: Vec<SurfacePoint>,
    /// Per core point of `points`, its reading at the tool's footprint, mm, which `points`
    /// then carry as their distance (the closed loop's inspections, `cycle::planner_input`;
    /// NaN where it has too few points): the rim guard counts a conform point's loss as read
    /// there (`motion::dwell::rim_budget`). Empty where there is none (an inspection folder
    /// read back).
    pub fine: Vec<f64>,
}

impl Inspection {
    /// Reads `dir/regions.json` and `dir/deviations.csv` and checks that they agree.
    pub fn load(dir: &Path) -> Result<Inspection, InputError> {
        let rfile = dir.join("regions.json");
        let text = read(&rfile)?;
        let parsed: RegionsFile = serde_json::from_str(&text)
            .map_err(|e| InputError::new(&rfile, format!("line {}", e.line()), e.to_string()))?;
        let csv = dir.join("deviations.csv");
        let points = read_deviations(&csv)?;
        let known = |id: i64| parsed.regions.iter().any(|r| r.id as i64 == id);
        if let Some(i) = points
            .iter()
            .position(|p| p.region < -1 || (p.region >= 0 && !known(p.region)))
        {
            let msg = format!(
                "region {} is neither -1 nor an id of regions.json",
                points[i].region
            );
            return Err(InputError::new(&csv, format!("row {}", i + 1), msg));
        }
        let footprint = dir.join(FOOTPRINT_FILE);
        let fine = match footprint.exists() {
            true => read_footprint(&footprint, points.len())?,
            false => Vec::new(),
        };
        let inspection = Inspection {
            dir: dir.to_path_buf(),
            tolerance: parsed.tolerance,
            regions: parsed.regions,
            points,
            fine: Vec::new(),
        };
        inspection.check(&rfile)?;
        for (i, r) in inspection.regions.iter().enumerate() {
            inspection
                .check_against_rows(r, parsed.spacing, parsed.gap)
                .map_err(|m| InputError::new(&rfile, format!("regions[{i}] (id {})", r.id), m))?;
        }
        // regions.json summarises deviations.csv's distances: checked before they are replaced
        Ok(inspection.read_at_footprint(fine))
    }

    /// This inspection with each core point's distance its reading at the tool's footprint
    /// `fine` (one per point; the distance kept where it is NaN), and `fine` kept beside
    /// (`Inspection::fine`); unchanged when `fine` is empty.
    pub fn read_at_footprint(mut self, fine: Vec<f64>) -> Inspection {
        for (p, f) in self.points.iter_mut().zip(&fine) {
            if f.is_finite() {
                p.distance = *f;
            }
        }
        self.fine = fine;
        self
    }

    /// Points of region `id`, as indices into `points`.
    pub fn region_points(&self, id: usize) -> Vec<usize> {
        (0..self.points.len())
            .filter(|&i| self.points[i].region == id as i64)
            .collect()
    }

    fn check(&self, rfile: &Path) -> Result<(), InputError> {
        for (i, r) in self.regions.iter().enumerate() {
            let place = format!("regions[{i}] (id {})", r.id);
            let finite = r.centroid.iter().chain(&r.normal).all(|v| v.is_finite())
                && [r.area, r.peak, r.mean, r.volume]
                    .iter()
                    .all(|v| v.is_finite());
            if !finite {
                return Err(InputError::new(rfile, place, "values must be finite"));
            }
            let n = Vector3::from(r.normal).norm();
            if (n - 1.0).abs() > 1e-3 {
                return Err(InputError::new(
                    rfile,
                    place,
                    format!("normal has norm {n}"),
                ));
            }
            if self.regions[..i].iter().any(|o| o.id == r.id) {
                return Err(InputError::new(rfile, place, "id repeats"));
            }
            let rows = self.region_points(r.id).len();
            if rows != r.points {
                let msg = format!(
                    "{} points, but deviations.csv has {rows} rows with region {}",
                    r.points, r.id
                );
                return Err(InputError::new(rfile, place, msg));
            }
        }
        Ok(())
    }
}

impl Inspection {
    /// What regions.json says of region `r` against its rows of deviations.csv: the sign of
    /// its peak, `repairable`, its mean distance and centroid, its extent (its rows joined at
    /// `gap`) and its area (about points × `spacing`²).
    fn check_against_rows(
        &self,
        r: &RegionInfo,
        spacing: Option<f64>,
        gap: Option<f64>,
    ) -> Result<(), String> {
        if r.repairable != (r.peak > 0.0) {
            return Err(format!(
                "repairable is {} but the peak is {} mm (material in excess is a positive peak)",
                r.repairable, r.peak
            ));
        }
        let rows: Vec<&SurfacePoint> = self
            .region_points(r.id)
            .iter()
            .map(|&i| &self.points[i])
            .collect();
        if rows.is_empty() {
            return Err("no rows of deviations.csv carry its id".into());
        }
        let n = rows.len() as f64;
        let mean = rows.iter().map(|p| p.distance).sum::<f64>() / n;
        let diff = (mean - r.mean).abs();
        if diff.is_nan() || diff > AGREEMENT_MM * (1.0 + mean.abs()) {
            return Err(format!(
                "mean {} mm, but its rows of deviations.csv average {mean} mm",
                r.mean
            ));
        }
        if r.mean * r.peak < 0.0 {
            return Err(format!(
                "peak {} mm and mean {} mm differ in sign",
                r.peak, r.mean
            ));
        }
        let centroid = rows.iter().map(|p| p.position.coords).sum::<Vector3<f64>>() / n;
        let off = (centroid - Vector3::from(r.centroid)).norm();
        if off.is_nan() || off > AGREEMENT_MM * (1.0 + centroid.norm()) {
            return Err(format!("centroid lies {off} mm from the mean of its rows"));
        }
        if let Some(gap) = gap.filter(|g| g.is_finite() && *g > 0.0) {
            let reach = n * gap;
            let far = rows
                .iter()
                .map(|p| (p.position.coords - centroid).norm())
                .fold(0.0, f64::max);
            if far > reach {
                return Err(format!(
                    "a row lies {far} mm from the centroid, farther than its {n} points joined \
                     at {gap} mm can reach ({reach} mm)"
                ));
            }
        }
        if let Some(s) = spacing.filter(|s| s.is_finite() && *s > 0.0) {
            let ratio = r.area / (n * s * s);
            if !(1.0 / AREA_RATIO_LIMIT..=AREA_RATIO_LIMIT).contains(&ratio) {
                return Err(format!(
                    "area {} mm² is {ratio:.3e} × its {n} points × spacing² ({s} mm): \
                     not the area of its rows",
                    r.area
                ));
            }
        }
        Ok(())
    }
}

fn read(file: &Path) -> Result<String, InputError> {
    std::fs::read_to_string(file).map_err(|e| InputError::new(file, "file", e.to_string()))
}

/// Reads deviations.csv: a header naming the columns (any order, extra columns ignored), then
/// one row per core point; x,y,z,nx,ny,nz,distance,region are required, `uncertainty` is read
/// when present (NaN allowed, else at least 0).
fn read_deviations(file: &Path) -> Result<Vec<SurfacePoint>, InputError> {
    let text = read(file)?;
    let mut lines = text.lines().enumerate();
    let header = lines
        .next()
        .ok_or_else(|| InputError::new(file, "line 1", "empty file"))?
        .1;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    let need = ["x", "y", "z", "nx", "ny", "nz", "distance", "region"];
    let mut col = [0usize; 8];
    for (k, n) in need.iter().enumerate() {
        col[k] = names.iter().position(|h| h == n).ok_or_else(|| {
            InputError::new(file, "line 1", format!("header has no column `{n}`"))
        })?;
    }
    let lod = names.iter().position(|h| *h == "uncertainty");
    let mut out = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let place = || format!("line {}", i + 1);
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.len() != names.len() {
            let msg = format!("{} values, header has {}", cells.len(), names.len());
            return Err(InputError::new(file, place(), msg));
        }
        let mut v = [0.0; 8];
        for (k, c) in col.iter().enumerate() {
            v[k] = cells[*c].parse::<f64>().map_err(|_| {
                let msg = format!("column {}: not a number: {:?}", need[k], cells[*c]);
                InputError::new(file, place(), msg)
            })?;
            // distance is NaN where the comparison found too few points (DESIGN.md)
            let allowed_nan = need[k] == "distance" && v[k].is_nan();
            if !(v[k].is_finite() || allowed_nan) {
                let msg = format!("column {}: not finite", need[k]);
                return Err(InputError::new(file, place(), msg));
            }
        }
        let normal = Vector3::new(v[3], v[4], v[5]);
        let norm = normal.norm();
        if (norm - 1.0).abs() > 1e-3 {
            let msg = format!("normal has norm {norm}");
            return Err(InputError::new(file, place(), msg));
        }
        if v[7].fract() != 0.0 {
            return Err(InputError::new(file, place(), "region must be an integer"));
        }
        let uncertainty = match lod {
            Some(c) => match cells[c].parse::<f64>() {
                Ok(u) if u.is_nan() || (u >= 0.0 && u.is_finite()) => u,
                _ => {
                    let msg = format!("column uncertainty: not a number >= 0: {:?}", cells[c]);
                    return Err(InputError::new(file, place(), msg));
                }
            },
            None => 0.0,
        };
        out.push(SurfacePoint {
            position: Point3::new(v[0], v[1], v[2]),
            normal: normal / norm,
            distance: v[6],
            uncertainty,
            region: v[7] as i64,
        });
    }
    if out.is_empty() {
        return Err(InputError::new(file, "file", "no rows"));
    }
    Ok(out)
}

/// The inspection folder's file of the readings at the tool's footprint (`Inspection::fine`,
/// written by the closed loop's inspections, `inspect::inspect_into`): the header
/// `footprint_distance`, then one distance per core point in deviations.csv's order, mm
/// (`NaN`: too few points; docs/FORMATS.md).
const FOOTPRINT_FILE: &str = "footprint.csv";

/// Reads [`FOOTPRINT_FILE`] `file`, which must hold `rows` readings (deviations.csv's rows).
fn read_footprint(file: &Path, rows: usize) -> Result<Vec<f64>, InputError> {
    let text = read(file)?;
    let mut lines = text.lines();
    if lines.next().map(str::trim) != Some("footprint_distance") {
        return Err(InputError::new(
            file,
            "line 1",
            "header is not `footprint_distance`",
        ));
    }
    let fine = lines
        .enumerate()
        .map(|(i, l)| {
            let bad = |why: String| InputError::new(file, format!("line {}", i + 2), why);
            match l.trim().parse::<f64>() {
                Ok(v) if v.is_infinite() => Err(bad("infinite".into())),
                Ok(v) => Ok(v),
                Err(_) => Err(bad(format!("`{l}` is not a number"))),
            }
        })
        .collect::<Result<Vec<f64>, InputError>>()?;
    if fine.len() != rows {
        let msg = format!(
            "{} readings, but deviations.csv has {rows} rows",
            fine.len()
        );
        return Err(InputError::new(
            file,
            format!("line {}", fine.len() + 2),
            msg,
        ));
    }
    Ok(fine)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The footprint readings read back as the loop writes them (NaN kept), and a file of the
    /// wrong length or with a word in it is refused naming the file and the line.
    #[test]
    fn footprint_readings_round_trip_and_bad_rows_are_named() {
        let dir = std::env::temp_dir().join(format!("polishbot-footprint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join(FOOTPRINT_FILE);
        std::fs::write(&file, "footprint_distance\n0.012\nNaN\n-0.03\n").unwrap();
        let back = read_footprint(&file, 3).unwrap();
        assert_eq!(back[0], 0.012);
        assert!(back[1].is_nan());
        assert_eq!(back[2], -0.03);
        let short = read_footprint(&file, 4).unwrap_err().to_string();
        assert!(
            short.contains("footprint.csv") && short.contains("line 5"),
            "{short}"
        );
        std::fs::write(&file, "footprint_distance\n0.1\nabc\n").unwrap();
        let word = read_footprint(&file, 2).unwrap_err().to_string();
        assert!(word.contains("line 3") && word.contains("abc"), "{word}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A footprint reading replaces a point's distance where it is a number, not where it is
    /// NaN, and an empty one changes nothing.
    #[test]
    fn the_footprint_reading_replaces_the_distance_where_it_has_one() {
        let point = |distance| SurfacePoint {
            position: Point3::origin(),
            normal: Vector3::z(),
            distance,
            uncertainty: 0.01,
            region: -1,
        };
        let inspection = Inspection {
            dir: PathBuf::new(),
            tolerance: Some(0.05),
            regions: Vec::new(),
            points: vec![point(0.1), point(-0.004)],
            fine: Vec::new(),
        };
        let same = inspection.clone().read_at_footprint(Vec::new());
        assert_eq!(same.points[1].distance, -0.004);
        let read = inspection.read_at_footprint(vec![f64::NAN, -0.024]);
        assert_eq!(
            (read.points[0].distance, read.points[1].distance),
            (0.1, -0.024)
        );
        assert_eq!(read.fine.len(), 2);
    }
}

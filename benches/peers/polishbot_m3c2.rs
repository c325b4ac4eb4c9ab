//! polishbot's side of the M3C2 rows of the peer table (`benches/peers/run.py`): classic M3C2
//! and the adaptive (improved, default) variant on the files `m3c2_py4dgeo.py` reads, at the
//! same core points (reference[::stride], the reference's outward normals), timed as py4dgeo
//! is timed there: best of 3, the search structures built inside the timing, loading outside
//! it. The adaptive variant runs with its defaults and the same max distance.
//!
//! usage: `peers_m3c2 DIR RADIUS MAX_DISTANCE COUNT...` (threads: RAYON_NUM_THREADS).
//! DIR holds reference.ply, scan.ply and truth.json (`polishbot synth`); the scan is moved by
//! the true scan_to_reference. Writes DIR/polishbot_m3c2_COUNT.f64 (one little-endian f64
//! classic distance per core point, NaN where none) and prints one JSON line per COUNT with
//! both variants' seconds.
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use polishbot::cloud::{load_cloud, transform::isometry_from_rows, Units};
use polishbot::compare::{compare, CompareConfig, Method};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 4 || args[0].starts_with("--") {
        // `cargo bench` runs every bench target with `--bench`: nothing to do without files.
        println!(
            "peers_m3c2: run by benches/peers/run.py (usage: DIR RADIUS MAX_DISTANCE COUNT...)"
        );
        return Ok(());
    }
    let dir = Path::new(&args[0]);
    let radius: f64 = args[1].parse().context("RADIUS")?;
    let max_distance: f64 = args[2].parse().context("MAX_DISTANCE")?;
    let reference = load_cloud(&dir.join("reference.ply"), None, Some(Units::Mm))?;
    let mut scan = load_cloud(&dir.join("scan.ply"), None, Some(Units::Mm))?;
    #[derive(serde::Deserialize)]
    struct Truth {
        scan_to_reference: [[f64; 4]; 4],
    }
    let truth_path = dir.join("truth.json");
    let truth: Truth = serde_json::from_str(&std::fs::read_to_string(&truth_path)?)
        .with_context(|| truth_path.display().to_string())?;
    scan.transform(&isometry_from_rows(&truth.scan_to_reference)?);
    let classic = CompareConfig {
        method: Method::Classic,
        radius: Some(radius),
        max_distance,
        min_points: 1, // py4dgeo's rule: NaN only for an empty cylinder
        ..CompareConfig::default()
    };
    let adaptive = CompareConfig {
        method: Method::Adaptive,
        max_distance,
        ..CompareConfig::default()
    };
    for count in &args[3..] {
        let count: usize = count.parse().context("COUNT")?;
        let stride = reference.len() / count;
        let idx: Vec<usize> = (0..reference.len()).step_by(stride).take(count).collect();
        let core = reference.select(&idx);
        // Best of 3 runs: the seconds and the last run's distances.
        let best_of_3 = |cfg: &CompareConfig| -> Result<(f64, Vec<f64>)> {
            let mut best = f64::INFINITY;
            let mut distances = Vec::new();
            for _ in 0..3 {
                let t = Instant::now();
                let dev = compare(&core, &reference, &scan, cfg)?;
                best = best.min(t.elapsed().as_secs_f64());
                distances = dev.values.iter().map(|v| v.distance).collect();
            }
            Ok((best, distances))
        };
        let (seconds, distances) = best_of_3(&classic)?;
        let (adaptive_seconds, _) = best_of_3(&adaptive)?;
        let out = dir.join(format!("polishbot_m3c2_{count}.f64"));
        let bytes: Vec<u8> = distances.iter().flat_map(|d| d.to_le_bytes()).collect();
        std::fs::write(&out, bytes).with_context(|| out.display().to_string())?;
        println!(
            "{}",
            serde_json::json!({"count": count, "seconds": seconds,
                "adaptive_seconds": adaptive_seconds, "distances": out})
        );
    }
    Ok(())
}

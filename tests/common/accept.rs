//! Issue 29's acceptance harness: one synth case through `cycle --mode removal` against the
//! simulator, scored against the simulator's own truth (`after_truth.ply`: the removal per
//! point) and synth's planted defects; shared by tests/cycle.rs's suite cases and its ten.
use std::path::Path;

use nalgebra::{Point3, Vector3};
use polishbot::spatial::Neighbours;
use polishbot::synth::{DefectKind, SiteProbe, Truth};

use super::polishbot;
use super::true_part::TruePart;
pub use super::true_part::TrueState;

/// The planted defect's footprint radius on the surface, mm (as demo's summary matches).
pub fn footprint(width: f64, length: f64) -> f64 {
    width + length / 2.0
}

/// Signed distance of each point to the reference cloud (nearest point's normal), mm.
pub fn true_deviation(
    reference: &polishbot::cloud::PointCloud,
    points: &[Point3<f64>],
) -> Vec<f64> {
    let index = Neighbours::new(&reference.points);
    let normals = reference.normals.as_ref().unwrap();
    points
        .iter()
        .map(|p| {
            let nb = index.nearest(p).unwrap();
            normals[nb.index].dot(&(p - reference.points[nb.index]))
        })
        .collect()
}

/// 90th percentile of `v` (None when empty).
pub fn p90(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[(v.len() - 1) * 9 / 10])
}

/// Per planted bump or ridge: the 90th percentile of the true deviation over the points of
/// its central part (half its footprint) before and after one iteration's grind, from that
/// iteration's truth file (the removal per point); and the largest removal on any pit.
pub fn truth_scores(dir: &Path, truth: &Truth, iter: usize) -> (Vec<(f64, f64)>, f64) {
    let reference = polishbot::cloud::load_cloud(&dir.join("reference.ply"), None, None).unwrap();
    let file = dir.join(format!("cycle/iter-{iter}/after_truth.ply"));
    let ground = polishbot::cloud::load_cloud(&file, None, None).unwrap();
    let removal = ground.field("removal").unwrap();
    let dev = true_deviation(&reference, &ground.points);
    let mut peaks = Vec::new();
    let mut on_pits: f64 = 0.0;
    for d in &truth.defects {
        let c = Point3::from(d.centre);
        let r = footprint(d.width, d.length);
        let inside: Vec<usize> = (0..ground.len())
            .filter(|&i| (ground.points[i] - c).norm() < r)
            .collect();
        if d.kind == DefectKind::Pit {
            on_pits = inside.iter().map(|&i| removal[i]).fold(on_pits, f64::max);
            continue;
        }
        let centre: Vec<usize> = (0..ground.len())
            .filter(|&i| (ground.points[i] - c).norm() < r / 2.0)
            .collect();
        let after = p90(centre.iter().map(|&i| dev[i]).collect()).unwrap();
        let before = p90(centre.iter().map(|&i| dev[i] + removal[i]).collect()).unwrap();
        peaks.push((before, after));
    }
    (peaks, on_pits)
}

/// `cycle` on the case in `dir` (reference.ply, scan.ply) into `dir/out`.
pub fn cycle(dir: &Path, out: &str) -> std::process::Command {
    let mut cmd = polishbot();
    cmd.arg("cycle")
        .arg("--reference")
        .arg(dir.join("reference.ply"))
        .arg("--scan")
        .arg(dir.join("scan.ply"))
        .arg("-o")
        .arg(dir.join(out));
    cmd
}

/// One inspection of an acceptance case.
#[derive(Debug, Clone, Copy)]
pub struct Inspected {
    /// Repairable regions.
    pub regions: usize,
    /// Their volume above the tolerance, mm^3.
    pub volume: f64,
    /// Their highest peak, mm.
    pub peak: f64,
    /// The lowest core point measured to within the tolerance, away from the planted pits, mm.
    pub lowest: f64,
    /// As `lowest`, over the ground area only (within [`GROUND_REACH_MM`] of a point an
    /// earlier grind removed from; infinite before the first grind), mm.
    pub lowest_ground: f64,
    /// Core points of repairable regions above the tolerance where the arm reaches.
    pub open: usize,
}

/// One acceptance case's numbers (issue 29): per inspection the repairable volume above the
/// tolerance and peak, and the lowest core points; the first fitted k against the true k (the
/// scale that maps iteration 1's predicted removal, moved to where the tool really ground,
/// onto the simulator's true removal, `after_truth.ply`: `super::true_k`).
#[derive(Debug)]
pub struct Acceptance {
    /// Every inspection, in order.
    pub inspections: Vec<Inspected>,
    /// The lowest true deviation (synth's planted deviation less the simulator's removal, see
    /// `TruePart`) at a point the grinds removed from, away from the pits, mm; how many of
    /// those points lie more than the tolerance below nominal, of how many.
    pub true_low: (f64, usize, usize),
    /// First fitted k / true k (None: not fitted).
    pub k_ratio: Option<f64>,
    /// Every grind's fitted k (cycle.json's `k_fitted`, the k the next plan used) / true k.
    pub k_ratios: Vec<Option<f64>>,
    /// Largest removal summed over the grinds on a pit's footprint, mm.
    pub on_pits: f64,
    /// Iteration 1's agreement (cycle.json): RMS over its defect points of the residual
    /// predicted at the plan's k, at the fitted k, achieved, and achieved minus predicted at
    /// the fitted k point by point, mm.
    pub agreement: Option<[f64; 4]>,
    /// The true part before the first grind and after each grind (noise-free, `TruePart`).
    pub truth: Vec<TrueState>,
    /// First fitted k / the cell's Preston k (`[sim.grinding]` preston_k x k_factor, read from
    /// the settings the cell ran; None: not fitted).
    pub k_cell: Option<f64>,
    /// How the loop ended (cycle.json's `outcome`, e.g. "max_iterations", "off_plan").
    pub outcome: String,
    /// Each grind's plan (plan.json `removal.regions[]`): the highest region peak before it
    /// and the highest the plan predicts after it, mm.
    pub planned_peaks: Vec<(f64, f64)>,
}

/// A core point is in the ground area when a point some grind removed from lies this near,
/// mm (2.0: over the 1.85 mm projection radius the cases' inspections use, so every core point
/// whose measurement a ground point enters counts).
pub const GROUND_REACH_MM: f64 = 2.0;

/// Runs `cycle --mode removal` on synth case `seed` with the simulator's true k 1.3 x the
/// planner's (`super::SIM_TOOL`) on the cell's default (documented) arm, up to 3 grinds, and
/// collects the numbers.
pub fn acceptance(seed: u64) -> Acceptance {
    acceptance_with(seed, "")
}

/// `[sim.grinding]` line of a cell whose arm has no backlash, sag or lag (issue 50).
pub const IDEAL_ARM: &str = "ideal_arm = true\n";

/// [`acceptance`] with more `[sim.grinding]` lines `sim` (e.g. [`IDEAL_ARM`]).
pub fn acceptance_with(seed: u64, sim: &str) -> Acceptance {
    let servos = std::env::var("POLISHBOT_ACCEPT_SERVOS").unwrap_or_default();
    acceptance_in(seed, sim, &format!("accept-{seed}"), &servos)
}

/// [`acceptance_with`] in the scratch folder `name` (runs side by side each need their own),
/// the cell's servos.toml `servos`: "" the shipped one, "fitted" the table `calibrate
/// compliance` fits on this case's simulated arm, else a file's path.
pub fn acceptance_in(seed: u64, sim: &str, name: &str, servos: &str) -> Acceptance {
    let dir = super::scratch(name);
    let truth = super::case(seed, &dir);
    let arm = run_removal_loop(&dir, sim, servos);
    let near_pit = |p: &Point3<f64>| {
        truth.defects.iter().any(|d| {
            d.kind == DefectKind::Pit
                && (Point3::from(d.centre) - p).norm() < footprint(d.width, d.length) + 1.0
        })
    };
    let mut inspections = Vec::new();
    let mut part = TruePart::default();
    let mut states = Vec::new();
    let reach = polishbot::cell::reachable_sites(&super::shipped_cell(), 0.0).unwrap();
    let in_area = |p: &Point3<f64>, n: &Vector3<f64>| !near_pit(p) && reach(&[(*p, *n)]);
    for k in 1.. {
        let it = dir.join(format!("cycle/iter-{k}"));
        let Ok(i) = polishbot::repair::Inspection::load(&it.join("inspection")) else {
            break;
        };
        inspections.push(inspected(&it, &i, &part, &near_pit, &reach));
        if it.join("after_truth.ply").is_file() {
            part.grind(&dir, &truth, k, &in_area);
            if k == 1 {
                states.push(part.state(false));
            }
            states.push(part.state(true));
        }
    }
    let (k_ratio, k_ratios, agreement) = k_numbers(&dir);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cycle/cycle.json")).unwrap())
            .unwrap();
    let a = Acceptance {
        inspections,
        true_low: part.lowest_ground(&|p| !near_pit(p)),
        on_pits: part.most_removed(&|p| {
            truth.defects.iter().any(|d| {
                d.kind == DefectKind::Pit
                    && (Point3::from(d.centre) - p).norm() < footprint(d.width, d.length)
            })
        }),
        k_ratio,
        k_ratios,
        agreement,
        truth: states,
        k_cell: first_fitted_k(&dir).map(|k| k / (arm.preston_k * arm.k_factor)),
        outcome: json["outcome"].as_str().unwrap_or("?").to_string(),
        planned_peaks: planned_peaks(&dir),
    };
    println!("acceptance seed {seed}: {a:.4?}");
    // `POLISHBOT_ACCEPT_GOUGED=1`: the true points ground below -tolerance, one line each
    // (reference frame x, y, z; planted deviation; each grind's removal, mm), to `gouged.csv`
    // of the run's folder, to take a gouge apart by hand (with `POLISHBOT_SURVEY_KEEP=1`)
    if std::env::var_os("POLISHBOT_ACCEPT_GOUGED").is_some() {
        let rows: String = (part.below(&|p| !near_pit(p), -TOLERANCE_MM).iter())
            .map(|(p, planted, by)| {
                let by: Vec<String> = by.iter().map(|r| format!("{r:.5}")).collect();
                format!("{},{},{},{planted:.5},{}\n", p.x, p.y, p.z, by.join(";"))
            })
            .collect();
        std::fs::write(dir.join("gouged.csv"), rows).unwrap();
    }
    a
}

/// Writes the loop's settings into `dir` (cycle.toml: `super::SIM_TOOL`, `sim`, the
/// `[sim.grinding]` lines of `POLISHBOT_ACCEPT_SIM`, and the cell's servos.toml `servos` as in
/// [`acceptance_in`]) and runs `cycle --mode removal` there; returns the simulated arm's
/// settings.
fn run_removal_loop(dir: &Path, sim: &str, servos: &str) -> polishbot::sim::GrindConfig {
    let cfg = dir.join("cycle.toml");
    // more of the simulated cell's truth, to take it apart by hand: `;`-separated
    // `[sim.grinding]` lines whose keys SIM_TOOL does not set (e.g. "pressure_exponent = 1.0;
    // k_noise = 0.0")
    let extra = std::env::var("POLISHBOT_ACCEPT_SIM")
        .unwrap_or_default()
        .replace(';', "\n");
    // a cell whose servos.toml has `[compliance]` (issue 50's compensation): `fitted`, the
    // table `calibrate compliance` fits on this case's simulated arm, or a file given by hand
    let mut servos = servos.to_string();
    let arm: polishbot::sim::GrindConfig =
        toml::from_str(&format!("{}{sim}{extra}", super::SIM_TOOL)).unwrap();
    if servos == "fitted" {
        let c = super::compensation::fitted(&arm);
        println!("fitted [compliance]: {c:?}");
        servos = super::compensation::servos_with(&c, dir)
            .display()
            .to_string();
    }
    let robot = match servos.is_empty() {
        true => String::new(),
        false => format!("[plan.robot]\nservos = {servos:?}\n[run.robot]\nservos = {servos:?}\n"),
    };
    std::fs::write(
        &cfg,
        format!(
            "{robot}[run.sim.grinding]\n{}{sim}{extra}\n",
            super::SIM_TOOL
        ),
    )
    .unwrap();
    let mut command = cycle(dir, "cycle");
    command
        .args(["--sim", "--mode", "removal", "--config"])
        .arg(&cfg);
    // more grinds than the 3, to see what a 4th would do (run by hand)
    if let Ok(grinds) = std::env::var("POLISHBOT_ACCEPT_GRINDS") {
        command.args(["--max-iterations", &grinds]);
    }
    // the planner reading the part at the tool's footprint (docs/ALGORITHMS.md, "The loop
    // reads at the tool's footprint"; run by hand)
    if let Ok(radius) = std::env::var("POLISHBOT_ACCEPT_FOOTPRINT") {
        command.args(["--footprint-radius", &radius]);
    }
    let out = command.output().unwrap();
    println!("{}", String::from_utf8_lossy(&out.stdout));
    let code = out.status.code();
    assert!(
        code == Some(0) || code == Some(4),
        "{code:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    arm
}

/// One inspection's numbers (`it`: its iteration's folder, `i` the inspection read from it;
/// `part`: the true part as ground so far, `near_pit` and `reach` the area judged).
fn inspected(
    it: &Path,
    i: &polishbot::repair::Inspection,
    part: &TruePart,
    near_pit: &dyn Fn(&Point3<f64>) -> bool,
    reach: &dyn Fn(&[SiteProbe]) -> bool,
) -> Inspected {
    let rep: Vec<_> = i.regions.iter().filter(|r| r.repairable).collect();
    let sure = measured_within(&it.join("inspection"), TOLERANCE_MM);
    assert_eq!(sure.len(), i.points.len());
    let judged: Vec<_> = i
        .points
        .iter()
        .zip(&sure)
        .filter(|(p, s)| **s && p.distance.is_finite() && !near_pit(&p.position))
        .map(|(p, _)| p)
        .collect();
    let lowest = judged
        .iter()
        .map(|p| p.distance)
        .fold(f64::INFINITY, f64::min);
    let ground = part.ground();
    let ground_index = (!ground.is_empty()).then(|| Neighbours::new(&ground));
    let lowest_ground = judged
        .iter()
        .filter(|p| {
            ground_index
                .as_ref()
                .is_some_and(|g| !g.within(&p.position, GROUND_REACH_MM).is_empty())
        })
        .map(|p| p.distance)
        .fold(f64::INFINITY, f64::min);
    // the "reachable area": the tool reaches the point square to the reference
    // surface within the planner's axis limit (a defect at the part's edge has a rim the
    // 5-DOF arm cannot tilt to: plan.json lists its raster points as unreachable)
    let open = i
        .points
        .iter()
        .filter(|p| {
            rep.iter().any(|r| r.id as i64 == p.region)
                && p.distance > TOLERANCE_MM
                && reach(&[(p.position, p.normal)])
        })
        .count();
    Inspected {
        regions: rep.len(),
        volume: rep.iter().map(|r| r.volume).sum(),
        peak: rep.iter().map(|r| r.peak).fold(0.0, f64::max),
        lowest,
        lowest_ground,
        open,
    }
}

/// The loop's k in `dir` against the true k: the first refit's ratio (None: not refitted),
/// every grind's (cycle.json's `k_fitted`), and iteration 1's agreement (see [`Acceptance`]).
fn k_numbers(dir: &Path) -> (Option<f64>, Vec<Option<f64>>, Option<[f64; 4]>) {
    let fitted = first_fitted_k(dir);
    let plan_k = polishbot::removal::ToolModel::load(&super::calib("tool.toml"))
        .unwrap()
        .preston_k_mm2_n;
    let it = dir.join("cycle/iter-1");
    let k_true = super::true_k(
        &it.join("inspection"),
        &it.join("predicted.csv"),
        &it.join("after_truth.ply"),
        plan_k,
    );
    let k_ratio = fitted.map(|k| k / k_true);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("cycle/cycle.json")).unwrap())
            .unwrap();
    let agreement = json["records"][0]["agreement"].as_object().map(|a| {
        [
            "predicted_plan_k_mm",
            "predicted_fitted_k_mm",
            "achieved_mm",
            "difference_mm",
        ]
        .map(|key| a[key].as_f64().unwrap_or(f64::NAN))
    });
    let k_ratios = json["records"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["planned_volume_mm3"].is_number())
        .map(|r| r["k_fitted"].as_f64().map(|k| k / k_true))
        .collect();
    (k_ratio, k_ratios, agreement)
}

/// Each grind's plan's highest region peak before and predicted after it (plan.json), mm.
fn planned_peaks(dir: &Path) -> Vec<(f64, f64)> {
    (1..)
        .map(|k| dir.join(format!("cycle/iter-{k}/plan.json")))
        .take_while(|p| p.is_file())
        .map(|p| {
            let plan: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
            let regions = plan["removal"]["regions"].as_array().cloned();
            let peak = |when: &str| {
                regions.iter().flatten().fold(0.0, |m: f64, r| {
                    m.max(r[when]["peak_mm"].as_f64().unwrap_or(f64::NAN))
                })
            };
            (peak("before"), peak("after"))
        })
        .collect()
}

/// The k the loop fitted after its first grind (iter-2/tool.toml; None: not refitted), mm^2/N.
fn first_fitted_k(dir: &Path) -> Option<f64> {
    let refit = dir.join("cycle/iter-2/tool.toml");
    refit.is_file().then(|| {
        polishbot::removal::ToolModel::load(&refit)
            .unwrap()
            .preston_k_mm2_n
    })
}

/// Tolerance of the cases, mm (inspect's default).
pub const TOLERANCE_MM: f64 = 0.05;

/// Per core point of the inspection in `dir` (deviations.csv's rows, in order): whether its
/// distance is measured to within `limit` mm (its `uncertainty` at most that). A point measured
/// from a handful of scan points at an edge (seed 1: 6 scan points, uncertainty 0.30 mm,
/// distance -0.094 then -0.123 mm on rescans, true removal 0) cannot say whether the part is
/// below the tolerance there, and is not counted as over-ground.
pub fn measured_within(dir: &Path, limit: f64) -> Vec<bool> {
    let text = std::fs::read_to_string(dir.join("deviations.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "uncertainty").unwrap();
    lines
        .map(|l| {
            let u: f64 = l.split(',').nth(col).unwrap().parse().unwrap_or(f64::NAN);
            u <= limit
        })
        .collect()
}

/// The acceptance on one case: no core point of a repairable region above the
/// tolerance where the arm reaches after the last grind; no core point where the cell ground
/// measured more than the tolerance below nominal on any re-inspection; pits untouched; the
/// first fitted k within 10 % of the true k. Reported, not judged: measured core points below
/// the tolerance where the cell never ground (inspection error on the part's outer faces,
/// where the simulator's truth averages -0.001..-0.005 mm) and single points of the truth
/// below it (`true_low`: 0-7 of the 95-748 ground points of a case).
pub fn accepted(a: &Acceptance) -> bool {
    let last = a.inspections.last().unwrap();
    last.open == 0
        && a.inspections
            .iter()
            .all(|i| i.lowest_ground >= -TOLERANCE_MM)
        && a.on_pits == 0.0
        && a.k_ratio.is_some_and(|r| (r - 1.0).abs() <= 0.1)
}

/// Points of grind `k`'s truth (every 50th) that grind `k` did not touch, and how far the
/// farthest of them lies from the part grind `k - 1` left (its truth), mm: the simulator grinds
/// one virtual part, so what a grind leaves alone keeps its place to the bit (before the part
/// was carried over, it was rebuilt from each noisy rescan and drifted by 0.01 mm of mean and
/// 0.015 mm of noise per grind, raising new 0.12 mm "defects" by the third).
pub fn untouched_drift(dir: &Path, k: usize) -> (usize, f64) {
    let load = |k: usize| {
        let f = dir.join(format!("cycle/iter-{k}/after_truth.ply"));
        polishbot::cloud::load_cloud(&f, None, None).unwrap()
    };
    let (before, after) = (load(k - 1), load(k));
    let index = Neighbours::new(&before.points);
    let removal = after.field("removal").unwrap();
    let untouched: Vec<usize> = (0..after.len())
        .step_by(50)
        .filter(|&i| removal[i] == 0.0)
        .collect();
    let drift = untouched
        .iter()
        .map(|&i| index.nearest(&after.points[i]).unwrap().dist2.sqrt())
        .fold(0.0, f64::max);
    (untouched.len(), drift)
}

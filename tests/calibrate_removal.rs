//! Removal calibration (issue 29, `polishbot calibrate removal`): the fit against closed-form
//! cases written here (a known scale of a known removal field; Gaussian noise and the
//! textbook standard error of a slope through the origin, sigma / sqrt(sum p^2)), its
//! refusals, the pooling of grinds planned at different k (`cycle`), and the binary on a
//! simulated grind scored against the simulator's own truth (`after_truth.ply`: the removal
//! per point). The closed-form grid: tests/common/fit_grid.rs.
mod common;

use std::path::Path;

use polishbot::motion::Inspection;
use polishbot::removal::fit::{
    agreement, evidence, fit, parse_predicted, pool, predicted_removal, Evidence, FitConfig,
    GrindPair,
};
use polishbot::removal::prediction::PredictedRow;
use rand::{Rng, SeedableRng};

use common::fit_grid::{after, before, expected_used, PLAN_K};
use common::polishbot;

#[test]
fn a_known_scale_of_a_known_removal_field_gives_k_exactly() {
    let (b, p) = before();
    let s = 1.37;
    let removed: Vec<f64> = p.iter().map(|v| s * v).collect();
    let mut a = after(&b, &removed);
    // unmeasured points are left out; the pit's points too, whatever the field says there
    a.points[0].distance = f64::NAN;
    let f = fit(&GrindPair::new(&b, &a), &p, PLAN_K, &FitConfig::default()).unwrap();
    let used = expected_used(&b, &p)
        .into_iter()
        .filter(|&i| i != 0)
        .count();
    assert_eq!(f.points, used);
    assert!(
        (f.k_mm2_n / (s * PLAN_K) - 1.0).abs() < 1e-12,
        "{}",
        f.k_mm2_n
    );
    assert!(f.residual_rms_mm < 1e-12 && f.k_std_error_mm2_n < 1e-15);
    assert_eq!(f.regions.len(), 2);
    for r in &f.regions {
        assert!((r.k_mm2_n / (s * PLAN_K) - 1.0).abs() < 1e-12);
    }
    // predicted.csv rows are summed per core point (one row per region whose reach holds it)
    let rows: Vec<PredictedRow> = b
        .points
        .iter()
        .zip(&p)
        .flat_map(|(pt, v)| {
            let half = PredictedRow {
                position: pt.position.coords.into(),
                deviation: pt.distance,
                residual: pt.distance - v / 2.0,
                spread_p95: 0.0,
            };
            [half, half]
        })
        .collect();
    let summed = predicted_removal(&b, &rows).unwrap();
    assert!(summed.iter().zip(&p).all(|(a, b)| (a - b).abs() < 1e-12));
}

/// RMS of `f` over the indices `idx`.
fn rms_over(idx: &[usize], f: impl Fn(usize) -> f64) -> f64 {
    (idx.iter().map(|&i| f(i).powi(2)).sum::<f64>() / idx.len() as f64).sqrt()
}

#[test]
fn a_pass_re_predicted_with_the_fitted_k_scales_the_predicted_removal_at_each_point() {
    let (b, p) = before();
    // the true removal: 1.3 x the prediction, plus a ripple of +-0.004 mm point by point
    let ripple = |i: usize| if i.is_multiple_of(2) { 0.004 } else { -0.004 };
    let removed: Vec<f64> = (0..p.len()).map(|i| 1.3 * p[i] + ripple(i)).collect();
    let mut a = after(&b, &removed);
    // a point the second inspection did not measure is left out
    a.points[1].distance = f64::NAN;
    let got = agreement(&GrindPair::new(&b, &a), &p, Some(1.3), &[0, 1]).unwrap();
    // written out here: the defect points of regions 0 and 1, deviation d = p + 0.05 before
    let idx: Vec<usize> = (0..p.len())
        .filter(|&i| b.points[i].region < 2 && i != 1)
        .collect();
    let d = |i: usize| p[i] + 0.05;
    let close = |x: f64, y: f64| assert!((x - y).abs() < 1e-12, "{x} vs {y}");
    assert_eq!(got.points, idx.len());
    close(got.predicted_plan_k_mm, rms_over(&idx, |i| d(i) - p[i]));
    close(
        got.predicted_fitted_k_mm.unwrap(),
        rms_over(&idx, |i| 0.05 - 0.3 * p[i]),
    );
    close(got.achieved_mm, rms_over(&idx, |i| d(i) - removed[i]));
    // at the fitted k only the ripple is left between prediction and achievement
    close(got.difference_mm, 0.004);
    // the lowest ground point: over the defect points and wherever removal was predicted
    // (the pit region's points in the tool's reach too)
    let lowest = (0..p.len())
        .filter(|&i| i != 1 && (b.points[i].region < 2 || p[i] > 0.0))
        .map(|i| d(i) - removed[i])
        .fold(f64::INFINITY, f64::min);
    close(got.lowest_ground_mm, lowest);
    // k not fitted: compared with the plan's k
    let plain = agreement(&GrindPair::new(&b, &a), &p, None, &[0, 1]).unwrap();
    assert_eq!(plain.predicted_fitted_k_mm, None);
    close(
        plain.difference_mm,
        rms_over(&idx, |i| 0.3 * p[i] + ripple(i)),
    );
    // no planned region: nothing to compare
    assert_eq!(
        agreement(&GrindPair::new(&b, &a), &p, Some(1.3), &[7]),
        None
    );
}

#[test]
fn the_planners_removal_rate_is_linear_in_k() {
    // what makes the re-prediction a scaling: the planner's removal is its influence rate
    // times the dwell, and the rate at every patch offset is proportional to k
    use polishbot::removal::{Influence, Tilt, ToolModel};
    let tool = ToolModel::default();
    let scaled = ToolModel {
        preston_k_mm2_n: tool.preston_k_mm2_n * 1.37,
        ..tool.clone()
    };
    let (a, b) = (Influence::new(&tool, 3.0), Influence::new(&scaled, 3.0));
    let mut nonzero = 0;
    for i in -8..=8 {
        for j in -8..=8 {
            let (x, y) = (i as f64 * 0.08, j as f64 * 0.08);
            let tilt = Tilt::of_angle(20f64.to_radians());
            let (ra, rb) = (a.rate(x, y, tilt), b.rate(x, y, tilt));
            assert!((rb - 1.37 * ra).abs() <= 1e-12 * rb.abs(), "({x}, {y})");
            nonzero += usize::from(ra > 0.0);
        }
    }
    assert!(nonzero > 50, "{nonzero} offsets inside the patch");
}

/// One standard normal draw (Box-Muller).
fn normal(rng: &mut impl Rng) -> f64 {
    let (u, v): (f64, f64) = (rng.gen::<f64>().max(1e-300), rng.gen());
    (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
}

#[test]
fn noise_on_the_measured_removal_gives_the_textbook_spread() {
    let (b, p) = before();
    let (s, sigma, trials) = (0.7, 0.015, 300);
    let used = expected_used(&b, &p);
    let pp: f64 = used.iter().map(|&i| p[i] * p[i]).sum();
    let want = sigma / pp.sqrt();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(29);
    let (mut ks, mut ses, mut rms) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..trials {
        let removed: Vec<f64> = p.iter().map(|v| s * v + sigma * normal(&mut rng)).collect();
        let a = after(&b, &removed);
        let f = fit(&GrindPair::new(&b, &a), &p, PLAN_K, &FitConfig::default()).unwrap();
        ks.push(f.k_mm2_n / PLAN_K);
        ses.push(f.k_std_error_mm2_n / PLAN_K);
        rms.push(f.residual_rms_mm);
    }
    let n = trials as f64;
    let mean = ks.iter().sum::<f64>() / n;
    let sd = (ks.iter().map(|k| (k - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let se = ses.iter().sum::<f64>() / n;
    let r = rms.iter().sum::<f64>() / n;
    println!("scale mean {mean:.5} sd {sd:.5} reported se {se:.5} textbook {want:.5} rms {r:.5}");
    // unbiased within 3 standard errors of the mean of 300 trials
    assert!((mean - s).abs() < 3.0 * want / n.sqrt(), "{mean}");
    // the spread of 300 draws is within 15 % of the textbook value (its own relative
    // uncertainty is 1 / sqrt(2 x 300) = 4 %), the reported standard error within 5 %
    assert!((sd / want - 1.0).abs() < 0.15, "{sd} vs {want}");
    assert!((se / want - 1.0).abs() < 0.05, "{se} vs {want}");
    assert!((r / sigma - 1.0).abs() < 0.05, "{r} vs {sigma}");
}

#[test]
fn thin_evidence_and_unmatched_core_points_are_refused_in_one_line() {
    let (b, p) = before();
    let removed: Vec<f64> = p.iter().map(|v| 0.9 * v).collect();
    let a = after(&b, &removed);
    let strict = FitConfig {
        min_points: 100_000,
        ..FitConfig::default()
    };
    let e = fit(&GrindPair::new(&b, &a), &p, PLAN_K, &strict).unwrap_err();
    assert!(e.contains("too little evidence"), "{e}");
    // a rescan against another reference (core points 0.01 mm away)
    let mut moved = a.clone();
    moved.points.iter_mut().for_each(|q| q.position.x += 0.01);
    let pair = GrindPair::new(&b, &moved);
    let e = fit(&pair, &p, PLAN_K, &FitConfig::default()).unwrap_err();
    assert!(e.contains("not made against the same reference"), "{e}");
    // nothing removed
    let e = fit(&GrindPair::new(&b, &b), &p, PLAN_K, &FitConfig::default()).unwrap_err();
    assert!(e.contains("nothing was removed"), "{e}");
    // noise ten times the removal: k is not determined
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let noisy: Vec<f64> = p.iter().map(|v| v + 2.0 * normal(&mut rng)).collect();
    let noisy = after(&b, &noisy);
    let pair = GrindPair::new(&b, &noisy);
    let e = fit(&pair, &p, PLAN_K, &FitConfig::default()).unwrap_err();
    assert!(e.contains("relative error"), "{e}");
    assert!(!e.contains('\n'));
    // predicted.csv: bad cells name the line and column; rows off the core points the row
    let e =
        parse_predicted("x,y,z,deviation,predicted_residual,spread_p95\n1,2,x,4,5,\n").unwrap_err();
    assert_eq!(e, "line 2: column 3: not a finite number");
    let off = PredictedRow {
        position: [100.0, 0.0, 0.0],
        ..PredictedRow::default()
    };
    let e = predicted_removal(&b, &[off]).unwrap_err();
    assert!(
        e.starts_with("row 1: (100.000, 0.000, 0.000) is no core point"),
        "{e}"
    );
}

/// Scanner noise on the measured removal of the pooled grinds, mm (the rescan's).
const NOISE_MM: f64 = 0.015;
/// The true k of the pooled grinds: 1.3 x the first plan's, as the simulated tool's.
const TRUE_K: f64 = 1.3 * PLAN_K;

/// A grind of `before()` planned at `plan_k` predicting `p`, removing `bias` x what TRUE_K
/// would (the prediction x TRUE_K / plan_k) plus NOISE_MM of Gaussian noise: its evidence and
/// the (u, m) pairs the fit should use (u = p / plan_k, m the removal), worked out here.
fn grind(
    b: &Inspection,
    p: &[f64],
    plan_k: f64,
    bias: f64,
    rng: &mut impl Rng,
) -> (Evidence, Vec<(f64, f64)>) {
    let removed: Vec<f64> = p
        .iter()
        .map(|v| bias * TRUE_K / plan_k * v + NOISE_MM * normal(rng))
        .collect();
    let a = after(b, &removed);
    let g = evidence(&GrindPair::new(b, &a), p, plan_k, &FitConfig::default()).unwrap();
    let pairs = expected_used(b, p)
        .into_iter()
        .map(|i| (p[i] / plan_k, removed[i]))
        .collect();
    (g, pairs)
}

#[test]
fn grinds_planned_at_different_k_pool_into_one_fit_and_a_thin_grind_adds_its_points() {
    let (b, p) = before();
    let cfg = FitConfig::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(21);
    // grind 1 at the plan's k; grind 2 a finishing grind planned at a refitted k that
    // predicts 3 % of the bump (66 points above 0.005 mm, each removal near the noise) and
    // removed half of what the true k would: alone its k's relative error is above 0.25
    let (g1, pairs1) = grind(&b, &p, PLAN_K, 1.0, &mut rng);
    let p2: Vec<f64> = p.iter().map(|v| 0.03 * v).collect();
    let k2 = 1.25 * PLAN_K;
    let (g2, pairs2) = grind(&b, &p2, k2, 0.5, &mut rng);
    assert_eq!(
        (g1.points.len(), g2.points.len()),
        (pairs1.len(), pairs2.len())
    );
    let e = pool(std::slice::from_ref(&g2), &cfg).unwrap_err();
    assert!(e.contains("too little evidence"), "{e}");
    let loose = FitConfig {
        min_points: 2,
        max_relative_error: f64::INFINITY,
        ..cfg
    };
    let own2 = pool(std::slice::from_ref(&g2), &loose).unwrap().k_mm2_n;
    let own1 = pool(std::slice::from_ref(&g1), &cfg).unwrap();
    let both = pool(&[g1, g2], &cfg).unwrap();
    // closed form over both grinds' points
    let all: Vec<(f64, f64)> = pairs1.iter().chain(&pairs2).copied().collect();
    let uu: f64 = all.iter().map(|(u, _)| u * u).sum();
    let k = all.iter().map(|(u, m)| u * m).sum::<f64>() / uu;
    let ss: f64 = all.iter().map(|(u, m)| (m - k * u).powi(2)).sum();
    let se = (ss / (all.len() as f64 - 1.0) / uu).sqrt();
    println!(
        "grind 1 alone {:.4e}, grind 2 alone {own2:.4e} ({} points), pooled {:.4e} +- {:.2e}, \
         true {TRUE_K:.4e}",
        own1.k_mm2_n,
        pairs2.len(),
        both.k_mm2_n,
        both.k_std_error_mm2_n
    );
    assert!(
        (both.k_mm2_n / k - 1.0).abs() < 1e-12,
        "{} vs {k}",
        both.k_mm2_n
    );
    assert!((both.k_std_error_mm2_n / se - 1.0).abs() < 1e-9);
    assert_eq!((both.points, both.grinds), (all.len(), 2));
    assert_eq!(both.plan_k_mm2_n, k2);
    // the thin grind's points are in the fit, yet it does not drag k towards its own
    assert!(both.k_mm2_n != own1.k_mm2_n);
    assert!((own2 / TRUE_K - 1.0).abs() > 0.3, "{own2}");
    assert!((both.k_mm2_n / own1.k_mm2_n - 1.0).abs() < 0.01);
    assert!((both.k_mm2_n - TRUE_K).abs() < 3.0 * both.k_std_error_mm2_n);
}

/// The bound on the first fit: within 10 % of the true k.
const K_WITHIN: f64 = 0.10;

#[test]
fn the_binary_fits_k_from_a_simulated_grind_within_a_tenth_of_the_true_k() {
    let dir = common::scratch("calibrate_removal");
    let d = |f: &str| dir.join(f).display().to_string();
    // tests/cycle.rs's case: 5 defects (0.08-0.5 mm) where the arm reaches, one a pit
    common::case(3, &dir);
    common::inspect_in(&dir, "scan.ply", "before");
    // the simulator's true k 1.3 x the planner's (issue 29's "30 % off"), on an ideal arm
    // whose compliance table is its own (`calibrate compliance --sim` on it, as tests/cycle.rs's
    // rigid loop): this checks the fit where the removal follows the planned force. On the
    // documented arm the arm gives way under the contact and the fit reads 0.6 x the cell's
    // Preston k (issue 50's closing note), which is the arm's problem, not the fit's.
    let arm = dir.join("ideal-arm.toml");
    std::fs::write(&arm, "[sim.grinding]\nideal_arm = true\n").unwrap();
    let own = dir.join("own-cell");
    std::fs::create_dir_all(&own).unwrap();
    common::succeed(
        polishbot()
            .args(["calibrate", "compliance", "--sim", "--cell"])
            .arg(common::calib(""))
            .arg("--out")
            .arg(&own)
            .arg("--config")
            .arg(&arm),
    );
    let servos = own.join("servos.toml");
    std::fs::write(
        dir.join("plan.toml"),
        format!("[robot]\nservos = {servos:?}\n"),
    )
    .unwrap();
    let plan = |mode: &str, out: &str| {
        common::succeed(
            polishbot()
                .args(["plan", "--mode", mode, "--inspection", &d("before")])
                .args(["--config", &d("plan.toml"), "-o"])
                .arg(d(out)),
        )
    };
    plan("removal", "plan.json");
    grind_on_the_ideal_arm(&dir, &servos);
    let shipped = std::fs::read_to_string(common::calib("tool.toml")).unwrap();
    std::fs::write(dir.join("tool.toml"), &shipped).unwrap();
    let calibrate = |plan: &str| {
        let mut cmd = polishbot();
        cmd.args(["calibrate", "removal", "--before", &d("before")])
            .args(["--after", &d("after"), "--plan", &d(plan), "--tool"])
            .arg(d("tool.toml"));
        cmd
    };
    let out = common::succeed(&mut calibrate("plan.json"));
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");

    only_k_and_its_sd_rewritten(&shipped, &dir);
    let tool = polishbot::removal::ToolModel::load(&dir.join("tool.toml")).unwrap();
    let k = tool.preston_k_mm2_n;
    // the uncertainty now the fit's (the shipped 30 % is a guess before any grind): the
    // simulator's k varies +-10 % over the part (5.8 % sd) and the model errs by a few percent
    assert!(
        tool.preston_k_rel_sd > 0.0 && tool.preston_k_rel_sd < 0.3,
        "{}",
        tool.preston_k_rel_sd
    );

    // the true k for the planner's model: the scale that best maps the plan's predicted
    // removal onto the simulator's true removal at the same points
    let k_true = common::true_k(
        &dir.join("before"),
        &dir.join("predicted.csv"),
        &dir.join("after_truth.ply"),
        PLAN_K,
    );
    println!(
        "fitted k {k:.4e}, true k {k_true:.4e}, ratio {:.4}; the simulator's Preston k {:.4e}, \
         ratio {:.4}",
        k / k_true,
        PLAN_K * 1.3,
        k / (PLAN_K * 1.3)
    );
    assert!((k / k_true - 1.0).abs() < K_WITHIN, "{k} vs {k_true}");
    assert!(stdout.contains("fit residual RMS"), "{stdout}");

    // run again on the tool file it just wrote: the plan's k comes from the plan, so the same
    // k is written (issue 52: it compounded 5.85e-6, 6.84e-6, 8.00e-6)
    common::succeed(&mut calibrate("plan.json"));
    let again = polishbot::removal::ToolModel::load(&dir.join("tool.toml")).unwrap();
    assert!(
        (again.preston_k_mm2_n / k - 1.0).abs() < 1e-9,
        "{} after {k}",
        again.preston_k_mm2_n
    );
    let written = std::fs::read_to_string(dir.join("tool.toml")).unwrap();

    // a rigid plan has no prediction to fit against: refused in one line, the file untouched
    std::fs::create_dir_all(dir.join("rigid")).unwrap();
    plan("rigid", "rigid/plan.json");
    let out = calibrate("rigid/plan.json").output().unwrap();
    let line = common::one_line_failure(&out);
    assert!(line.contains("no `removal` prediction"), "{line}");
    assert_eq!(
        std::fs::read_to_string(dir.join("tool.toml")).unwrap(),
        written
    );
}

/// `run --sim` of the removal plan in `dir` (plan.json) on synth's scan with the simulator's
/// tool (`common::SIM_TOOL`) on the ideal arm with the cell's servos.toml `servos`, and the
/// ground part (after.ply) inspected into `after`.
fn grind_on_the_ideal_arm(dir: &Path, servos: &Path) {
    let d = |f: &str| dir.join(f).display().to_string();
    std::fs::write(
        dir.join("run.toml"),
        format!(
            "[robot]\nservos = {servos:?}\n[sim.grinding]\n{}ideal_arm = true\n",
            common::SIM_TOOL
        ),
    )
    .unwrap();
    common::succeed(polishbot().args(["run", "--config", &d("run.toml")]).args([
        "--plan",
        &d("plan.json"),
        "--sim",
        "--part",
        &d("scan.ply"),
        "--ground-out",
        &d("after.ply"),
    ]));
    common::inspect_in(dir, "after.ply", "after");
}

/// k and its uncertainty written on their own lines of `dir`'s tool.toml, every other line of
/// the `shipped` file (the comments) kept.
fn only_k_and_its_sd_rewritten(shipped: &str, dir: &Path) {
    let written = std::fs::read_to_string(dir.join("tool.toml")).unwrap();
    let changed: Vec<(&str, &str)> = shipped
        .lines()
        .zip(written.lines())
        .filter(|(a, b)| a != b)
        .collect();
    assert_eq!(shipped.lines().count(), written.lines().count());
    assert_eq!(changed.len(), 2, "{changed:?}");
    assert!(changed[0].1.starts_with("preston_k_mm2_n = "));
    assert!(changed[1].1.starts_with("preston_k_rel_sd = "));
}

//! Removal calibration (`polishbot calibrate removal`, and `cycle` after every grind): Preston's
//! k fitted from what a grind really removed against what its plan predicted.
//!
//! The plan's predicted removal at a core point (predicted.csv: deviation minus predicted
//! residual, summed over the regions whose tool reach holds the point) is linear in k at the
//! planned force and speeds, so the measured removal m (the deviation before minus the
//! deviation after, at the same core point of two inspections against the same reference) is
//! modelled as m = s p with p the predicted removal: least squares through the origin gives
//! s = sum(m p) / sum(p^2) and k = s x the plan's k. Its spread: the standard error
//! sqrt(sum(r^2) / (n - 1) / sum(p^2)) of s, and a k per region. `cycle` pools the points of
//! every grind so far: with u = p / the grind's plan k, m = k u and k = sum(m u) / sum(u^2)
//! over all of them. Method: docs/CALIBRATION.md, "5. Removal".
//!
//! Stages: [`evidence`] collects one grind's points ([`Evidence`]); [`pool`] fits k to the
//! points of one or more grinds under a [`FitConfig`] ([`RemovalFit`]); [`fit`] is both for
//! one grind (`calibrate removal`).
use std::collections::BTreeMap;

use serde::Serialize;

pub use super::matching::{
    agreement, parse_predicted, predicted_removal, repairable_ids, Agreement, GrindPair,
    SAME_POINT_MM,
};

/// Least uncertainty of a fitted k (0.05): the evidence is one part and a handful of regions;
/// a region's own k from 30-150 points scatters by 2-3 % from the rescan noise alone (0.015 mm
/// on removals of about 0.1 mm), so a spread under 5 % cannot be told from that scatter, and
/// the tool's k drifts with wear between grinds.
pub const MIN_K_REL_SD: f64 = 0.05;

/// Settings of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitConfig {
    /// Least predicted removal for a point to count as one the tool ground, mm (0.005: a third
    /// of the rescan noise 0.015 mm; where less is predicted the measured removal is noise and
    /// says nothing about k).
    pub min_predicted_mm: f64,
    /// Fewest points to fit k from (30: with 0.015 mm noise per point and 0.05 mm of removal,
    /// 30 points give k within about 5 %).
    pub min_points: usize,
    /// Largest relative standard error of k accepted (0.25): a looser k would move the next
    /// plan's removal by more than the tolerance on a 0.2 mm defect.
    pub max_relative_error: f64,
    /// Least share of the first inspection's core points found again in the second (0.9):
    /// the reference sample is the same in both (about 99 % of the points); each inspection
    /// adds its own densified points around its defects, which have no partner.
    pub min_matched_share: f64,
    /// Fewest points for a region's own k (10).
    pub min_region_points: usize,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            min_predicted_mm: 0.005,
            min_points: 30,
            max_relative_error: 0.25,
            min_matched_share: 0.9,
            min_region_points: 10,
        }
    }
}

/// One region's own k.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RegionFit {
    /// Region id (of the first inspection).
    pub region: usize,
    /// Points used.
    pub points: usize,
    /// k fitted on them alone, mm^2/N.
    pub k_mm2_n: f64,
}

/// The fitted k and the evidence for it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RemovalFit {
    /// Fitted Preston coefficient, mm^2/N.
    pub k_mm2_n: f64,
    /// The k the plan was made with (the last grind's when pooled), mm^2/N.
    pub plan_k_mm2_n: f64,
    /// Standard error of the fitted k, mm^2/N.
    pub k_std_error_mm2_n: f64,
    /// Per region of the last grind with at least `min_region_points` points.
    pub regions: Vec<RegionFit>,
    /// RMS of measured minus fitted removal over the points used, mm.
    pub residual_rms_mm: f64,
    /// Relative spread of the removal about the fitted k from point to point (the tool's and
    /// the part's local variation and the model's local error): s of [`LocalSpread`].
    pub k_local_rel_sd: f64,
    /// Relative spread of k between regions (`region_spread`): what varies over a region's
    /// extent, which the point-to-point spread can miss under the measurement noise.
    pub k_region_rel_sd: f64,
    /// The measurement noise of one point's removal (two inspections), mm: sigma of
    /// [`LocalSpread`].
    pub noise_mm: f64,
    /// Points used: defect points of repairable regions, measured in both inspections, where
    /// the plan predicted at least `min_predicted_mm` (of every grind pooled).
    pub points: usize,
    /// Grinds whose points were pooled (1 for `calibrate removal`'s single grind).
    pub grinds: usize,
    /// Defect points of the first inspection with no partner in the second (densified
    /// around a defect by one inspection only) and nothing the second measured around them
    /// (`GrindPair::removal_near`), summed over the grinds pooled.
    pub unmatched: usize,
    /// Mean measured removal over the points used, mm.
    pub measured_mean_mm: f64,
    /// Mean predicted removal (at each grind's plan k) over the points used, mm.
    pub predicted_mean_mm: f64,
}

/// One point of a grind's evidence: a defect point of a repairable region, measured in both
/// inspections, where the plan predicted at least `min_predicted_mm`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EvidencePoint {
    /// Region id (of the inspection before the grind).
    pub region: i64,
    /// Removal the plan predicted at its k, mm.
    pub predicted_mm: f64,
    /// Removal measured (deviation before minus after), mm.
    pub measured_mm: f64,
}

/// What one grind says about k: its points and the k its plan was made with. The model is
/// m = k u with u = predicted / plan k (the removal per unit k), so grinds planned at
/// different k pool into one fit ([`pool`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evidence {
    /// The k the grind's plan was made with, mm^2/N.
    pub plan_k_mm2_n: f64,
    /// The points usable for the fit.
    pub points: Vec<EvidencePoint>,
    /// Defect points of the inspection before with no partner in the one after and nothing
    /// it measured around them.
    pub unmatched: usize,
}

impl Evidence {
    /// (u, m) per point: the predicted removal per unit k (mm per mm^2/N) and the measured
    /// removal (mm).
    fn pairs(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.points
            .iter()
            .map(|q| (q.predicted_mm / self.plan_k_mm2_n, q.measured_mm))
    }
}

/// Least squares through the origin of y on x over pairs (x, y).
struct Slope {
    /// sum(x y) / sum(x^2).
    value: f64,
    /// sqrt(sum(r^2) / (n - 1) / sum(x^2)), r = y - value x.
    std_error: f64,
    /// sum(r^2).
    residual_ss: f64,
}

/// The residuals of the fit split into a part that grows with the removal and one that does
/// not: r^2 = s^2 (k u)^2 + sigma^2 over the points, fitted by least squares in (s^2,
/// sigma^2) (moments of the squared residuals), each kept at or above 0 (the other refitted
/// alone then). s is the relative spread of k from point to point; sigma the noise of a
/// measured removal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalSpread {
    /// s, relative (0.1 = 10 %).
    pub relative: f64,
    /// sigma, mm.
    pub noise_mm: f64,
}

/// [`LocalSpread`] of `pairs` (u, m) about m = k u.
pub fn spread(pairs: &[(f64, f64)], k: f64) -> LocalSpread {
    let xy: Vec<(f64, f64)> = pairs
        .iter()
        .map(|(u, m)| ((k * u).powi(2), (m - k * u).powi(2)))
        .collect();
    let n = xy.len().max(1) as f64;
    let (mx, my) = (
        xy.iter().map(|p| p.0).sum::<f64>() / n,
        xy.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = xy.iter().map(|(x, _)| (x - mx).powi(2)).sum();
    let sxy: f64 = xy.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
    let mut a = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let mut b = my - a * mx;
    if b < 0.0 {
        (a, b) = (through_origin(&xy).value, 0.0);
    }
    if a < 0.0 {
        (a, b) = (0.0, my);
    }
    LocalSpread {
        relative: a.max(0.0).sqrt(),
        noise_mm: b.max(0.0).sqrt(),
    }
}

/// The one least-squares fit of this file: `fit`'s k, `pool`'s, and each region's.
fn through_origin(pairs: &[(f64, f64)]) -> Slope {
    let xx: f64 = pairs.iter().map(|(x, _)| x * x).sum();
    let xy: f64 = pairs.iter().map(|(x, y)| x * y).sum();
    let value = xy / xx;
    let residual_ss: f64 = pairs.iter().map(|(x, y)| (y - value * x).powi(2)).sum();
    let std_error = (residual_ss / (pairs.len() as f64 - 1.0) / xx).sqrt();
    Slope {
        value,
        std_error,
        residual_ss,
    }
}

/// Collects the evidence of one grind from its inspections before and after (`pair`: the same
/// reference, the same core points) and `predicted` (per core point of `pair.before`, at the
/// plan's k `plan_k`); refuses with a one-line reason when the points do not match or
/// `pair.before` has no repairable region. Thin evidence is not refused here: [`pool`] judges it.
pub fn evidence(
    pair: &GrindPair,
    predicted: &[f64],
    plan_k: f64,
    cfg: &FitConfig,
) -> Result<Evidence, String> {
    let before = pair.before;
    let repairable = repairable_ids(before);
    let cores = before.points.len();
    let matched = pair.matched() as f64 / cores.max(1) as f64;
    if matched < cfg.min_matched_share {
        return Err(format!(
            "only {:.1} % of the first inspection's {} core points have a core point within \
             {SAME_POINT_MM} mm in the second (need {:.0} %): the two inspections were not made \
             against the same reference with the same core points",
            100.0 * matched,
            cores,
            100.0 * cfg.min_matched_share
        ));
    }
    let (mut defect, mut unmatched) = (0, 0);
    let mut points = Vec::new();
    for (i, p) in before.points.iter().enumerate() {
        if !repairable.contains(&p.region) {
            continue;
        }
        defect += 1;
        let Some(m) = pair.removal_near(i) else {
            unmatched += 1;
            continue;
        };
        if m.is_finite() && predicted[i] >= cfg.min_predicted_mm {
            points.push(EvidencePoint {
                region: p.region,
                predicted_mm: predicted[i],
                measured_mm: m,
            });
        }
    }
    if defect == 0 {
        return Err("the first inspection has no repairable region".into());
    }
    Ok(Evidence {
        plan_k_mm2_n: plan_k,
        points,
        unmatched,
    })
}

/// Fits k from one grind ([`evidence`], then [`pool`] over it alone); refuses with a one-line
/// reason when the points do not match or the evidence is too thin.
pub fn fit(
    pair: &GrindPair,
    predicted: &[f64],
    plan_k: f64,
    cfg: &FitConfig,
) -> Result<RemovalFit, String> {
    pool(&[evidence(pair, predicted, plan_k, cfg)?], cfg)
}

/// Fits one k to the points of all `grinds` pooled: m = k u with u = predicted / the grind's
/// plan k, k = sum(m u) / sum(u^2) over every point, its standard error
/// sqrt(sum(r^2) / (n - 1) / sum(u^2)). A grind too thin to fit alone still adds its points.
/// Refuses with a one-line reason when the pool as a whole has fewer than `min_points`
/// points, a relative standard error above `max_relative_error`, or nothing removed. The
/// fit's plan k, scale and regions are the last grind's (the one the current plan made).
pub fn pool(grinds: &[Evidence], cfg: &FitConfig) -> Result<RemovalFit, String> {
    let pairs: Vec<(f64, f64)> = grinds.iter().flat_map(Evidence::pairs).collect();
    let used = grinds.iter().filter(|g| !g.points.is_empty()).count();
    let over = match used {
        0 | 1 => String::new(),
        n => format!(" (pooled over {n} grinds)"),
    };
    // a standard error needs two points
    let least = cfg.min_points.max(2);
    let Some(last) = grinds.last().filter(|_| pairs.len() >= least) else {
        return Err(format!(
            "{} defect points where the plan predicts at least {} mm of removal and both \
             inspections measured{over}, fewer than {least}: too little evidence to fit k",
            pairs.len(),
            cfg.min_predicted_mm,
        ));
    };
    let k = through_origin(&pairs);
    let (s, se) = (k.value / last.plan_k_mm2_n, k.std_error / last.plan_k_mm2_n);
    if !(s > 0.0 && se / s <= cfg.max_relative_error) {
        return Err(format!(
            "k scale {s:.3} +- {se:.3} of the plan's over {} points{over}: the relative error \
             is above {} (or nothing was removed): too little evidence to fit k",
            pairs.len(),
            cfg.max_relative_error
        ));
    }
    let n = pairs.len() as f64;
    let all = || grinds.iter().flat_map(|g| &g.points);
    let local = spread(&pairs, k.value);
    Ok(RemovalFit {
        k_mm2_n: k.value,
        plan_k_mm2_n: last.plan_k_mm2_n,
        k_std_error_mm2_n: k.std_error,
        regions: region_fits(last, cfg.min_region_points),
        residual_rms_mm: (k.residual_ss / n).sqrt(),
        k_local_rel_sd: local.relative,
        k_region_rel_sd: region_spread(grinds, k.value, cfg.min_region_points),
        noise_mm: local.noise_mm,
        points: pairs.len(),
        grinds: used,
        unmatched: grinds.iter().map(|g| g.unmatched).sum(),
        measured_mean_mm: all().map(|q| q.measured_mm).sum::<f64>() / n,
        predicted_mean_mm: all().map(|q| q.predicted_mm).sum::<f64>() / n,
    })
}

impl RemovalFit {
    /// Relative standard uncertainty of k for the next plan's Monte Carlo: the between-region
    /// spread with the fit's standard error, sqrt(s_region^2 + (se / k)^2), and at least
    /// [`MIN_K_REL_SD`]. The Monte Carlo scales k by one draw for every contact of a region, so
    /// it takes what k may be over a region, not the point-to-point spread
    /// (`k_local_rel_sd`, reported): that spread is where the removal landed beside its
    /// prediction (the landing shift and smear, 0.46-0.59 after a grind of acceptance case 1),
    /// which the Monte Carlo draws as the tip's displacement and the rim guard holds as the
    /// landing margin; taken as a k that moves as one, it drew k from about 0 to 2x and raised
    /// every region's allowance by 2-7 steps on the ideal arm.
    pub fn k_rel_sd(&self) -> f64 {
        self.k_region_rel_sd
            .hypot(self.k_std_error_mm2_n / self.k_mm2_n)
            .max(MIN_K_REL_SD)
    }
}

/// The (u, m) pairs of grind `g` per region with at least `least` points, by region id.
fn by_region(g: &Evidence, least: usize) -> Vec<(i64, Vec<(f64, f64)>)> {
    let mut regions: BTreeMap<i64, Vec<(f64, f64)>> = BTreeMap::new();
    for (uv, q) in g.pairs().zip(&g.points) {
        regions.entry(q.region).or_default().push(uv);
    }
    regions
        .into_iter()
        .filter(|(_, pairs)| pairs.len() >= least)
        .collect()
}

/// k per region of the grind `g` with at least `least` points.
fn region_fits(g: &Evidence, least: usize) -> Vec<RegionFit> {
    by_region(g, least)
        .into_iter()
        .map(|(id, pairs)| RegionFit {
            region: id as usize,
            points: pairs.len(),
            k_mm2_n: through_origin(&pairs).value,
        })
        .collect()
}

/// Spread of k between regions relative to `k`: the regions of every grind with at least
/// `least` points, each fitted alone and weighted by its sum(u^2) (what it knows about k, as
/// in the pooled fit: a region the plan barely ground weighs little); 0 with fewer than two.
fn region_spread(grinds: &[Evidence], k: f64, least: usize) -> f64 {
    let fits: Vec<(f64, f64)> = grinds
        .iter()
        .flat_map(|g| by_region(g, least))
        .map(|(_, pairs)| {
            let w: f64 = pairs.iter().map(|(u, _)| u * u).sum();
            (through_origin(&pairs).value, w)
        })
        .collect();
    let w: f64 = fits.iter().map(|f| f.1).sum();
    match fits.len() {
        0 | 1 => 0.0,
        _ => (fits
            .iter()
            .map(|(kr, wr)| wr * (kr / k - 1.0).powi(2))
            .sum::<f64>()
            / w)
            .sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points m = k u (1 + s z1) + sigma z2 with z1, z2 standard normal: the spread's two
    /// parts come back (5000 points: within 15 %); with one of them 0 the estimate of it
    /// stays under a tenth (s) or half (sigma) of its value in the other cases.
    #[test]
    fn the_spread_splits_into_a_relative_part_and_a_noise_floor() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut normal = move || {
            // Box-Muller
            let (a, b): (f64, f64) = (rng.gen_range(1e-12..1.0), rng.gen_range(0.0..1.0));
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let k = 5e-6;
        let mut draw = |s: f64, sigma: f64| -> Vec<(f64, f64)> {
            (0..5000)
                .map(|i| {
                    let u = (0.01 + 0.3 * (i % 100) as f64 / 100.0) / k;
                    (u, k * u * (1.0 + s * normal()) + sigma * normal())
                })
                .collect()
        };
        let both = spread(&draw(0.15, 0.02), k);
        assert!((both.relative / 0.15 - 1.0).abs() < 0.15, "{both:?}");
        assert!((both.noise_mm / 0.02 - 1.0).abs() < 0.15, "{both:?}");
        let noise = spread(&draw(0.0, 0.02), k);
        assert!(noise.relative < 0.015, "{noise:?}");
        assert!((noise.noise_mm / 0.02 - 1.0).abs() < 0.15, "{noise:?}");
        let relative = spread(&draw(0.15, 0.0), k);
        assert!(
            (relative.relative / 0.15 - 1.0).abs() < 0.15,
            "{relative:?}"
        );
        assert!(relative.noise_mm < 0.01, "{relative:?}");
    }

    /// Two regions of 40 points each, the same removals, k 1.1 and 0.9 x the plan's with no
    /// noise: the pooled k is the plan's, the regions spread by 10 % about it (and so do the
    /// points); one region alone spreads by nothing and the written uncertainty is the floor;
    /// one region whose points scatter by 40 % writes about its k's standard error, not 40 %.
    #[test]
    fn regions_that_remove_at_different_rates_spread_k_and_one_alone_gets_the_floor() {
        let plan_k = 5e-6;
        let region = |id: i64, scale: f64| {
            (0..40).map(move |i| {
                let p = 0.01 + 0.005 * i as f64;
                EvidencePoint {
                    region: id,
                    predicted_mm: p,
                    measured_mm: scale * p,
                }
            })
        };
        let grind = |points: Vec<EvidencePoint>| Evidence {
            plan_k_mm2_n: plan_k,
            points,
            unmatched: 0,
        };
        let cfg = FitConfig::default();
        let two = pool(
            &[grind(region(0, 1.1).chain(region(1, 0.9)).collect())],
            &cfg,
        )
        .unwrap();
        assert!((two.k_mm2_n / plan_k - 1.0).abs() < 1e-12, "{two:?}");
        assert!((two.k_region_rel_sd - 0.1).abs() < 1e-9, "{two:?}");
        assert!(
            two.k_rel_sd() >= 0.1 && two.k_rel_sd() < 0.11,
            "{}",
            two.k_rel_sd()
        );
        let one = pool(&[grind(region(0, 1.1).collect())], &cfg).unwrap();
        assert_eq!(one.k_region_rel_sd, 0.0);
        assert_eq!(one.k_rel_sd(), MIN_K_REL_SD);
        // one region whose points scatter +-40 % about the plan (the removal landed beside
        // its prediction) but whose k is well determined: the Monte Carlo's k stays near it
        let scattered: Vec<EvidencePoint> = region(0, 1.0)
            .enumerate()
            .map(|(i, q)| EvidencePoint {
                measured_mm: q.measured_mm * if i % 2 == 0 { 0.6 } else { 1.4 },
                ..q
            })
            .collect();
        let landed = pool(&[grind(scattered)], &cfg).unwrap();
        assert!(landed.k_local_rel_sd > 0.3, "{landed:?}");
        assert!(landed.k_rel_sd() < 0.15, "{}", landed.k_rel_sd());
    }
}

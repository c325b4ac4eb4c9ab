//! Step 2, similarity and radius (RWME): per core point, the cylinder of the largest
//! candidate radius is gathered once (reference points per ring, point pairs ordered by
//! ring), and the radius grows through the candidates while the RWME similarity of the
//! reference part X and the scan part Y inside it stays at least `similarity`.
//!
//! R(X, Y) = Σ w_i |X_i| / (λ + Σ w_i d(X_i, Y)), w_i = exp(-d(X_i, Y)/h), with X_i a reference
//! point, |X_i| its area share (disc area / count) and d(X_i, Y) = |δ_i| its one-sided distance
//! to the scan ([`super::prepare`]). The similarity s(r) = R / R0 compares with a perfect match
//! at the noise level (every d = d0 = σ sqrt(2/π)).
use anyhow::{ensure, Result};
use nalgebra::{Point3, Vector3};

use super::context::{tangent_frame, Context};
use super::quadric::{FitScratch, Local};
use crate::compare::config::{AdaptiveConfig, CompareConfig};
use crate::compare::cover::{filled, Sectors};
use crate::compare::deviation::{Deviation, Reason};

/// Candidate radii when none are configured: r0 · √2^k for k below this (r0 to 2.83 r0; the
/// largest holds about 8 × the smallest's points).
const DEFAULT_RADII: usize = 4;

/// The sectors' annulus (`cover.rs`) starts at this share of the smallest radius: points
/// nearer the core point say nothing about which side the scan lies on.
const INNER_SHARE: f64 = 0.5;

/// The candidate radii: the configured ones, or r0·√2^k for k = 0..4 with `r0` the radius
/// that holds about 12 scan points.
pub(in crate::compare) fn radii(a: &AdaptiveConfig, r0: f64) -> Result<Vec<f64>> {
    let radii = if a.radii.is_empty() {
        (0..DEFAULT_RADII as i32)
            .map(|k| r0 * 2f64.sqrt().powi(k))
            .collect()
    } else {
        a.radii.clone()
    };
    ensure!(
        !radii.is_empty() && radii.windows(2).all(|w| w[0] < w[1]) && radii[0] > 0.0,
        "adaptive radii must be positive and ascending"
    );
    Ok(radii)
}

/// Per-chunk scratch buffers of a core point's evaluation ([`gather`], [`super::fit::at`],
/// [`super::refine`]).
#[derive(Default)]
pub(super) struct Scratch {
    /// Per candidate radius: the reference points within it.
    pub(super) rings: Vec<Ring>,
    /// Scan points in the cylinder: index of the smallest radius holding them, and the pair.
    pub(super) tagged: Vec<(usize, Local)>,
    /// The same pairs, ordered by that radius: those within radius k are a prefix.
    pub(super) pairs: Vec<Local>,
    /// Pairs within each radius.
    pub(super) within: Vec<usize>,
    /// Next free place of each ring in `pairs` (the counting sort's cursors).
    pub(super) next: Vec<usize>,
    pub(super) fit: FitScratch,
    pub(super) knn: Vec<(f64, u32)>,
    /// Reference points around a core point whose peak is refined.
    pub(super) near: Vec<usize>,
    /// Both clouds' points per sector of the annulus (`cover.rs`).
    pub(super) sectors: Sectors,
}

/// Reference points within a candidate radius ([`gather`] counts each in the ring between
/// the radius below and its own, then adds the rings up).
#[derive(Default, Clone, Copy)]
pub(super) struct Ring {
    /// Points whose normal agrees with the core point's.
    pub(super) count: usize,
    /// Of those, the ones no scan point covers (`cover.rs`).
    pub(super) uncovered: usize,
    /// Of those, the scanned ones (finite δ) and the sums of their RWME terms.
    pub(super) scanned: f64,
    pub(super) sum_w: f64,
    pub(super) sum_wd: f64,
}

/// Similarity s(r) of the reference points counted in `ring` (those within r): the RWME of
/// the module doc, R = Σ w_i |X_i| / (λ + Σ w_i |δ_i|) with |X_i| = π r² / m, over its value
/// at a perfect match (every |δ_i| = d0).
fn similarity(prep: &Context, ring: &Ring, r: f64, h: f64, lambda: f64) -> f64 {
    let m = ring.scanned;
    if m == 0.0 {
        return 0.0;
    }
    let share = std::f64::consts::PI * r * r / m;
    let rwme = ring.sum_w * share / (lambda + ring.sum_wd);
    let d0 = prep.noise * (2.0 / std::f64::consts::PI).sqrt();
    let w0 = (-d0 / h).exp();
    let ideal = m * w0 * share / (lambda + m * w0 * d0);
    rwme / ideal
}

/// Index of the smallest of the squared radii `radii2` (ascending) that holds `rho2`.
#[inline]
fn ring_of(radii2: &[f64], rho2: f64) -> usize {
    // Without branches (the radii ascend, so those below rho are a prefix): the per-core-point
    // loop took 490 ms instead of 570 ms at 100k core points with a loop that stops at the
    // first radius holding rho (mispredicted branches).
    radii2.iter().map(|&r2| usize::from(rho2 > r2)).sum()
}

/// Gathers the cylinder of the largest radius at `p` (normal `n`) into `s`: per radius, the
/// reference points within it (`s.rings`, made cumulative) and the scan point pairs within it
/// (a prefix of `s.pairs` of length `s.within[k]`), in the tangent frame (`e1`, `e2`, `n`).
/// Points whose (nearest reference point's) normal is beyond `max_normal_angle` of `n` are
/// another surface and are left out.
pub(super) fn gather(prep: &Context, p: &Point3<f64>, n: &Vector3<f64>, s: &mut Scratch) {
    let c = prep.clouds;
    let radii2 = &prep.radii2;
    let r_max = *prep.radii.last().expect("radii");
    s.rings.clear();
    s.rings.resize(radii2.len(), Ring::default());
    let rings = &mut s.rings;
    let (e1, e2) = tangent_frame(n);
    // The sectors' annulus starts at half the smallest radius.
    let inner2 = INNER_SHARE * INNER_SHARE * radii2[0];
    let sectors = &mut s.sectors;
    *sectors = Sectors::default();
    let tagged = &mut s.tagged;
    tagged.clear();
    prep.scan_pairs(p, n, r_max, &mut s.knn, |rho2, d, pair| {
        let (u, v) = (d.dot(&e1), d.dot(&e2));
        if rho2 >= inner2 {
            sectors.add(u, v, true);
        }
        tagged.push((ring_of(radii2, rho2), [u, v, pair]));
    });
    // Reference points only matter to the sectors when the scan leaves a run of them empty
    // (`cover.rs`): else no sector is empty, whatever the reference holds.
    let in_doubt = sectors.scan_gap();
    c.ref_grid
        .near_axis(p, n, r_max, prep.half_length, |slot, _, rho2| {
            let x = &prep.ref_slots[slot];
            if x.normal.dot(n) >= prep.cos_limit {
                if in_doubt && rho2 >= inner2 {
                    let d = Vector3::from(*c.ref_grid.slot_point(slot)) - p.coords;
                    sectors.add(d.dot(&e1), d.dot(&e2), false);
                }
                let ring = &mut rings[ring_of(radii2, rho2)];
                ring.count += 1;
                ring.uncovered += usize::from(!x.covered);
                if !x.terms[0].is_nan() {
                    ring.scanned += 1.0;
                    ring.sum_w += x.terms[0];
                    ring.sum_wd += x.terms[1];
                }
            }
        });
    for k in 1..rings.len() {
        let below = rings[k - 1];
        let ring = &mut rings[k];
        ring.count += below.count;
        ring.uncovered += below.uncovered;
        ring.scanned += below.scanned;
        ring.sum_w += below.sum_w;
        ring.sum_wd += below.sum_wd;
    }
    s.within.clear();
    s.within.resize(radii2.len(), 0);
    for &(k, _) in tagged.iter() {
        s.within[k] += 1;
    }
    for k in 1..s.within.len() {
        s.within[k] += s.within[k - 1];
    }
    // Counting sort by ring (stable): ring k's pairs follow those of the smaller radii.
    s.pairs.clear();
    s.pairs.resize(tagged.len(), [0.0; 3]);
    s.next.clear();
    s.next.push(0);
    s.next.extend_from_slice(&s.within);
    for &(k, local) in tagged.iter() {
        s.pairs[s.next[k]] = local;
        s.next[k] += 1;
    }
}

/// The radius [`rwme_radius`] chose for a gathered cylinder.
#[derive(Debug, Clone, Copy)]
pub(super) struct Radius {
    /// Index of the chosen candidate radius.
    pub(super) k: usize,
    /// Candidate radii whose disc the scan fills (a prefix; the fits stay within it).
    pub(super) usable: usize,
}

/// The RWME radius of the cylinder gathered into `s` ([`gather`]): only radii whose disc the
/// scan fills count (`cover.rs`; a disc with fewer than `min_points` reference points cannot
/// be judged), a prefix of the radii; the radius grows through them while every one so far
/// is similar (stays at the smallest when it is not), then further only as far as needed to
/// hold `min_points` of each cloud. Err: the missing result when the scan lies on one side of
/// the core point or fills no disc.
pub(super) fn rwme_radius(
    prep: &Context,
    s: &Scratch,
    cfg: &CompareConfig,
) -> std::result::Result<Radius, Deviation> {
    let a = &cfg.adaptive;
    let (rings, within, radii) = (&s.rings, &s.within, &prep.radii);
    let min = cfg.min_points.max(1);
    // The scan on one side of the core point only (`cover.rs`): no distance.
    let unscanned = match within[0] {
        0 => Reason::FewScan,
        _ => Reason::ScanBorder,
    };
    if s.sectors.one_sided() {
        return Err(Deviation::missing(
            unscanned,
            radii[0],
            rings[0].count,
            within[0],
        ));
    }
    // A disc the scan does not fill is mostly within the next one; none at a scan border.
    let usable = (0..radii.len())
        .take_while(|&j| rings[j].count < min || filled(rings[j].count, rings[j].uncovered))
        .count();
    if usable == 0 {
        return Err(Deviation::missing(
            unscanned,
            radii[0],
            rings[0].count,
            within[0],
        ));
    }
    let radii = &radii[..usable];
    let mut k = 0;
    for (j, &r) in radii.iter().enumerate() {
        if similarity(prep, &rings[j], r, a.h, a.lambda) < a.similarity {
            break;
        }
        k = j;
    }
    while k + 1 < radii.len() && (rings[k].count < min || within[k] < min) {
        k += 1;
    }
    Ok(Radius { k, usable })
}

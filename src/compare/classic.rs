//! Classic M3C2 at one core point (Lague et al. 2013, as py4dgeo 1.2 computes it): distance =
//! mean position of the scan's cylinder points along the normal minus the reference's;
//! LoD95 = 1.96 (sqrt(s1²/n1 + s2²/n2) + reg) with sample standard deviations (n - 1); or
//! ([`Aggregate::Median`]) medians and interquartile ranges in their place, as py4dgeo's
//! `robust_aggr`.
use nalgebra::{Point3, Vector3};

use crate::compare::clouds::Clouds;
use crate::compare::config::{Aggregate, CompareConfig};
use crate::compare::deviation::{Deviation, Reason, Z95};
use crate::spatial::Member;

/// Mean and sample variance (n - 1; NaN below two values, as py4dgeo) of the axial offsets.
fn mean_var(members: &[Member]) -> (f64, f64) {
    let n = members.len() as f64;
    let mean = members.iter().map(|m| m.t).sum::<f64>() / n;
    let ss: f64 = members.iter().map(|m| (m.t - mean) * (m.t - mean)).sum();
    (mean, ss / (n - 1.0))
}

/// Median and interquartile range of the axial offsets, with py4dgeo's quartiles: order
/// statistic ⌊n/4⌋, ⌊n/2⌋ and ⌊3n/4⌋, each averaged with the one below it when n is a multiple
/// of 4 (quartiles) or of 2 (median). Sorts `members` (scratch) by offset.
fn median_iqr(members: &mut [Member]) -> (f64, f64) {
    members.sort_unstable_by(|a, b| a.t.total_cmp(&b.t));
    let n = members.len();
    let at = |pos: usize, average: bool| {
        if average && pos > 0 {
            (members[pos].t + members[pos - 1].t) / 2.0
        } else {
            members[pos].t
        }
    };
    let (q1, q2, q3) = (
        at(n / 4, n.is_multiple_of(4)),
        at(n / 2, n.is_multiple_of(2)),
        at(3 * n / 4, n.is_multiple_of(4)),
    );
    (q2, q3 - q1)
}

/// The classic M3C2 result at core point `p` with outward unit normal `n`; `buf` is scratch.
pub fn at(
    clouds: &Clouds,
    p: &Point3<f64>,
    n: &Vector3<f64>,
    radius: f64,
    cfg: &CompareConfig,
    buf: &mut [Vec<Member>; 2],
) -> Deviation {
    let [ref_in, scan_in] = buf;
    ref_in.clear();
    scan_in.clear();
    clouds
        .ref_grid
        .cylinder(p, n, radius, cfg.max_distance, ref_in);
    clouds
        .scan_grid
        .cylinder(p, n, radius, cfg.max_distance, scan_in);
    let (n1, n2) = (ref_in.len(), scan_in.len());
    let min = cfg.min_points.max(1);
    if n1 < min {
        return Deviation::missing(Reason::FewReference, radius, n1, n2);
    }
    if n2 < min {
        return Deviation::missing(Reason::FewScan, radius, n1, n2);
    }
    let ([m1, m2], [s1, s2]) = match cfg.aggregate {
        Aggregate::Mean => {
            let ((m1, v1), (m2, v2)) = (mean_var(ref_in), mean_var(scan_in));
            ([m1, m2], [v1.sqrt(), v2.sqrt()])
        }
        Aggregate::Median => {
            let ((m1, s1), (m2, s2)) = (median_iqr(ref_in), median_iqr(scan_in));
            ([m1, m2], [s1, s2])
        }
    };
    let lod = Z95 * ((s1 * s1 / n1 as f64 + s2 * s2 / n2 as f64).sqrt() + cfg.registration_error);
    Deviation {
        distance: m2 - m1,
        uncertainty: lod,
        significant: false,
        radius,
        n_ref: n1,
        n_scan: n2,
        direction: Vector3::zeros(),
        spread: [s1, s2],
        peak: f64::NAN,
        peak_fitted: false,
        reason: Reason::Ok,
    }
    .finish(n)
}

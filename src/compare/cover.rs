//! The border tests of the adaptive variant (docs/ACCURACY.md, step 2b).
//!
//! 1. Sides: the annulus from half the smallest radius r0 to the largest radius around the
//!    core point is cut into 8 sectors of 45°; a sector is *empty* when it holds at least
//!    [`SECTOR_MIN_REF`] reference points of the core point's surface but no scan point of it.
//!    [`ONE_SIDED_RUN`] consecutive empty sectors (135°) mean the scan lies on one side of
//!    the core point: no distance ([`super::Reason::ScanBorder`] when the smallest disc holds
//!    scan points, else [`super::Reason::FewScan`], inside a hole). The reference's own
//!    sectors make a face's edge (where the reference ends too) no border.
//! 2. Fill: a reference point is *covered* when one of its 3 nearest scan points lies within
//!    the cover radius g of its normal line (across the normal: a defect lifts the scan off
//!    along it), g = sqrt([`COVER_POINTS`] / (π ρ)) with ρ the scan's median surface density; a
//!    radius is *filled* when at most [`MAX_UNCOVERED`] of the reference points in its disc
//!    are uncovered. The radius is chosen among the filled ones (a prefix of the candidates):
//!    a cylinder does not reach far over a border into a hole.

/// Scan points a cover disc of a full scan holds at the scan's median density (12: the cover
/// radius is r0): a reference point with no scan point within that disc is uncovered. With
/// 6 (g = 0.71 r0) the statistical outlier filter's thinning of the sparsest spots of a
/// uniformly sampled full scan (2.7 % of its points) left 1,691 of 50,381 core points of
/// seed 7 without a filled smallest disc (3.4 % of the area unmeasured on a full scan).
pub(super) const COVER_POINTS: f64 = 12.0;

/// Fewest reference points (of the core point's surface) a sector must hold to count as
/// empty when it holds no scan point: a sector of the reference's own edge is no gap.
pub(super) const SECTOR_MIN_REF: u32 = 2;

/// Consecutive empty sectors (of 8) that make a core point one-sided: 3, i.e. 135°. A full
/// scan puts about 11.6 points into a sector at its median density (the annulus from r0/2 to
/// 2.83 r0 holds 12 × 7.75 of them), so a sector is empty with probability e^-11.6 (e^-5.8
/// at half the median density) and three in a row never happen; a straight border through
/// the core point empties at least three (any 180° holds three whole sectors), one at
/// 0.1 r0 inside the data still two or three.
pub(super) const ONE_SIDED_RUN: usize = 3;

/// Largest share of a disc's reference points that may be uncovered for the disc to count
/// as filled. A straight scan border at distance e from the core point (e > 0: the core point
/// is inside the data) leaves uncovered the segment beyond e + g; it holds 20 % of a disc of
/// radius r when e + g = 0.4 r: with g = r0, the largest radius (2.83 r0) is refused for a
/// core point within 0.13 r0 of the border, 2 r0 for one outside it. Full scans: a disc of
/// about 16 reference points with four uncovered does not happen (each is uncovered with
/// probability e^-12).
pub(super) const MAX_UNCOVERED: f64 = 0.2;

/// Reference and scan points of the core point's surface per 45° sector of the annulus
/// between r0/2 and the largest radius (see the module doc).
#[derive(Default, Clone, Copy)]
pub(super) struct Sectors {
    reference: [u32; 8],
    scan: [u32; 8],
}

impl Sectors {
    /// Counts a reference point (`scan` false) or a scan point at tangent-frame offset
    /// (`u`, `v`) from the core point.
    #[inline]
    pub(super) fn add(&mut self, u: f64, v: f64, scan: bool) {
        let k = octant(u, v);
        match scan {
            true => self.scan[k] += 1,
            false => self.reference[k] += 1,
        }
    }

    /// Whether [`ONE_SIDED_RUN`] consecutive sectors (circularly) are empty.
    pub(super) fn one_sided(&self) -> bool {
        let empty = |k: usize| self.reference[k % 8] >= SECTOR_MIN_REF && self.scan[k % 8] == 0;
        let mut run = 0;
        // Twice round: a run may wrap past sector 7.
        for k in 0..16 {
            run = if empty(k) { run + 1 } else { 0 };
            if run >= ONE_SIDED_RUN {
                return true;
            }
        }
        false
    }
}

/// The 45° sector (0..8, counter-clockwise from +u) of the direction (`u`, `v`), without
/// trigonometry.
#[inline]
fn octant(u: f64, v: f64) -> usize {
    let (base, u, v) = if v < 0.0 { (4, -u, -v) } else { (0, u, v) };
    base + match (u > 0.0, u.abs() > v) {
        (true, true) => 0,
        (true, false) => 1,
        (false, false) => 2,
        (false, true) => 3,
    }
}

/// The cover radius g² (squared, mm²) of a scan of median surface density `density`
/// (points per mm²).
pub(super) fn cover_radius2(density: f64) -> f64 {
    COVER_POINTS / (std::f64::consts::PI * density)
}

/// Whether a disc holding `count` reference points of the core point's surface, `uncovered`
/// of them without a scan point within the cover radius, is filled by the scan.
#[inline]
pub(super) fn filled(count: usize, uncovered: usize) -> bool {
    uncovered as f64 <= MAX_UNCOVERED * count as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octants_go_round_and_a_half_disc_is_one_sided() {
        let dirs: Vec<usize> = (0..8)
            .map(|k| {
                let a = (k as f64 + 0.5) * std::f64::consts::FRAC_PI_4;
                octant(a.cos(), a.sin())
            })
            .collect();
        assert_eq!(dirs, (0..8).collect::<Vec<usize>>());
        let ring = |keep: &dyn Fn(f64) -> bool| {
            let mut s = Sectors::default();
            for k in 0..360 {
                let a = (k as f64).to_radians();
                s.add(a.cos(), a.sin(), false);
                if keep(a) {
                    s.add(a.cos(), a.sin(), true);
                }
            }
            s
        };
        assert!(!ring(&|_| true).one_sided());
        // Scan on one side of a line through the core point (wrapping past sector 7 too).
        assert!(ring(&|a| a.sin() > 0.0).one_sided());
        assert!(ring(&|a| a.cos() > 0.0).one_sided());
        // A 90° gap is not one-sided.
        assert!(!ring(&|a| !(0.1..1.6).contains(&a)).one_sided());
    }

    #[test]
    fn a_half_disc_is_not_filled_a_full_one_is() {
        assert!(filled(100, 0) && filled(100, 20) && filled(0, 0));
        assert!(!filled(100, 21) && !filled(16, 4));
        // g holds COVER_POINTS points at the density: π g² ρ = COVER_POINTS.
        let g2 = cover_radius2(4.0);
        assert!((std::f64::consts::PI * g2 * 4.0 - COVER_POINTS).abs() < 1e-12);
    }
}

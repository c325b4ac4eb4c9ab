//! Putative correspondences: nearest neighbour in FPFH space (an exact brute-force scan,
//! [`super::feature_search`]), optionally mutual, capped to the pairs of smallest feature
//! distance.
use super::feature_search::PackedFeatures;
use super::fpfh::Fpfh;

/// A putative match between a scan point and a reference point (indices into the
/// down-sampled clouds the features were computed on).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correspondence {
    /// Index of the scan point.
    pub scan: usize,
    /// Index of the reference point.
    pub reference: usize,
    /// Euclidean distance between the two descriptors.
    pub feature_distance: f64,
}

/// Fewest mutual matches accepted before falling back to one-way (scan to reference) matches.
const MIN_MUTUAL: usize = 100;

/// For each query descriptor, the index of the nearest descriptor in `into` (not empty) and
/// the distance.
fn nearest_all(query: &[Fpfh], into: &[Fpfh]) -> Vec<(usize, f64)> {
    PackedFeatures::new(into)
        .nearest_all(query)
        .into_iter()
        .flatten()
        .collect()
}

/// Matches scan features to reference features. With `mutual`, a pair is kept only when each
/// is the other's nearest neighbour (falling back to one-way matches when fewer than 100 pairs
/// survive). At most `max` pairs are returned, smallest feature distance first.
pub fn match_features(
    scan: &[Fpfh],
    reference: &[Fpfh],
    mutual: bool,
    max: usize,
) -> Vec<Correspondence> {
    if scan.is_empty() || reference.is_empty() {
        return Vec::new();
    }
    let forward = nearest_all(scan, reference);
    let all: Vec<Correspondence> = forward
        .iter()
        .enumerate()
        .map(|(s, &(r, d))| Correspondence {
            scan: s,
            reference: r,
            feature_distance: d,
        })
        .collect();
    let mut chosen = if mutual {
        // Only the reference descriptors some scan descriptor chose need their own nearest
        // neighbour (a few thousand of tens of thousands): the same answer as querying all.
        let mut chosen_refs: Vec<usize> = all.iter().map(|c| c.reference).collect();
        chosen_refs.sort_unstable();
        chosen_refs.dedup();
        let queries: Vec<Fpfh> = chosen_refs.iter().map(|&r| reference[r]).collect();
        let mut backward = vec![usize::MAX; reference.len()];
        for (&r, &(s, _)) in chosen_refs.iter().zip(&nearest_all(&queries, scan)) {
            backward[r] = s;
        }
        let kept: Vec<Correspondence> = all
            .iter()
            .filter(|c| backward[c.reference] == c.scan)
            .copied()
            .collect();
        if kept.len() >= MIN_MUTUAL.min(all.len()) {
            kept
        } else {
            all
        }
    } else {
        all
    };
    chosen.sort_by(|a, b| a.feature_distance.total_cmp(&b.feature_distance));
    chosen.truncate(max);
    chosen
}

#[cfg(test)]
mod tests {
    use super::super::fpfh::FPFH_BINS;
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn matches_equal_brute_force_and_are_mutual() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut f = || {
            let mut h = [0.0; FPFH_BINS];
            h.iter_mut().for_each(|v| *v = rng.gen_range(0.0..100.0));
            h
        };
        let a: Vec<Fpfh> = (0..300).map(|_| f()).collect();
        let b: Vec<Fpfh> = (0..400).map(|_| f()).collect();
        let dist =
            |x: &Fpfh, y: &Fpfh| x.iter().zip(y).map(|(p, q)| (p - q) * (p - q)).sum::<f64>();
        let brute = |q: &Fpfh, set: &[Fpfh]| {
            (0..set.len())
                .min_by(|&i, &j| dist(q, &set[i]).total_cmp(&dist(q, &set[j])))
                .unwrap()
        };
        let one_way = match_features(&a, &b, false, usize::MAX);
        assert_eq!(one_way.len(), a.len());
        for c in &one_way {
            assert_eq!(c.reference, brute(&a[c.scan], &b));
        }
        let mutual = match_features(&a, &b, true, usize::MAX);
        for c in &mutual {
            assert_eq!(c.scan, brute(&b[c.reference], &a));
        }
        let capped = match_features(&a, &b, false, 10);
        assert_eq!(capped.len(), 10);
        assert!(capped
            .windows(2)
            .all(|w| w[0].feature_distance <= w[1].feature_distance));
    }
}

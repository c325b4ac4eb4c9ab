//! Visiting order of the regions: nearest neighbour from the start, then 2-opt on the open
//! path until no reversal shortens it.
use nalgebra::Point3;

/// Order of `points` (indices) starting nearest `start`, shortening the open path
/// start -> points: nearest neighbour then 2-opt.
pub fn order(start: &Point3<f64>, points: &[Point3<f64>]) -> Vec<usize> {
    let mut left: Vec<usize> = (0..points.len()).collect();
    let mut route = Vec::with_capacity(points.len());
    let mut at = *start;
    while !left.is_empty() {
        let (k, _) = left
            .iter()
            .enumerate()
            .min_by(|a, b| {
                let da = (points[*a.1] - at).norm();
                let db = (points[*b.1] - at).norm();
                da.total_cmp(&db).then(a.1.cmp(b.1))
            })
            .expect("non-empty");
        let i = left.remove(k);
        at = points[i];
        route.push(i);
    }
    two_opt(start, points, &mut route);
    route
}

/// Length of the open path start -> route.
pub fn length(start: &Point3<f64>, points: &[Point3<f64>], route: &[usize]) -> f64 {
    let mut at = *start;
    let mut sum = 0.0;
    for &i in route {
        sum += (points[i] - at).norm();
        at = points[i];
    }
    sum
}

fn two_opt(start: &Point3<f64>, points: &[Point3<f64>], route: &mut [usize]) {
    let n = route.len();
    let pos = |route: &[usize], k: usize| -> Point3<f64> {
        if k == 0 {
            *start
        } else {
            points[route[k - 1]]
        }
    };
    // positions 0..=n on the path: 0 is the start, k is route[k - 1]
    let mut improved = true;
    while improved {
        improved = false;
        for i in 0..n {
            for j in i + 2..=n {
                // reverse route[i..j]: edges (i, i+1) and (j, j+1) become (i, j) and (i+1, j+1)
                let (a, b, c) = (pos(route, i), pos(route, i + 1), pos(route, j));
                let before = (b - a).norm();
                let after = (c - a).norm();
                let (tail_before, tail_after) = if j < n {
                    let d = pos(route, j + 1);
                    ((d - c).norm(), (d - b).norm())
                } else {
                    (0.0, 0.0)
                };
                if after + tail_after < before + tail_before - 1e-12 {
                    route[i..j].reverse();
                    improved = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_opt_untangles_and_never_lengthens() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..50 {
            let pts: Vec<Point3<f64>> = (0..12)
                .map(|_| Point3::new(rng.gen_range(0.0..50.0), rng.gen_range(0.0..50.0), 0.0))
                .collect();
            let start = Point3::origin();
            let r = order(&start, &pts);
            let mut sorted = r.clone();
            sorted.sort();
            assert_eq!(sorted, (0..12).collect::<Vec<_>>());
            // no single reversal shortens the result
            let l = length(&start, &pts, &r);
            for i in 0..12 {
                for j in i + 1..=12 {
                    let mut t = r.clone();
                    t[i..j].reverse();
                    assert!(length(&start, &pts, &t) >= l - 1e-9);
                }
            }
        }
    }
}

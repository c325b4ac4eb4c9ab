//! The dwell solve: `min |A t - r|^2 + lambda |t|^2` subject to `t_min <= t <= t_max`, a
//! bounded least-squares problem handed to Clarabel (an interior-point QP/conic solver) as
//! `min 1/2 t^T (A^T A + lambda I) t - (A^T r)^T t` with the bounds as a nonnegative cone, and
//! optionally linear inequalities `g^T t <= h` (removal budgets, `guard`) as more rows of it.
use std::collections::BTreeMap;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT::NonnegativeConeT,
};

use super::influence::InfluenceColumns;

/// Clarabel's iteration cap: its interior-point method converges in 10-40 iterations on these
/// problems; 200 is its own default.
const MAX_ITER: u32 = 200;

/// Dwell times, s, one per column of `a` (A by columns over `n` core points), minimising
/// `|A t - target|^2 + lambda_rel x mean(diag A^T A) x |t|^2` within `lower..=upper`.
/// `Err` says why the solver failed.
pub fn solve(
    a: &InfluenceColumns,
    n: usize,
    target: &[f64],
    lower: &[f64],
    upper: &[f64],
    lambda_rel: f64,
) -> Result<Vec<f64>, String> {
    solve_within(a, n, target, (lower, upper), lambda_rel, &[])
}

/// [`solve`] with every one of `cuts` held too: `sum g_k t_k <= h` for each `(g, h)`, `g` the
/// (column, coefficient) pairs, at most one per column.
pub fn solve_within(
    a: &InfluenceColumns,
    n: usize,
    target: &[f64],
    (lower, upper): (&[f64], &[f64]),
    lambda_rel: f64,
    cuts: &[(Vec<(usize, f64)>, f64)],
) -> Result<Vec<f64>, String> {
    let m = a.len();
    if m == 0 {
        return Ok(Vec::new());
    }
    // rows of A: for each core point, the (column, value) pairs reaching it
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for (i, col) in a.iter().enumerate() {
        for &(j, v) in col {
            rows[j].push((i, v));
        }
    }
    // upper triangle of A^T A by columns, and A^T r
    let mut upper_tri: Vec<BTreeMap<usize, f64>> = vec![BTreeMap::new(); m];
    let mut q = vec![0.0; m];
    for (row, r) in rows.iter().zip(target) {
        for &(i, vi) in row {
            q[i] -= vi * r;
            for &(k, vk) in row {
                if i <= k {
                    *upper_tri[k].entry(i).or_insert(0.0) += vi * vk;
                }
            }
        }
    }
    let diag_mean = (0..m)
        .map(|i| upper_tri[i].get(&i).copied().unwrap_or(0.0))
        .sum::<f64>()
        / m as f64;
    let lambda = lambda_rel * diag_mean.max(f64::MIN_POSITIVE);
    for (i, col) in upper_tri.iter_mut().enumerate() {
        *col.entry(i).or_insert(0.0) += lambda;
    }
    let p = csc(m, upper_tri.into_iter().map(|c| c.into_iter().collect()));
    // t <= upper: I t + s = upper; t >= lower: -I t + s = -lower; g^T t + s = h; s >= 0
    let mut columns: Vec<Vec<(usize, f64)>> =
        (0..m).map(|i| vec![(i, 1.0), (m + i, -1.0)]).collect();
    for (k, (g, _)) in cuts.iter().enumerate() {
        for &(i, v) in g {
            columns[i].push((2 * m + k, v));
        }
    }
    let bounds = csc(2 * m + cuts.len(), columns.into_iter());
    let b: Vec<f64> = (upper.iter().copied())
        .chain(lower.iter().map(|l| -l))
        .chain(cuts.iter().map(|(_, h)| *h))
        .collect();
    let settings = DefaultSettings {
        verbose: false,
        max_iter: MAX_ITER,
        ..DefaultSettings::default()
    };
    let cones = [NonnegativeConeT(2 * m + cuts.len())];
    let mut solver = DefaultSolver::new(&p, &q, &bounds, &b, &cones, settings)
        .map_err(|e| format!("dwell problem refused by the solver: {e}"))?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => Ok(solver
            .solution
            .x
            .iter()
            .zip(lower.iter().zip(upper))
            .map(|(t, (lo, hi))| t.clamp(*lo, *hi))
            .collect()),
        s => Err(format!("dwell solve ended {s:?} on {m} contact points")),
    }
}

/// A CSC matrix of `rows` rows from its columns' (row, value) pairs, rows increasing.
fn csc(rows: usize, columns: impl Iterator<Item = Vec<(usize, f64)>>) -> CscMatrix<f64> {
    let (mut colptr, mut rowval, mut nzval) = (vec![0], Vec::new(), Vec::new());
    for col in columns {
        for (r, v) in col {
            rowval.push(r);
            nzval.push(v);
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, colptr.len() - 1, colptr, rowval, nzval)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A diagonal A: the bounded answer is r_i / a_i clamped, which the solver must find.
    #[test]
    fn diagonal_problem_gives_the_clamped_quotients() {
        let a: InfluenceColumns = vec![vec![(0, 2.0)], vec![(1, 0.5)], vec![(2, 1.0)]];
        let r = [1.0, 4.0, -1.0];
        let t = solve(&a, 3, &r, &[0.1; 3], &[5.0; 3], 0.0).unwrap();
        for (got, want) in t.iter().zip([0.5, 5.0, 0.1]) {
            assert!((got - want).abs() < 1e-6, "{t:?}");
        }
    }

    /// Two overlapping columns: the unconstrained normal equations solved by hand.
    #[test]
    fn overlapping_columns_match_the_normal_equations() {
        // A = [[1, 0.5], [0.5, 1]], r = [1, 1]: t = A^-1 r = [2/3, 2/3]
        let a: InfluenceColumns = vec![vec![(0, 1.0), (1, 0.5)], vec![(0, 0.5), (1, 1.0)]];
        let t = solve(&a, 2, &[1.0, 1.0], &[0.0; 2], &[10.0; 2], 0.0).unwrap();
        assert!(t.iter().all(|v| (v - 2.0 / 3.0).abs() < 1e-6), "{t:?}");
    }
}

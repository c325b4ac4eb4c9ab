//! Removal budgets held inside the dwell solve (issue 50): each guarded point may lose at most
//! its budget under every landing scenario of the region's contacts ([`landings`]), a set
//! of linear inequalities `sum_j A_s[i, j] t_j <= budget_i` on the dwell. [`solve`] adds them
//! to the bounded least-squares problem (`dwell::solve_within`) as they are violated (a
//! cutting-plane loop: the landing scenarios, dozens, times the guarded points, 196-312 per
//! region in survey cases 61/101/121, are thousands of rows, of which 29-212 were cut in), so
//! that the solver trades dwell where a budget binds instead
//! of scaling every contact reaching the point down (`cap::hold`, which stays as the final
//! check on the pass ground in order). [`lift_to_hold`] lifts the contacts whose shortest
//! dwell alone breaks a budget, so that the bounded problem is feasible.
use super::dwell;
use super::influence::{Contact, Influence, InfluenceColumns, Reach};
use crate::repair::SurfacePoint;
use nalgebra::Vector3;
use std::cell::RefCell;
use std::collections::BTreeSet;

/// Rings of landing shifts between no shift and a contact's whole landing margin
/// ([`landings`]) per patch radius of margin (1): a shift between two rings a patch radius
/// apart still puts the patch over every point the two rings' patches leave between them,
/// so the worst removal at a guarded point is not missed between them.
const RINGS_PER_PATCH: f64 = 1.0;

/// Fewest directions of a ring of landing shifts (8: every 45 degrees); a wider ring takes
/// one direction per patch radius of its circumference, so that neighbouring shifts' patches
/// overlap. Between two directions the removal at a guarded point can exceed what either
/// predicts: in the test below by 16 % (0.0058 mm against a 0.005 mm budget).
const MIN_DIRECTIONS: usize = 8;

/// The landing shifts a region's removal is held against (issue 50, "no grind takes conform
/// surface below -tol"): per scenario, one shift per contact of `contacts`, mm. Scenario 0
/// is no shift; the others move every contact the same way (a landing error is systematic
/// within a grind: the removal shift the loop measures is one vector per region) by a share
/// of its own `margin` (mm) in one direction of the tangent plane of the contacts' mean
/// normal (projected into each contact's own tangent plane), on rings every
/// [`RINGS_PER_PATCH`] patch radius `patch` (mm) of the largest margin.
pub fn landings(contacts: &[Contact], margin: &[f64], patch: f64) -> Vec<Vec<Vector3<f64>>> {
    let mut out = vec![vec![Vector3::zeros(); contacts.len()]];
    let widest = margin.iter().copied().fold(0.0, f64::max);
    let mean: Vector3<f64> = contacts.iter().map(|c| c.normal).sum();
    let Some(normal) = mean.try_normalize(1e-12) else {
        return out;
    };
    if widest <= 0.0 || patch <= 0.0 {
        return out;
    }
    let (tx, ty) = crate::spatial::tangent_basis(&normal);
    let rings = (widest / (patch / RINGS_PER_PATCH)).ceil().max(1.0) as usize;
    for ring in 1..=rings {
        let share = ring as f64 / rings as f64;
        let around = std::f64::consts::TAU * share * widest / patch;
        let directions = (around.ceil() as usize).max(MIN_DIRECTIONS);
        for k in 0..directions {
            let angle = std::f64::consts::TAU * k as f64 / directions as f64;
            let d = tx * angle.cos() + ty * angle.sin();
            let shifts = contacts
                .iter()
                .zip(margin)
                .map(|(c, m)| (d - c.normal * c.normal.dot(&d)) * (share * m))
                .collect();
            out.push(shifts);
        }
    }
    out
}

/// One inequality's left side: the (contact, removal per second of dwell, mm/s) pairs.
pub type Row = Vec<(usize, f64)>;

/// Cutting-plane rounds of [`solve`] at most (12): each round adds, for every guarded point
/// over its budget, the scenario that takes most there; a landing moves the binding scenario
/// to a neighbouring one as the dwell changes, so a few rounds settle it, and the final check
/// (`cap::hold_landed`) holds what is left when the rounds run out.
const MAX_CUT_ROUNDS: usize = 12;

/// Share of a budget a point's removal may exceed and count as held (1e-3, `cap`'s own: the
/// solver's tolerance on the dwell).
const SLACK: f64 = 1e-3;

/// Budgets over a set of guarded points, each under one or more landing scenarios.
#[derive(Debug, Clone, Default)]
pub struct Guard {
    /// Per guarded point, one [`Row`] per landing scenario that reaches it.
    rows: Vec<Vec<Row>>,
    /// Per guarded point, the removal it may take, mm.
    limit: Vec<f64>,
    /// The (point, scenario) rows [`solve`] found binding so far: the next solve over the
    /// same region (the in-order rounds, the bounded solve after the tool-free one) starts
    /// from them, which spares most of its cutting rounds.
    bound: RefCell<BTreeSet<(usize, usize)>>,
}

impl Guard {
    /// The budgets `limit` (mm, one per point of `guarded`) under every landing of
    /// `contacts` within their `margin` (mm, one per contact: [`landings`]).
    pub fn landed(
        contacts: &[Contact],
        (guarded, limit): (&[SurfacePoint], &[f64]),
        influence: &Influence,
        margin: &[f64],
    ) -> Guard {
        let geometry: Vec<_> = guarded.iter().map(|c| (c.position, c.normal)).collect();
        let reach = Reach::new(&geometry);
        let scenarios = landings(contacts, margin, influence.patch_radius());
        let mut rows: Vec<Vec<Row>> = vec![Vec::new(); guarded.len()];
        for shifts in scenarios {
            let moved: Vec<Contact> = (contacts.iter().zip(&shifts))
                .map(|(c, s)| Contact {
                    offset: c.offset + s,
                    ..*c
                })
                .collect();
            let mut by_point: Vec<Row> = vec![Vec::new(); guarded.len()];
            for (j, col) in reach.matrix(influence, &moved).iter().enumerate() {
                for &(i, v) in col {
                    by_point[i].push((j, v));
                }
            }
            for (all, row) in rows.iter_mut().zip(by_point) {
                if !row.is_empty() {
                    all.push(row);
                }
            }
        }
        Guard {
            rows,
            limit: limit.to_vec(),
            bound: RefCell::default(),
        }
    }

    /// The guarded points' budgets, mm.
    pub fn limit(&self) -> &[f64] {
        &self.limit
    }

    /// A contact reaches a guarded point when it does in any scenario: the union of the
    /// scenarios' columns over `contacts` contacts.
    pub fn columns(&self, contacts: usize) -> InfluenceColumns {
        let mut a: InfluenceColumns = vec![Vec::new(); contacts];
        for (i, rows) in self.rows.iter().enumerate() {
            for &(j, v) in rows.iter().flatten() {
                a[j].push((i, v));
            }
        }
        a
    }

    /// The largest removal over the scenarios at every guarded point of dwell `t` (s, one per
    /// contact), with the scenario it comes from.
    fn worst(&self, t: &[f64]) -> Vec<(f64, usize)> {
        let value = |row: &Row| row.iter().map(|&(j, v)| v * t[j]).sum::<f64>();
        (self.rows.iter())
            .map(|rows| {
                (rows.iter().enumerate())
                    .map(|(s, row)| (value(row), s))
                    .fold((0.0, 0), |a, b| if b.0 > a.0 { b } else { a })
            })
            .collect()
    }

    /// The largest removal over the scenarios at every guarded point of dwell `t`, mm.
    pub fn removal(&self, t: &[f64]) -> Vec<f64> {
        self.worst(t).into_iter().map(|(r, _)| r).collect()
    }

    /// The guarded points over their budget times `room` at dwell `t`, each with the
    /// scenario that takes most there and its excess ratio (removal / budget; infinite at a
    /// zero budget).
    fn over(&self, t: &[f64], room: f64) -> Vec<(usize, usize, f64)> {
        (self.worst(t).into_iter().zip(&self.limit).enumerate())
            .filter(|(_, ((r, _), l))| *r > **l * room + f64::EPSILON)
            .map(|(i, ((r, s), l))| (i, s, if *l > 0.0 { r / l } else { f64::INFINITY }))
            .collect()
    }
}

/// Share of a budget the kept contacts may take at their shortest dwell after
/// [`lift_to_hold`] (1 - [`SLACK`]): strictly inside the budget, so that the bounded solve,
/// which holds each budget itself (not the budget plus the slack), has room above every
/// shortest dwell.
const FLOOR_ROOM: f64 = 1.0 - SLACK;

/// Lifts (`lift`, one flag per contact) the fewest contacts, those the relaxed solve wanted
/// least first (`relaxed / lower`), until every budget of `guard` holds within
/// [`FLOOR_ROOM`] with every kept contact at its shortest dwell `lower` (s): the bounded
/// problem is then feasible. Returns how many it lifted.
pub fn lift_to_hold(guard: &Guard, lift: &mut [bool], lower: &[f64], relaxed: &[f64]) -> usize {
    let floor = |lift: &[bool]| -> Vec<f64> {
        (lift.iter().zip(lower))
            .map(|(l, t)| if *l { 0.0 } else { *t })
            .collect()
    };
    let want = |j: usize| relaxed[j] / lower[j].max(f64::MIN_POSITIVE);
    let mut lifted = 0;
    loop {
        let mut t = floor(lift);
        let mut over = guard.over(&t, FLOOR_ROOM);
        if over.is_empty() {
            return lifted;
        }
        over.sort_by(|a, b| b.2.total_cmp(&a.2));
        for (i, s, _) in over {
            let row = &guard.rows[i][s];
            let mut by_want: Vec<(usize, f64)> =
                row.iter().copied().filter(|&(j, _)| !lift[j]).collect();
            by_want.sort_by(|a, b| want(a.0).total_cmp(&want(b.0)));
            let mut value: f64 = row.iter().map(|&(j, v)| v * t[j]).sum();
            for (j, v) in by_want {
                if value <= guard.limit[i] * FLOOR_ROOM {
                    break;
                }
                value -= v * t[j];
                (lift[j], t[j]) = (true, 0.0);
                lifted += 1;
            }
        }
    }
}

/// How often [`solve`] cut: rounds it took and rows it added.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Cuts {
    /// Solves run (1: the budgets held on the first).
    pub solves: usize,
    /// Inequalities added.
    pub rows: usize,
}

/// `dwell::solve` over the contacts `keep` (their columns `a` over `n` core points, targets,
/// bounds and regularisation as there) with `guard`'s budgets held on the dwell of every
/// contact (0 for those not kept, `all` contacts in all), adding the violated scenarios as
/// inequalities round by round ([`MAX_CUT_ROUNDS`]).
pub fn solve(
    (a, n, target): (&InfluenceColumns, usize, &[f64]),
    (lower, upper, lambda_rel): (&[f64], &[f64], f64),
    (guard, keep, all): (&Guard, &[usize], usize),
) -> Result<(Vec<f64>, Cuts), String> {
    let mut position = vec![None; all];
    for (k, &j) in keep.iter().enumerate() {
        position[j] = Some(k);
    }
    let row = |(i, s): (usize, usize)| -> (Row, f64) {
        let g = (guard.rows[i][s].iter())
            .filter_map(|&(j, v)| position[j].map(|k| (k, v)))
            .collect();
        (g, guard.limit[i])
    };
    let mut taken = guard.bound.borrow().clone();
    let mut cuts: Vec<(Row, f64)> = taken.iter().map(|&key| row(key)).collect();
    let mut count = Cuts::default();
    loop {
        let t = dwell::solve_within(a, n, target, (lower, upper), lambda_rel, &cuts)?;
        count.solves += 1;
        let mut full = vec![0.0; all];
        keep.iter().zip(&t).for_each(|(&j, v)| full[j] = *v);
        let fresh: Vec<(usize, usize)> = (guard.over(&full, 1.0 + SLACK).into_iter())
            .map(|(i, s, _)| (i, s))
            .filter(|key| !taken.contains(key))
            .collect();
        if fresh.is_empty() || count.solves > MAX_CUT_ROUNDS {
            guard.bound.borrow_mut().extend(taken);
            return Ok((t, count));
        }
        for key in fresh {
            taken.insert(key);
            cuts.push(row(key));
            count.rows += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::removal::cap::hold;
    use crate::removal::influence::apply;

    /// Six contacts, each the only one to reach its own core point (removal 1 mm per s), and
    /// one guarded point beside the last: where the contacts land as predicted only the last
    /// one reaches it (1 mm/s), landed off the first five reach it by their skirts (0.05 mm/s
    /// each); it may lose 0.5 mm. At 1 s each (every core point's target) it loses 1.25 mm.
    fn beside() -> (InfluenceColumns, Guard) {
        let a: InfluenceColumns = (0..6).map(|j| vec![(j, 1.0)]).collect();
        let skirts: Row = (0..5).map(|j| (j, 0.05)).collect();
        let guard = Guard {
            rows: vec![vec![vec![(5, 1.0)], [skirts, vec![(5, 1.0)]].concat()]],
            limit: vec![0.5],
            ..Guard::default()
        };
        (a, guard)
    }

    /// The blunt hold (`cap::hold`) divides every contact that reaches the point in any
    /// landing by the worst ratio (2.5): 0.4 s each, 60 % of every core point's target lost.
    /// Held in the solve, the five contacts far from it keep nearly all their dwell and the
    /// last gives up what the budget asks, the budget held on every landing.
    #[test]
    fn the_solve_keeps_the_dwell_far_from_a_guarded_point_the_blunt_hold_scales_down() {
        let (a, guard) = beside();
        let (lower, upper, target) = (vec![0.1; 6], vec![10.0; 6], vec![1.0; 6]);
        let keep: Vec<usize> = (0..6).collect();
        let (free, _) = solve(
            (&a, 6, &target),
            (&lower, &upper, 0.0),
            (&Guard::default(), &keep, 6),
        )
        .unwrap();
        assert!(
            guard.removal(&free)[0] > 1.2,
            "the case must break the budget: {free:?}"
        );
        let (mut blunt, mut lifted) = (free.clone(), vec![false; 6]);
        hold(
            &guard.columns(6),
            (&mut blunt, &mut lifted),
            &lower,
            guard.limit(),
            |t| guard.removal(t),
        );
        let (held, cuts) =
            solve((&a, 6, &target), (&lower, &upper, 0.0), (&guard, &keep, 6)).unwrap();
        assert!(cuts.rows >= 1 && cuts.solves >= 2, "{cuts:?}");
        for t in [&blunt, &held] {
            assert!(guard.removal(t)[0] <= 0.5 * (1.0 + SLACK) + 1e-9, "{t:?}");
        }
        let sum = |t: &[f64]| t.iter().sum::<f64>();
        assert!(sum(&blunt) < 2.5, "{blunt:?}");
        assert!(sum(&held) > 4.5, "{held:?}");
        assert!(held[..5].iter().all(|t| *t > 0.9), "{held:?}");
        // closer to the targets (the objective): 0.56 against 2.16
        let error = |t: &[f64]| {
            apply(&a, t, 6)
                .iter()
                .map(|r| (r - 1.0).powi(2))
                .sum::<f64>()
        };
        assert!(error(&held) < 0.3 * error(&blunt), "{held:?} {blunt:?}");
    }

    /// Six contacts reach a guarded point by 0.3 mm at their shortest dwell (1 s), which may
    /// lose 1 mm: at least three must be lifted, and those the relaxed solve wanted least go
    /// first; a point with no budget lifts every contact that reaches it.
    #[test]
    fn the_contacts_wanted_least_are_lifted_until_the_shortest_dwells_hold_the_budget() {
        let row: Row = (0..6).map(|j| (j, 0.3)).collect();
        let guard = Guard {
            rows: vec![vec![row]],
            limit: vec![1.0],
            ..Guard::default()
        };
        let relaxed = [2.0, 0.2, 3.0, 0.5, 0.1, 4.0];
        let mut lift = vec![false; 6];
        assert_eq!(lift_to_hold(&guard, &mut lift, &[1.0; 6], &relaxed), 3);
        assert_eq!(lift, vec![false, true, false, true, true, false]);
        let none = Guard {
            rows: vec![vec![vec![(1, 0.01), (4, 0.2)]]],
            limit: vec![0.0],
            ..Guard::default()
        };
        let mut lift = vec![false; 6];
        lift_to_hold(&none, &mut lift, &[1.0; 6], &relaxed);
        assert_eq!(lift, vec![false, true, false, false, true, false]);
    }

    /// Two contacts at their shortest dwell (1 s) take 1.0004 mm off a guarded point that may
    /// lose 1 mm: within the slack, yet over the budget the bounded solve holds, which then has
    /// no feasible point (survey case 181's first plan left a whole region out so). Lifted
    /// strictly inside the budget, the solve finds the dwell and holds the budget.
    #[test]
    fn a_budget_filled_within_the_slack_at_the_shortest_dwells_still_lifts_one_contact() {
        // the kept contact's column (contact 1 is the one lifted)
        let a: InfluenceColumns = vec![vec![(0, 1.0)]];
        let guard = Guard {
            rows: vec![vec![vec![(0, 0.5002), (1, 0.5002)]]],
            limit: vec![1.0],
            ..Guard::default()
        };
        let (lower, upper, target) = (vec![1.0; 2], vec![10.0; 2], vec![2.0; 2]);
        let mut lift = vec![false; 2];
        assert_eq!(lift_to_hold(&guard, &mut lift, &lower, &[2.0, 1.0]), 1);
        assert_eq!(lift, vec![false, true]);
        let (t, _) = solve(
            (&a, 2, &target),
            (&lower[..1], &upper[..1], 0.0),
            (&guard, &[0], 2),
        )
        .expect("feasible once a contact is lifted");
        assert!(t[0] >= 1.0 && 0.5002 * t[0] <= 1.0 + SLACK, "{t:?}");
    }
}

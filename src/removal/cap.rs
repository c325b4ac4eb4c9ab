//! A removal cap held on the solved dwell (issue 50, "no plan removes at a point that is not
//! above the tolerance by more than its measurement uncertainty"): the caller's targets are
//! capped (with plan.toml's `[plan.aim] first_pass_share`, a pass takes at most that share of
//! the tolerance off any point), but the dwell solve cannot hold a target below what its shortest
//! dwell removes (`t_min = piece / fastest feed`), and the in-order rounds raise the targets where
//! the pass ground in order removes less than the linear model. So the removal the solved dwell
//! makes can exceed the cap (acceptance seed 21's first plan: 0.061 mm off a peak against the
//! 0.035 mm cap). [`hold`] lowers the dwell of each contact reaching a point over its limit
//! by that point's excess ratio, lifts the tool over a contact already at its shortest dwell,
//! and repeats until no point is over its limit.
use super::guard::Guard;
use super::influence::{self, Contact, Influence, InfluenceColumns, Reach};
use super::tool::ToolModel;
use super::{sequence, RegionRemoval, RemovalConfig};
use crate::repair::SurfacePoint;

/// Rounds of [`hold`] at most (30): each round scales every contact reaching an over-limit
/// point by the worst ratio it reaches (one round settles a linear removal; the in-order
/// removal is milder than linear in the dwell, so a few more rounds converge), and lifts a
/// contact on the second round that finds it at its shortest dwell; a bump ringed by
/// `patch / piece` contacts deep needs about as many rounds to lift its way in.
const MAX_ROUNDS: usize = 30;

/// Share of a point's limit its removal may exceed and still count as held (1e-3: the
/// solver's own tolerance on the dwell; 0.035 um at the first grind's 0.035 mm cap).
const SLACK: f64 = 1e-3;

/// The dwell settled within the limits.
#[derive(Debug, Clone, PartialEq)]
pub struct Held {
    /// Rounds it took (0: the dwell held the limits already).
    pub rounds: usize,
    /// Contacts the tool now lifts over that it ground before.
    pub newly_lifted: usize,
    /// The highest removal-to-limit ratio left (at most 1 + [`SLACK`] unless the rounds ran
    /// out).
    pub worst_ratio: f64,
}

/// Lowers `dwell` (s, one per contact, columns of `a` over the core points) until the removal
/// `removal_of(dwell)` makes at every core point is at most its `limit` (mm): each round, a
/// contact reaching a point over its limit has its dwell divided by the worst ratio
/// (removal / limit) among the points it reaches; one that would fall below its shortest dwell
/// `lower` is set to it, and one already there is lifted (dwell 0, `lifted` set). A point
/// with limit 0 or less takes no removal at all. The removal is the caller's (the linear model
/// or the pass ground in order), so that the cap holds on what the plan predicts.
pub fn hold(
    a: &InfluenceColumns,
    (dwell, lifted): (&mut [f64], &mut [bool]),
    lower: &[f64],
    limit: &[f64],
    removal_of: impl Fn(&[f64]) -> Vec<f64>,
) -> Held {
    let ratio = |removal: &[f64]| -> Vec<f64> {
        removal
            .iter()
            .zip(limit)
            .map(|(r, l)| match (*l > 0.0, *r > 0.0) {
                (true, _) => r / l,
                (false, true) => f64::INFINITY,
                (false, false) => 0.0,
            })
            .collect()
    };
    let mut held = Held {
        rounds: 0,
        newly_lifted: 0,
        worst_ratio: 0.0,
    };
    for round in 0..=MAX_ROUNDS {
        let q = ratio(&removal_of(dwell));
        held.worst_ratio = q.iter().copied().fold(0.0, f64::max);
        if held.worst_ratio <= 1.0 + SLACK || round == MAX_ROUNDS {
            break;
        }
        held.rounds = round + 1;
        for (j, col) in a.iter().enumerate() {
            if lifted[j] || dwell[j] <= 0.0 {
                continue;
            }
            let worst = col
                .iter()
                .filter(|(_, v)| *v > 0.0)
                .map(|&(i, _)| q[i])
                .fold(0.0, f64::max);
            if worst <= 1.0 + SLACK {
                continue;
            }
            let floor = lower[j];
            if dwell[j] <= floor * (1.0 + SLACK) {
                dwell[j] = 0.0;
                lifted[j] = true;
                held.newly_lifted += 1;
            } else {
                dwell[j] = (dwell[j] / worst).max(floor);
            }
        }
    }
    held
}

/// Holds `plan` (a region's solved dwell over `contacts`, `placed` as the raster placed them)
/// within `limit` mm at every one of `cores` on the removal of the pass ground in order
/// (`sequence::in_order`, what the plan predicts), by [`hold`] with the shortest dwell at
/// `solve`'s fastest feed; `plan.removal` becomes the linear model's of the held dwell.
pub fn hold_in_order(
    (placed, contacts): (&[Contact], &[Contact]),
    (cores, limit): (&[SurfacePoint], &[f64]),
    (tool, influence, solve): (&ToolModel, &Influence, &RemovalConfig),
    plan: &mut RegionRemoval,
) -> Held {
    let geometry: Vec<_> = cores.iter().map(|c| (c.position, c.normal)).collect();
    let reach = Reach::new(&geometry);
    let a = reach.matrix(influence, contacts);
    let lower: Vec<f64> = contacts
        .iter()
        .map(|c| c.length / solve.feed_max_mm_s)
        .collect();
    let removal_of = |t: &[f64]| sequence::in_order(placed, t, tool, influence, (cores, &reach));
    let held = hold(
        &a,
        (&mut plan.dwell, &mut plan.lifted),
        &lower,
        limit,
        removal_of,
    );
    plan.removal = influence::apply(&a, &plan.dwell, cores.len());
    held
}

/// Holds `plan` (a region's solved dwell over the pressed `contacts`, `placed` as the raster
/// placed them) so that no `guarded` point loses more than its budget (`guard`, built over
/// them: `guard::Guard::landed`) wherever the removal lands within each contact's landing
/// margin: the removal at a guarded point is the largest over the landing scenarios of the
/// linear model's (every contact's patch moved by the scenario's shift), and of the pass
/// ground in order where it lands as planned; [`hold`] lowers the dwell or lifts the contacts
/// reaching a point over its limit in any scenario. `plan.removal` is left as it was (the
/// caller's core points differ from the guarded ones).
pub fn hold_landed(
    (placed, contacts): (&[Contact], &[Contact]),
    (guarded, guard): (&[SurfacePoint], &Guard),
    (tool, influence, solve): (&ToolModel, &Influence, &RemovalConfig),
    plan: &mut RegionRemoval,
) -> Held {
    let geometry: Vec<_> = guarded.iter().map(|c| (c.position, c.normal)).collect();
    let reach = Reach::new(&geometry);
    let a = guard.columns(contacts.len());
    let lower: Vec<f64> = (contacts.iter())
        .map(|c| c.length / solve.feed_max_mm_s)
        .collect();
    let removal_of = |t: &[f64]| {
        let mut worst = sequence::in_order(placed, t, tool, influence, (guarded, &reach));
        let landed = guard.removal(t);
        worst
            .iter_mut()
            .zip(landed)
            .for_each(|(w, r)| *w = w.max(r));
        worst
    };
    hold(
        &a,
        (&mut plan.dwell, &mut plan.lifted),
        &lower,
        guard.limit(),
        removal_of,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::removal::guard::landings;
    use crate::removal::influence::apply;
    use nalgebra::Vector3;

    /// How far over its budget a guarded point may go when the removal lands between two
    /// directions of a ring (1.25): `guard::landings` spaces them a patch radius apart on the
    /// circumference, so a landing between them puts the patch's edge up to about a quarter
    /// of its radius nearer the point; the test below measured 0.0058 mm against 0.005 mm.
    const BETWEEN_LANDINGS: f64 = 1.25;

    /// Three contacts in a row over three points, each reaching its own point fully and its
    /// neighbours by half (a patch wider than the piece): the middle point takes 0.5 + 1 + 0.5
    /// of the dwell. At the shortest dwell 1 s each it removes 2 mm where the cap is 1 mm; no
    /// dwell within the bounds holds the cap, so the tool must be lifted over contacts.
    fn row() -> InfluenceColumns {
        vec![
            vec![(0, 1.0), (1, 0.5)],
            vec![(0, 0.5), (1, 1.0), (2, 0.5)],
            vec![(1, 0.5), (2, 1.0)],
        ]
    }

    #[test]
    fn a_dwell_at_its_floor_over_the_cap_is_lifted_until_the_cap_holds() {
        let a = row();
        let (mut dwell, mut lifted) = (vec![1.0; 3], vec![false; 3]);
        let before = apply(&a, &dwell, 3);
        assert!(before[1] > 1.0, "the case must break the cap: {before:?}");
        let held = hold(&a, (&mut dwell, &mut lifted), &[1.0; 3], &[1.0; 3], |t| {
            apply(&a, t, 3)
        });
        let after = apply(&a, &dwell, 3);
        assert!(after.iter().all(|r| *r <= 1.0 + 1e-9), "{after:?} {held:?}");
        assert!(held.newly_lifted >= 1, "{held:?}");
        // what is still ground keeps its shortest dwell or is lifted: never below the floor
        assert!(dwell.iter().all(|t| *t == 0.0 || *t >= 1.0), "{dwell:?}");
        assert!(lifted.iter().zip(&dwell).all(|(l, t)| *l == (*t == 0.0)));
    }

    #[test]
    fn a_dwell_above_its_floor_is_scaled_to_the_cap_not_lifted() {
        let a = row();
        let (mut dwell, mut lifted) = (vec![2.0; 3], vec![false; 3]);
        // 2 s each: the middle removes 4 mm, the ends 3 mm; cap 2 mm, floor 0.1 s
        let held = hold(&a, (&mut dwell, &mut lifted), &[0.1; 3], &[2.0; 3], |t| {
            apply(&a, t, 3)
        });
        let after = apply(&a, &dwell, 3);
        assert!(after.iter().all(|r| *r <= 2.0 * (1.0 + SLACK)), "{after:?}");
        assert_eq!(held.newly_lifted, 0);
        // the middle point's ratio is 2: every contact reaching it halves, so it lands on 2
        assert!((after[1] - 2.0).abs() < 1e-9, "{after:?}");
    }

    #[test]
    fn a_dwell_within_the_limits_is_left_alone() {
        let a = row();
        let (mut dwell, mut lifted) = (vec![0.3, 0.2, 0.3], vec![false; 3]);
        let kept = dwell.clone();
        let held = hold(&a, (&mut dwell, &mut lifted), &[0.1; 3], &[1.0; 3], |t| {
            apply(&a, t, 3)
        });
        assert_eq!(held.rounds, 0);
        assert_eq!(dwell, kept);
    }

    #[test]
    fn a_point_with_no_allowance_takes_no_removal() {
        let a = row();
        let (mut dwell, mut lifted) = (vec![0.5; 3], vec![false; 3]);
        hold(
            &a,
            (&mut dwell, &mut lifted),
            &[0.1; 3],
            &[1.0, 1.0, 0.0],
            |t| apply(&a, t, 3),
        );
        // contacts 1 and 2 reach point 2: both lifted; contact 0 still grinds
        assert_eq!(lifted, vec![false, true, true]);
        assert!(apply(&a, &dwell, 3)[2] == 0.0);
    }

    /// A flat part: a bump 0.1 mm high for x < 0.5 mm, conform surface beyond it, and one
    /// conform point at (1.5, 0) already ground to -0.04 mm (LoD95 0.005 mm, tolerance
    /// 0.05 mm: it may lose 0.005 mm). Three contacts over the bump at x = -1, -0.5, 0 with
    /// 5 s each: where the removal lands as predicted their patches (0.6 mm radius, plus a
    /// quarter millimetre of piece) do not reach the point; landed 1 mm toward +x, the last
    /// one grinds it below the tolerance. Held against a 1 mm landing margin, no landing
    /// takes it below its budget, and the bump is still ground where it is predicted.
    #[test]
    fn a_conform_point_beside_the_contacts_keeps_its_budget_wherever_they_land() {
        let tolerance = 0.05;
        let grid = 41;
        let cores: Vec<SurfacePoint> = (0..grid * grid)
            .map(|i| {
                let (x, y) = (0.1 * (i % grid) as f64 - 2.0, 0.1 * (i / grid) as f64 - 2.0);
                let distance = match ((x - 1.5).abs() < 1e-9 && y.abs() < 1e-9, x < 0.5) {
                    (true, _) => -0.04,
                    (false, true) => 0.1,
                    (false, false) => 0.0,
                };
                SurfacePoint {
                    position: nalgebra::Point3::new(x, y, 0.0),
                    normal: Vector3::z(),
                    distance,
                    uncertainty: 0.005,
                    region: if x < 0.5 { 0 } else { -1 },
                }
            })
            .collect();
        let rim = cores
            .iter()
            .position(|c| c.distance == -0.04)
            .expect("the grid holds (1.5, 0)");
        let tool = ToolModel::default();
        let influence = Influence::new(&tool, 3.0);
        let tilt = 20f64.to_radians();
        let contacts: Vec<Contact> = [-1.0, -0.5, 0.0]
            .iter()
            .map(|&x| Contact {
                point: nalgebra::Point3::new(x, 0.0, 0.0),
                normal: Vector3::z(),
                along: Vector3::y(),
                spin: -Vector3::new(tilt.sin(), 0.0, tilt.cos()),
                length: 0.25,
                force_ratio: 1.0,
                offset: Vector3::zeros(),
                depth_mm: tool.preload_mm,
            })
            .collect();
        let geometry: Vec<_> = cores.iter().map(|c| (c.position, c.normal)).collect();
        let reach = Reach::new(&geometry);
        let landed = |c: &Contact, dx: f64| Contact {
            offset: Vector3::new(dx, 0.0, 0.0),
            ..*c
        };
        let removal_at = |dwell: &[f64], dx: f64| {
            let moved: Vec<Contact> = contacts.iter().map(|c| landed(c, dx)).collect();
            apply(&reach.matrix(&influence, &moved), dwell, cores.len())
        };
        let mut plan = RegionRemoval {
            dwell: vec![5.0; 3],
            lifted: vec![false; 3],
            removal: Vec::new(),
            before: cores.iter().map(|c| c.distance).collect(),
        };
        let budget = -0.04 + tolerance - 0.005;
        let (predicted, shifted) = (removal_at(&plan.dwell, 0.0), removal_at(&plan.dwell, 1.0));
        assert!(predicted[rim] == 0.0, "{}", predicted[rim]);
        assert!(
            -0.04 - shifted[rim] < -tolerance,
            "the case must gouge when landed 1 mm off: {}",
            shifted[rim]
        );
        let limit: Vec<f64> = (cores.iter())
            .map(|c| (c.distance + tolerance - c.uncertainty).max(0.0))
            .collect();
        let solve = RemovalConfig::default();
        let model = (&tool, &influence, &solve);
        let guard = Guard::landed(&contacts, (&cores, &limit), &influence, &[1.0; 3]);
        hold_landed((&contacts, &contacts), (&cores, &guard), model, &mut plan);
        // held on every landing of the scenarios...
        let margin = [1.0; 3];
        for shifts in landings(&contacts, &margin, influence.patch_radius()) {
            let moved: Vec<Contact> = (contacts.iter().zip(&shifts))
                .map(|(c, s)| Contact { offset: *s, ..*c })
                .collect();
            let r = apply(&reach.matrix(&influence, &moved), &plan.dwell, cores.len())[rim];
            assert!(
                r <= budget * (1.0 + 2.0 * SLACK),
                "landed {:?}: {r}",
                shifts[0]
            );
        }
        // ...and between them within [`BETWEEN_LANDINGS`] of the budget (a sweep every 5
        // degrees and 0.1 mm; +x itself lies between two directions of the outer ring)
        for step in 0..72 {
            let angle = (5.0 * step as f64).to_radians();
            for r in 1..=10 {
                let d = 0.1 * r as f64 * Vector3::new(angle.cos(), angle.sin(), 0.0);
                let moved: Vec<Contact> = (contacts.iter())
                    .map(|c| Contact { offset: d, ..*c })
                    .collect();
                let got = apply(&reach.matrix(&influence, &moved), &plan.dwell, cores.len());
                assert!(got[rim] <= BETWEEN_LANDINGS * budget, "{d:?}: {}", got[rim]);
            }
        }
        // the contacts away from the point still grind the bump
        let kept = removal_at(&plan.dwell, 0.0);
        let bump = cores
            .iter()
            .position(|c| (c.position.x + 1.0).abs() < 1e-9 && c.position.y.abs() < 1e-9)
            .unwrap();
        assert!(kept[bump] > 0.02, "{:?} {}", plan.dwell, kept[bump]);
    }
}

//! `Scene::sweep`, the check of consecutive samples that carries each body's distance from the
//! part to the next sample and skips the body's search while that bound allows: it skips
//! searches, never an answer.
use nalgebra::{Matrix4, Point3};
use polishbot::plan::collide::{Allow, Body, Scene};
use polishbot::plan::{plan, PlanConfig, SurfacePoint};
use polishbot::robot::Workcell;

use super::{arm, grid, measure, point, to_ref, wedge};
use crate::common::dofbot;

/// The forearm (the link after joint 2, a 20 mm capsule) swept sideways by the base joint in
/// 0.002 rad steps towards a wall of reference points that it ends 0.5 mm inside the 1 mm
/// margin of: its search is skipped while it is far (the carried bound), and the first sample
/// whose brute-force clearance (every point against the segment, no index, the simulator's
/// kinematics) is under the margin is refused, naming the forearm, exactly as a scene
/// answering each sample afresh refuses it.
#[test]
fn a_link_just_inside_the_margin_after_a_stretch_of_skipped_searches_is_caught() {
    let robot = dofbot();
    let wc = Workcell {
        robot_from_reference: Matrix4::identity(),
    };
    let cfg = PlanConfig::rigid().collision;
    let (steps, step) = (300, 0.002);
    let q = |k: usize| vec![k as f64 * step, 0.6, 0.4, 0.3, 0.0];
    let forearm = |k: usize| {
        let (o, _, _) = arm(&q(k), &robot);
        (to_ref(&wc, &o[1]), to_ref(&wc, &o[2]))
    };
    // the wall: across the forearm's last step, 20.5 mm ahead of its axis's middle
    let (a, b) = forearm(steps);
    let (a0, b0) = forearm(steps - 1);
    let mid = Point3::from((a.coords + b.coords) / 2.0);
    let ahead = (mid - Point3::from((a0.coords + b0.coords) / 2.0)).normalize();
    let along = ((b - a) - ahead * (b - a).dot(&ahead)).normalize();
    let across = ahead.cross(&along);
    let centre = mid + ahead * (cfg.link_radius_mm[1] + 0.5);
    let wall: Vec<SurfacePoint> = grid(centre, along, across, 8.0, 8.0, 0.5)
        .into_iter()
        .map(|p| point(p, -ahead, 0.0, -1))
        .collect();
    let scene = Scene::new(&wall, &robot, &wc, &cfg);
    let fresh = Scene::new(&wall, &robot, &wc, &cfg);
    let mut sweep = scene.sweep();
    let mut first_inside = None;
    for k in 0..=steps {
        let skipped = sweep.skipped();
        let got = sweep.check(&robot, &q(k), Allow::Free);
        let want = fresh.check(&robot, &q(k), Allow::Free);
        assert_eq!(format!("{got:?}"), format!("{want:?}"), "sample {k}");
        let clearance = measure(&q(k), &robot, &wc, &wall).arm_clearance;
        if clearance < cfg.margin_mm {
            let hit = got.unwrap_or_else(|| panic!("sample {k}: {clearance:.3} mm passed"));
            if first_inside.is_none() {
                assert_eq!(hit.body, Body::Link(1), "sample {k}: {hit}");
                first_inside = Some((k, skipped, clearance));
            }
        }
    }
    let (k, skipped, clearance) = first_inside.expect("the forearm reaches the wall");
    assert!(
        clearance > 0.0 && k > steps / 2,
        "sample {k}: clearance {clearance:.3} mm (the case must end just inside the margin)"
    );
    assert!(
        skipped > 100,
        "only {skipped} searches skipped before sample {k}"
    );
}

/// Every sample of a plan (the wedge: transits around its nose, approaches, grinding on both
/// faces), in order, under each rule: the sweep answers each exactly as a second scene asked
/// sample by sample without a carried bound, refusals included, and skips searches.
#[test]
fn a_sweep_over_a_plan_answers_every_sample_as_the_plain_check_does() {
    let robot = dofbot();
    let (insp, wc) = wedge();
    let cfg = PlanConfig::rigid();
    let p = plan(&insp, &robot, &wc, &cfg).expect("plan");
    for allow in [Allow::Free, Allow::Contact, Allow::Grind] {
        let scene = Scene::new(&insp.points, &robot, &wc, &cfg.collision);
        let plain = Scene::new(&insp.points, &robot, &wc, &cfg.collision);
        let mut sweep = scene.sweep();
        let (mut clear, mut hits) = (0, 0);
        for (i, s) in p.samples.iter().enumerate() {
            let got = format!("{:?}", sweep.check(&robot, &s.q, allow));
            let want = format!("{:?}", plain.check(&robot, &s.q, allow));
            assert_eq!(got, want, "sample {i}, {allow:?}");
            if want == "None" {
                clear += 1;
            } else {
                hits += 1;
            }
        }
        assert!(clear > 0, "{allow:?}: no sample clear");
        assert!(
            hits > 0 || allow != Allow::Free,
            "{allow:?}: grinding samples touch the part"
        );
        assert!(sweep.skipped() > 0, "{allow:?}: nothing skipped");
    }
}

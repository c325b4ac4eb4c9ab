//! `Scene::sweep`, the check of consecutive samples that carries each body's distance from the
//! part to the next sample and skips the body's search while that bound allows: it skips
//! searches, never an answer.
use nalgebra::{Matrix4, Point3};
use polishbot::motion::collide::{Allow, Body, Scene};
use polishbot::motion::{plan_part, CollisionConfig, Plan, PlanConfig, SurfacePoint};
use polishbot::robot::{Robot, Workcell};

use super::scenes::{grid, point, wedge};
use super::{arm, measure, to_ref};
use crate::common::dofbot;

/// The arm, the part placed in the robot frame as it is (mm to m only) and the rigid plan's
/// collision settings.
fn bare_cell() -> (Robot, Workcell, CollisionConfig) {
    let wc = Workcell {
        robot_from_reference: Matrix4::identity(),
    };
    (dofbot(), wc, PlanConfig::rigid().collision)
}

/// The forearm (the link after joint 2, a 20 mm capsule) swept sideways by the base joint in
/// 0.002 rad steps towards a wall of reference points that it ends 0.5 mm inside the 1 mm
/// margin of: its search is skipped while it is far (the carried bound), and the first sample
/// whose brute-force clearance (every point against the segment, no index, the simulator's
/// kinematics) is under the margin is refused, naming the forearm, exactly as a scene
/// answering each sample afresh refuses it.
#[test]
fn a_link_just_inside_the_margin_after_a_stretch_of_skipped_searches_is_caught() {
    let (robot, wc, cfg) = bare_cell();
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
    let p = plan_part(&insp, &robot, &wc, &cfg).expect("plan");
    for (allow, clear, hits, skipped) in
        sweep_answers_as_plain(&p, &insp.points, &wc, &cfg.collision)
    {
        assert!(clear > 0, "{allow:?}: no sample clear");
        assert!(
            hits > 0 || allow != Allow::Free,
            "{allow:?}: grinding samples touch the part"
        );
        assert!(skipped > 0, "{allow:?}: nothing skipped");
    }
}

/// Every sample of `p`, in order, under each rule, checked by a sweep and by a plain scene
/// (no carried bound, every body searched: the exhaustive check) of `points` placed by `wc`:
/// the answers are the same (refusals with the same body, point and clearance). Per rule:
/// samples clear, samples refused, searches the sweep skipped.
pub(super) fn sweep_answers_as_plain(
    p: &Plan,
    points: &[SurfacePoint],
    wc: &Workcell,
    cfg: &CollisionConfig,
) -> Vec<(Allow, usize, usize, usize)> {
    let robot = dofbot();
    let mut out = Vec::new();
    for allow in [Allow::Free, Allow::Contact, Allow::Grind] {
        let scene = Scene::new(points, &robot, wc, cfg);
        let plain = Scene::new(points, &robot, wc, cfg);
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
        out.push((allow, clear, hits, sweep.skipped()));
    }
    out
}

/// The ball slid 1 mm per sample along a surface it sits 0.05 mm inside (a surface of
/// revolution about the base joint, built from the simulator's kinematics: every sample sees
/// it alike), with one reference point planted where only the middle sample's ball reaches it:
/// for `Contact`, raised 0.15 mm towards the ball (that ball 0.2 mm inside, beyond the 0.1 mm
/// tolerance; the neighbours' balls, 1 mm away, 0.027 mm inside); for `Grind`, 0.25 mm beside
/// the middle ball's nearest point with its normal turned 60 degrees (inside that ball only,
/// 0.04 mm: a second face). Swept from
/// several first samples (the bounds carried for the shank and links start at different
/// samples), the middle sample is refused naming the planted point and the ball, the others
/// pass, and every answer equals the plain check's: the sweep covers every sample, not only
/// the ends of a stretch it found clear.
#[test]
fn a_ball_inside_the_part_between_two_clear_samples_is_caught_by_the_sweep() {
    let (robot, wc, cfg) = bare_cell();
    let r = robot.tool.radius_mm();
    let q = |phi: f64| vec![phi, 0.6, 0.4, 0.3, 0.0];
    // the ball centre and tool axis at base angle phi (reference frame, mm)
    let ball = |phi: f64| {
        let (_, tip, axis) = arm(&q(phi), &robot);
        (to_ref(&wc, &tip), axis)
    };
    let (c0, _) = ball(0.0);
    let per_mm = 1e-4 / (ball(1e-4).0 - c0).norm();
    let (samples, middle) = (13usize, 6usize);
    // columns 0.5 mm apart: the line across the ball's path 0.05 mm inside its front
    let mut pts = Vec::new();
    for j in -8..=(2 * samples as i64 + 8) {
        let phi = j as f64 * 0.5 * per_mm;
        let (c, axis) = ball(phi);
        let along = (ball(phi + 1e-6).0 - c).normalize();
        let across = axis.cross(&along).normalize();
        let foot = c + axis * (r - 0.05);
        pts.extend((-8..=8).map(|i| point(foot + across * (0.5 * i as f64), -axis, 0.0, -1)));
    }
    let (cm, axis_m) = ball(middle as f64 * per_mm);
    let across_m = axis_m
        .cross(&(ball(middle as f64 * per_mm + 1e-6).0 - cm))
        .normalize();
    let turned = -axis_m * 60f64.to_radians().cos() + across_m * 60f64.to_radians().sin();
    let planted = pts.len();
    let mut skipped = 0;
    for (allow, offset, normal) in [
        (Allow::Contact, -axis_m * 0.15, -axis_m),
        (Allow::Grind, across_m * 0.25, turned),
    ] {
        let mut surface = pts.clone();
        surface.push(point(cm + axis_m * (r - 0.05) + offset, normal, 0.0, -1));
        let plain = Scene::new(&surface, &robot, &wc, &cfg);
        for first in 0..4 {
            let scene = Scene::new(&surface, &robot, &wc, &cfg);
            let mut sweep = scene.sweep();
            for k in first..samples {
                let qk = q(k as f64 * per_mm);
                let got = sweep.check(&robot, &qk, allow);
                let want = plain.check(&robot, &qk, allow);
                assert_eq!(
                    format!("{got:?}"),
                    format!("{want:?}"),
                    "{allow:?}, sample {k}"
                );
                if k != middle {
                    assert!(got.is_none(), "{allow:?}, sample {k}: {got:?}");
                    continue;
                }
                let hit = got.unwrap_or_else(|| panic!("{allow:?}: the middle sample passed"));
                assert_eq!(hit.body, Body::Ball, "{hit}");
                assert!(
                    format!("{hit:?}").contains(&format!("point: {planted}")),
                    "{hit:?}"
                );
            }
            skipped += sweep.skipped();
        }
    }
    assert!(skipped > 0, "the sweeps carried no bound");
}

/// A wall 2.4 mm thick (two faces of reference points 0.5 mm apart, normals facing away from
/// each other, the shape of femoral_dm's lateral rim) and the 6 mm ball at centres along its
/// normal: 1 mm off either face the ball is 2 mm into that face (the far face, 3.4 mm behind
/// its plane, is not the inside: the ball's centre is in front of its nearest face), and a
/// centre in the wall's middle is 1.2 mm deep (4.2 mm with the radius).
#[test]
fn a_ball_beside_a_thin_wall_is_measured_from_the_near_face_not_behind_the_far_one() {
    let (robot, wc, cfg) = bare_cell();
    let r = robot.tool.radius_mm();
    let (x, y, z) = (
        nalgebra::Vector3::x(),
        nalgebra::Vector3::y(),
        nalgebra::Vector3::z(),
    );
    let thick = 2.4;
    let face = |at: f64, n: nalgebra::Vector3<f64>| {
        grid(Point3::new(at, 0.0, 0.0), y, z, 10.0, 10.0, 0.5)
            .into_iter()
            .map(move |p| point(p, n, 0.0, -1))
    };
    let pts: Vec<SurfacePoint> = face(0.0, -x).chain(face(thick, x)).collect();
    let scene = Scene::new(&pts, &robot, &wc, &cfg);
    for (cx, want) in [
        (-1.0, 1.0 - r),
        (thick + 1.0, 1.0 - r),
        (thick / 2.0, -thick / 2.0 - r),
    ] {
        let got = scene.ball_clearance(&Point3::new(cx, 0.2, 0.1), -10.0);
        assert!(
            (got - want).abs() < 1e-9,
            "centre x {cx}: {got} (want {want})"
        );
    }
}

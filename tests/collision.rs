//! Collision-free plans (issue 35), checked apart from the planner's own model: forward
//! kinematics from the joint table of shared/DOFBOT.md (the simulator's, not `robot/`), brute
//! force over every reference point (no index, no tangent planes), and the tool and cell from
//! their files.
mod common;
#[path = "collision/heldout.rs"]
mod heldout;
#[path = "collision/scenes.rs"]
mod scenes;
#[path = "collision/sweep.rs"]
mod sweep;
#[path = "collision/synced.rs"]
mod synced;
#[path = "collision/uniform.rs"]
mod uniform;

use nalgebra::{Point3, Vector3};
use polishbot::motion::{
    plan_part, CollisionConfig, Inspection, Plan, PlanConfig, PlanError, SegmentKind, Solid,
    SurfacePoint,
};
use polishbot::robot::{Robot, Workcell};
use polishbot::sim::grind::fk::chain;

use common::{calib, dofbot};
use scenes::{cylinder, slotted_face, wedge};

/// The joint origins (robot frame, m) and the ball centre and tool axis at `q`: the
/// simulator's own chain from the joint table of DOFBOT.md (`sim::grind::fk`, independent of
/// `robot/` and k); the tool tip sits at tool.toml's `tip_offset` in the last frame, its axis
/// along `axis`.
fn arm(q: &[f64], robot: &Robot) -> ([Vector3<f64>; 5], Vector3<f64>, Vector3<f64>) {
    let (origins, t) = chain(&[q[0], q[1], q[2], q[3], q[4]]);
    let tip = t * Point3::from(Vector3::from(robot.tool.tip_offset));
    let axis = t.rotation * Vector3::from(robot.tool.axis);
    (origins, tip.coords, axis)
}

/// A robot-frame point (m) in the reference frame (mm).
fn to_ref(wc: &Workcell, p: &Vector3<f64>) -> Point3<f64> {
    let inv = wc.robot_from_reference.try_inverse().expect("rigid");
    Point3::from(inv.transform_point(&Point3::from(*p)).coords * 1e3)
}

fn segment_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let d = b - a;
    let t = if d.norm_squared() > 0.0 {
        ((p - a).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + d * t)).norm()
}

/// What a safety engineer measures at one sample, brute force over every reference point.
struct Measured {
    /// How far the ball is inside the part, mm (negative: its clearance).
    ball_depth: f64,
    /// The ball touches two faces whose normals are more than 45 degrees apart.
    second_face: bool,
    /// Smallest clearance of the shank and the links from the part, mm.
    arm_clearance: f64,
}

fn measure(q: &[f64], robot: &Robot, wc: &Workcell, points: &[SurfacePoint]) -> Measured {
    measure_shank_from(q, robot, wc, points, 0.0)
}

/// [`measure`] with the shank measured from `shank_from_mm` along the axis from the ball
/// centre: where the ball is pressed into the part on purpose (removal mode's grinding), the
/// stretch of the shank inside the ball is the ball, checked by the ball's own depth.
fn measure_shank_from(
    q: &[f64],
    robot: &Robot,
    wc: &Workcell,
    points: &[SurfacePoint],
    shank_from_mm: f64,
) -> Measured {
    let r = robot.tool.radius_mm();
    let (origins, tip, axis) = arm(q, robot);
    let c = to_ref(wc, &tip);
    let mut nearest = (f64::INFINITY, 0usize);
    for (i, p) in points.iter().enumerate() {
        let d = (c - p.position).norm();
        if d < nearest.0 {
            nearest = (d, i);
        }
    }
    let np = &points[nearest.1];
    let behind = (c - np.position).dot(&np.normal) < 0.0;
    let ball_depth = if behind { r + nearest.0 } else { r - nearest.0 };
    let second_face = points.iter().any(|p| {
        (c - p.position).norm() < r - 1e-3 && p.normal.angle(&np.normal).to_degrees() > 45.0
    });
    let radii = CollisionConfig::default().link_radius_mm;
    let shank_end = tip - axis * robot.tool.shank_length();
    let shank_start = to_ref(wc, &(tip - axis.normalize() * (shank_from_mm * 1e-3)));
    let mut capsules = vec![(
        shank_start,
        to_ref(wc, &shank_end),
        robot.tool.shank_radius() * 1e3,
    )];
    for (k, rad) in radii.iter().enumerate().skip(1) {
        capsules.push((to_ref(wc, &origins[k]), to_ref(wc, &origins[k + 1]), *rad));
    }
    let arm_clearance = capsules
        .iter()
        .flat_map(|(a, b, rad)| {
            points
                .iter()
                .map(move |p| segment_distance(&p.position, a, b) - rad)
        })
        .fold(f64::INFINITY, f64::min);
    Measured {
        ball_depth,
        second_face,
        arm_clearance,
    }
}

/// Kind of every sample (the later segment at a joint).
fn kinds(plan: &Plan) -> Vec<SegmentKind> {
    let mut out = vec![SegmentKind::Transit; plan.samples.len()];
    for s in &plan.segments {
        for k in out.iter_mut().take(s.last_sample + 1).skip(s.first_sample) {
            *k = s.kind;
        }
    }
    out
}

#[test]
fn a_contact_in_a_slot_narrower_than_the_ball_is_left_out_because_the_tool_does_not_fit() {
    let robot = dofbot();
    let wc = Workcell::load(&calib("workcell.toml")).expect("workcell");
    let insp = slotted_face();
    let p = plan_part(&insp, &robot, &wc, &PlanConfig::rigid()).expect("plan");
    let slot: Vec<_> = p
        .reachability
        .unreachable
        .iter()
        .filter(|u| u.region == 0)
        .collect();
    assert!(!slot.is_empty(), "the slot's contacts must be left out");
    assert!(
        slot.iter().all(|u| u.reason.contains("tool does not fit")),
        "{}",
        slot[0].reason
    );
    assert!(
        p.passes.iter().all(|pass| pass.region != 0),
        "nothing ground in the slot"
    );
    assert!(
        p.passes.iter().any(|pass| pass.region == 1),
        "the open bump is still ground"
    );
    let kinds = kinds(&p);
    for (i, s) in p.samples.iter().enumerate() {
        let m = measure(&s.q, &robot, &wc, &insp.points);
        assert!(
            !m.second_face,
            "sample {i} ({:?}): the ball touches a second face",
            kinds[i]
        );
        assert!(
            m.ball_depth <= 0.1,
            "sample {i}: ball {:.3} mm inside",
            m.ball_depth
        );
    }
}

#[test]
fn a_transit_between_the_two_sides_of_a_wedge_goes_around_its_nose_with_the_margin() {
    let robot = dofbot();
    let (insp, wc) = wedge();
    let cfg = PlanConfig::rigid();
    let p = plan_part(&insp, &robot, &wc, &cfg).expect("plan");
    for id in [0, 1] {
        let why: Vec<&String> = p
            .reachability
            .unreachable
            .iter()
            .map(|u| &u.reason)
            .take(3)
            .collect();
        assert!(
            p.passes.iter().any(|pass| pass.region == id),
            "region {id} ground: {why:?}"
        );
    }
    let margin = cfg.collision.margin_mm;
    let kinds = kinds(&p);
    let mut around = false;
    for (i, s) in p.samples.iter().enumerate() {
        let m = measure(&s.q, &robot, &wc, &insp.points);
        let free = kinds[i] == SegmentKind::Transit;
        if free {
            // point sampling (0.5 mm) makes the brute-force distance read up to 0.02 mm long
            assert!(
                -m.ball_depth >= margin - 0.02,
                "sample {i}: ball clearance {:.3}",
                -m.ball_depth
            );
            let tip = to_ref(&wc, &arm(&s.q, &robot).1);
            around |= tip.y < -5.0;
        } else {
            assert!(
                m.ball_depth <= 0.1,
                "sample {i} ({:?}): ball {:.3} mm inside",
                kinds[i],
                m.ball_depth
            );
        }
        assert!(
            m.arm_clearance >= margin - 0.02,
            "sample {i}: arm clearance {:.3}",
            m.arm_clearance
        );
    }
    assert!(around, "the transit passes in front of the nose");
    // the straight way between the two regions' approach points runs through the wedge
    let first = |id: usize| {
        let pass = p
            .passes
            .iter()
            .find(|pass| pass.region == id)
            .expect("pass");
        Point3::from(Vector3::from(pass.points[0].surface_mm))
            + Vector3::from(pass.points[0].normal) * 8.0
    };
    let mid = Point3::from((first(0).coords + first(1).coords) / 2.0);
    assert!(
        mid.y > 0.0,
        "the direct line passes behind the nose ({mid})"
    );
}

#[test]
fn a_turn_of_the_tool_at_a_contact_keeps_the_ball_centre_within_a_tenth_of_a_millimetre() {
    let robot = dofbot();
    let (insp, wc) = cylinder();
    let p = plan_part(&insp, &robot, &wc, &PlanConfig::rigid()).expect("plan");
    let mut turns = 0;
    for seg in p
        .segments
        .iter()
        .filter(|s| s.kind == SegmentKind::Reorient)
    {
        let ends = [seg.first_sample, seg.last_sample].map(|i| arm(&p.samples[i].q, &robot));
        let turned = ends[0].2.angle(&ends[1].2).to_degrees();
        if (ends[0].1 - ends[1].1).norm() * 1e3 > 0.01 || turned < 0.5 {
            continue;
        }
        turns += 1;
        for i in seg.first_sample..=seg.last_sample {
            let tip = arm(&p.samples[i].q, &robot).1;
            let off = (tip - ends[0].1).norm() * 1e3;
            assert!(
                off <= 0.1,
                "sample {i}: ball centre {off:.3} mm from the contact"
            );
        }
    }
    let segs: Vec<(SegmentKind, usize)> = p
        .segments
        .iter()
        .map(|s| (s.kind, s.last_sample - s.first_sample))
        .collect();
    assert!(turns > 0, "the plan turns the tool at a contact: {segs:?}");
    for (i, s) in p.samples.iter().enumerate() {
        let m = measure(&s.q, &robot, &wc, &insp.points);
        assert!(
            m.ball_depth <= 0.1,
            "sample {i}: ball {:.3} mm inside",
            m.ball_depth
        );
    }
}

#[test]
fn a_tall_fixture_in_the_way_of_the_links_keeps_the_arm_out_and_run_refuses_a_plan_made_without_it()
{
    let robot = dofbot();
    let (insp, wc) = cylinder();
    let open = plan_part(&insp, &robot, &wc, &PlanConfig::rigid()).expect("plan");
    assert!(!open.passes.is_empty());
    // a post beside the base, up to 0.4 m: the forearm reaches out over where it stands
    let post = Solid {
        name: "post".into(),
        min: [-0.04, 0.09, 0.0],
        max: [0.04, 0.13, 0.4],
    };
    let mut cfg = PlanConfig::rigid();
    cfg.collision.solids.push(post.clone());
    let blocked = plan_part(&insp, &robot, &wc, &cfg).expect("plan");
    assert!(
        blocked.passes.is_empty(),
        "nothing can be ground past the post"
    );
    let why = &blocked.reachability.unreachable[0].reason;
    assert!(
        why.contains("link after joint") && why.contains("\"post\""),
        "{why}"
    );
    // independent: every sample's links keep the margin from the box (dense steps)
    let lo = Vector3::from(post.min);
    let hi = Vector3::from(post.max);
    for (i, s) in blocked.samples.iter().enumerate() {
        let (origins, _, _) = arm(&s.q, &robot);
        for (k, r) in cfg.collision.link_radius_mm.iter().enumerate().skip(1) {
            let (a, b) = (origins[k], origins[k + 1]);
            let d = (0..=1000)
                .map(|t| {
                    let p = a + (b - a) * (f64::from(t) / 1000.0);
                    let out = Vector3::from_fn(|j, _| (lo[j] - p[j]).max(0.0).max(p[j] - hi[j]));
                    out.norm() * 1e3
                })
                .fold(f64::INFINITY, f64::min);
            assert!(
                d - r >= 1.0 - 0.01,
                "sample {i}: link {} {:.2} mm from the post",
                k + 1,
                d - r
            );
        }
    }
    // run's re-check: the plan made without the post is refused once the post is there
    let err = open
        .check_clearance(&insp, &robot, &wc, &cfg.collision)
        .expect_err("refused");
    let msg = err.to_string();
    assert!(matches!(err, PlanError::Collides(_)), "{msg}");
    assert!(
        msg.contains("sample ") && msg.contains("\"post\"") && msg.contains("link after joint"),
        "{msg}"
    );
}

#[test]
fn the_demo_plan_keeps_the_ball_out_of_the_part_except_at_the_contact() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_polishbot"))
        .args(["demo", "--out"])
        .arg(dir.path())
        .output()
        .expect("demo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let robot = dofbot();
    let wc = Workcell::load(&calib("workcell.toml")).expect("workcell");
    let insp = Inspection::load(&dir.path().join("inspection")).expect("inspection");
    let p = Plan::load(&dir.path().join("plan.json")).expect("plan");
    let kinds = kinds(&p);
    let (mut free, mut inside, mut second) = (0, 0, 0);
    for (i, s) in p.samples.iter().enumerate() {
        let m = measure(&s.q, &robot, &wc, &insp.points);
        // removal mode: the ball is pressed into the part while grinding and pressing
        if matches!(kinds[i], SegmentKind::Grind | SegmentKind::Press) {
            second += usize::from(m.second_face);
        } else {
            free += 1;
            inside += usize::from(m.ball_depth > 0.1);
        }
    }
    assert!(free > 0);
    assert_eq!(
        inside, 0,
        "{inside} of {free} free samples with the ball over 0.1 mm inside"
    );
    assert_eq!(second, 0, "{second} grinding samples touch a second face");
    // the planner's fast check (carried bounds) against the exhaustive one, the ball pressed
    // in by the plan's preload as `plan` and `run` check it
    let mut cfg = PlanConfig::default().collision;
    cfg.press_mm = p.removal.as_ref().map_or(0.0, |r| r.preload_mm);
    let mut skips = 0;
    for (allow, clear, hits, skipped) in sweep::sweep_answers_as_plain(&p, &insp.points, &wc, &cfg)
    {
        println!("demo, {allow:?}: {clear} clear, {hits} refused, {skipped} searches skipped");
        assert!(clear > 0, "{allow:?}");
        skips += skipped;
    }
    // the carried bounds answered some searches: on the demo since its defects moved (synth's
    // site filter probes their rims, `cell::reachable_sites`) none under `Free` (2844 clear
    // samples), 288 under `Contact` and 1096 under `Grind`
    assert!(skips > 0, "no search skipped under any rule");
}

/// `Scene::check` remembers the samples it found clear (so `plan`'s final check skips the
/// free-motion samples it checked while building): asked again, in any order of the rules, a
/// scene answers every sample exactly as a fresh scene does, refusals included.
#[test]
fn a_scene_answers_a_sample_it_has_seen_as_a_fresh_scene_does() {
    use polishbot::motion::collide::{Allow, Scene};
    let robot = dofbot();
    let (insp, wc) = wedge();
    let cfg = PlanConfig::rigid();
    let p = plan_part(&insp, &robot, &wc, &cfg).expect("plan");
    let seen = Scene::new(&insp.points, &robot, &wc, &cfg.collision);
    let rules = [Allow::Free, Allow::Contact, Allow::Grind];
    let (mut clear, mut hits) = (0, 0);
    for s in p.samples.iter().step_by(7) {
        // a new scene per sample, asked Contact first: none of its answers is a look-up
        let fresh = Scene::new(&insp.points, &robot, &wc, &cfg.collision);
        let want: Vec<String> = [Allow::Contact, Allow::Grind, Allow::Free]
            .map(|allow| format!("{:?}", fresh.check(&robot, &s.q, allow)))
            .into();
        for round in 0..2 {
            for allow in rules {
                let want = match allow {
                    Allow::Contact => &want[0],
                    Allow::Grind => &want[1],
                    Allow::Free => &want[2],
                };
                let got = format!("{:?}", seen.check(&robot, &s.q, allow));
                assert_eq!(&got, want, "sample at {} s, {allow:?}, round {round}", s.t);
                if round == 0 {
                    if want == "None" {
                        clear += 1;
                    } else {
                        hits += 1;
                    }
                }
            }
        }
    }
    // both answers occur (grinding samples touch the part: clear for Grind, hits for Free)
    assert!(clear > 0 && hits > 0, "clear {clear}, hits {hits}");
}

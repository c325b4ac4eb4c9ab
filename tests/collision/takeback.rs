//! The planner's take-back paths: a piece ground where no retract is clear is taken back with
//! the move onto it and left out with the reason, and what stays in the plan keeps the margin.
use nalgebra::{Point3, Vector3};
use polishbot::plan::{plan, PlanConfig, Solid};
use polishbot::robot::Workcell;

use super::{arm, grid, inspection, point};
use crate::common::{calib, dofbot};

/// Distance from `p` to the box `lo`..`hi` (robot frame, m), mm.
fn box_distance_mm(p: &Vector3<f64>, lo: &Vector3<f64>, hi: &Vector3<f64>) -> f64 {
    Vector3::from_fn(|j, _| (lo[j] - p[j]).max(0.0).max(p[j] - hi[j])).norm() * 1e3
}

/// The default cell's front face (reference y = -35, normal -y) with a round bump 8 mm across.
/// Planned once in the open; then a ledge (a solid 2 mm thick) is put 4.5-6.5 mm above the
/// ball centre at the end of the longest pass, from 3.5 mm beyond that end along the pass: the
/// grinding there keeps the 1 mm margin from it (ball 2.7 mm, shank 1.9 mm), the 5 mm retract
/// along the normal does not (the lifted ball passes it 0.5 mm away), and neither does the
/// straight retract. The plan then leaves that pass out with "no clear retract after it"
/// naming the ball and the ledge, and every sample it keeps has the ball and the shank (the
/// simulator's kinematics, brute force against the box) at least the margin from the ledge.
#[test]
fn a_pass_with_no_clear_retract_is_taken_back_and_left_out_with_the_reason() {
    let robot = dofbot();
    let wc = Workcell::load(&calib("workcell.toml")).expect("workcell");
    let centre = Point3::new(0.0, -35.0, -25.0);
    let face = grid(centre, Vector3::x(), Vector3::z(), 20.0, 20.0, 0.5);
    let pts = face
        .into_iter()
        .map(|p| {
            let bump = (p - centre).norm() <= 4.0;
            let (distance, region) = if bump { (0.2, 0) } else { (0.0, -1) };
            point(p, -Vector3::y(), distance, region)
        })
        .collect();
    let insp = inspection(pts);
    let mut cfg = PlanConfig::rigid();
    let open = plan(&insp, &robot, &wc, &cfg).expect("plan");
    let tip = |p: &polishbot::plan::PlannedPoint| Vector3::from(p.tip_m);
    let pass = open
        .passes
        .iter()
        .max_by(|a, b| {
            let len = |p: &polishbot::plan::PlannedPass| {
                (tip(&p.points[p.points.len() - 1]) - tip(&p.points[0])).norm()
            };
            len(a).total_cmp(&len(b))
        })
        .expect("passes");
    let (first, last) = (&pass.points[0], &pass.points[pass.points.len() - 1]);
    let c = tip(last);
    let up = -Vector3::from(last.axis);
    let along = (c - tip(first)).normalize();
    let across = up.cross(&along);
    let corners: Vec<Vector3<f64>> = [3.5, 10.0]
        .iter()
        .flat_map(|s| [4.5, 6.5].map(|h| (s, h)))
        .flat_map(|(s, h)| [-3.0, 3.0].map(|t| c + (along * *s + up * h + across * t) * 1e-3))
        .collect();
    let lo = corners.iter().fold(corners[0], |m, p| m.inf(p));
    let hi = corners.iter().fold(corners[0], |m, p| m.sup(p));
    cfg.collision.solids.push(Solid {
        name: "ledge".into(),
        min: lo.into(),
        max: hi.into(),
    });
    let p = plan(&insp, &robot, &wc, &cfg).expect("plan");
    let taken_back: Vec<&String> = p
        .reachability
        .unreachable
        .iter()
        .map(|u| &u.reason)
        .filter(|r| r.contains("no clear retract after it"))
        .collect();
    let all: Vec<&String> = p
        .reachability
        .unreachable
        .iter()
        .map(|u| &u.reason)
        .collect();
    assert!(!taken_back.is_empty(), "nothing taken back: {all:?}");
    for why in &taken_back {
        assert!(
            why.contains("retract from")
                && why.contains("solid \"ledge\"")
                && why.contains("straight out"),
            "{why}"
        );
    }
    assert!(!p.passes.is_empty(), "the rest of the bump is ground");
    assert!(
        p.passes.len() < open.passes.len(),
        "{} passes with the ledge, {} without",
        p.passes.len(),
        open.passes.len()
    );
    let (ball, shank) = (robot.tool.radius * 1e3, robot.tool.shank_radius() * 1e3);
    let length = robot.tool.shank_length();
    for (i, s) in p.samples.iter().enumerate() {
        let (_, tip, axis) = arm(&s.q, &robot);
        let b = box_distance_mm(&tip, &lo, &hi) - ball;
        let sh = (0..=200)
            .map(|k| box_distance_mm(&(tip - axis * (length * f64::from(k) / 200.0)), &lo, &hi))
            .fold(f64::INFINITY, f64::min)
            - shank;
        assert!(
            b.min(sh) >= cfg.collision.margin_mm - 0.01,
            "sample {i}: ball {b:.2} mm, shank {sh:.2} mm from the ledge"
        );
    }
}

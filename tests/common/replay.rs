//! A plan's servo commands replayed through the simulator's own mechanics (`sim::grind::slack`:
//! its kinematics, gear flanks and bending, under the arm's weight and the tool's force along
//! each contact's normal), less the offset a workcell calibration without force absorbed (the
//! simulator's rule), against the tips the plan wants: each sample held still
//! ([`tip_errors`]), or in time order with the gears' history ([`replayed`]: issue 50's "each
//! joint on a known flank at every contact"). tests/compensation.rs and tests/flank.rs.
use nalgebra::{Point3, Vector3};
use polishbot::motion::file::CompensationReport;
use polishbot::motion::{Plan, SegmentKind};
use polishbot::robot::{Robot, Workcell};
use polishbot::sim::grind::{fk, slack};
use polishbot::sim::GrindConfig;

/// Spread of the calibration's touch-offs around the part's origin, m (5 mm, the simulator's
/// and the planner's rule: the absorbed offset is the mean gravity-only offset over the poses
/// near the origin, weighted `exp(-((d - d_min) / spread)^2)`, not the offset at the single
/// nearest pose, which jumps between nearly tied poses 0.7 mm apart).
const TOUCH_SPREAD_M: f64 = 0.005;
/// Weight under which a pose is left out of that mean (1e-3, as the simulator's).
const TOUCH_MIN_WEIGHT: f64 = 1e-3;

/// A gear whose history moves the tip more than this, mm, sits on a flank its load does not
/// set (0.05, the tolerance: the model, which puts each gear on its load's flank, is then off
/// by the tolerance).
pub const HISTORY_MOVE_MM: f64 = 0.05;

/// The planner's joint angles as the simulator's (through the servo degrees of servos.toml
/// and DOFBOT.md's convention).
pub fn sim_joints(robot: &Robot, q: &[f64]) -> [f64; 5] {
    std::array::from_fn(|k| {
        let servo = robot.servos.for_joint(&robot.joints[k].name).unwrap();
        fk::joint_of_servo_deg(servo.servo_deg(q[k]))
    })
}

/// The servo commands `plan` sends (its compensated commands, else its samples), as the
/// simulator's joint angles.
pub fn sent(plan: &Plan, robot: &Robot) -> Vec<[f64; 5]> {
    match &plan.commands {
        Some(c) => c.iter().map(|q| sim_joints(robot, q)).collect(),
        None => plan
            .samples
            .iter()
            .map(|s| sim_joints(robot, &s.q))
            .collect(),
    }
}

/// The offset the workcell calibration absorbed (the simulator's rule over the commands
/// `sent`), m, robot frame.
pub fn absorbed(sim: &slack::Arm, sent: &[[f64; 5]], wc: &Workcell) -> Vector3<f64> {
    let tip = sim.tip_m();
    let m = &wc.robot_from_reference;
    let origin = Point3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    let dist: Vec<f64> = sent
        .iter()
        .map(|q| (fk::tool(q, &tip).0 - origin).norm())
        .collect();
    let nearest = dist.iter().copied().fold(f64::INFINITY, f64::min);
    let (mut sum, mut weight) = (Vector3::zeros(), 0.0);
    for (q, d) in sent.iter().zip(&dist) {
        let w = (-((d - nearest) / TOUCH_SPREAD_M).powi(2)).exp();
        if w >= TOUCH_MIN_WEIGHT {
            sum += (sim.held(*q, Vector3::zeros()).0 - fk::tool(q, &tip).0) * w;
            weight += w;
        }
    }
    let absorbed = sum / weight;
    println!(
        "absorbed offset (test's rule, over the sent commands): {:.3?} mm",
        absorbed * 1e3
    );
    absorbed
}

/// Per sample of `plan`: the planned tip (the simulator's kinematics, m) and the contact force
/// (N, robot frame: the tool's force along the part's normal the inspection measured under the
/// pass, `contact_normal`, else the nearest planned contact's outward nominal normal) at
/// grinding samples, None elsewhere.
pub fn planned_contacts(
    plan: &Plan,
    robot: &Robot,
    wc: &Workcell,
    tip: &[f64; 3],
) -> Vec<Option<(Point3<f64>, Vector3<f64>)>> {
    let force = polishbot::removal::ToolModel::of_robot(robot)
        .unwrap()
        .force_n();
    let mut out = vec![None; plan.samples.len()];
    for seg in &plan.segments {
        let (SegmentKind::Grind, Some(pass)) = (seg.kind, seg.pass) else {
            continue;
        };
        let range = seg.first_sample..=seg.last_sample;
        for (o, s) in out[range.clone()].iter_mut().zip(&plan.samples[range]) {
            let planned = fk::tool(&sim_joints(robot, &s.q), tip).0;
            let p = plan.passes[pass]
                .points
                .iter()
                .min_by(|a, b| {
                    let d = |t: &[f64; 3]| (Vector3::from(*t) - planned.coords).norm();
                    d(&a.tip_m).total_cmp(&d(&b.tip_m))
                })
                .unwrap();
            // the part pushes the ball along its own normal: the measured one under the pass's
            // patch where the plan has it, else the nominal
            let normal = plan.passes[pass].contact_normal.unwrap_or(p.normal);
            let nrm = wc
                .direction_from_reference(&Vector3::from(normal))
                .normalize();
            *o = Some((planned, nrm * force));
        }
    }
    out
}

/// Per sample of `plan`, the contact force (N, robot frame) on the presses next to a grinding
/// segment, and whether the press goes in: it builds linearly from 0 to the first grinding
/// sample's force `contacts` gives (press in) or falls from the last one's to 0 (press out),
/// as the compliant tool's spring is compressed along the press; None elsewhere.
pub fn press_forces(
    plan: &Plan,
    contacts: &[Option<(Point3<f64>, Vector3<f64>)>],
) -> Vec<Option<(Vector3<f64>, bool)>> {
    let mut out = vec![None; contacts.len()];
    for pair in plan.segments.windows(2) {
        let (press, grind, inward) = match (pair[0].kind, pair[1].kind) {
            (SegmentKind::Press, SegmentKind::Grind) => (&pair[0], &pair[1], true),
            (SegmentKind::Grind, SegmentKind::Press) => (&pair[1], &pair[0], false),
            _ => continue,
        };
        let at = if inward {
            grind.first_sample
        } else {
            grind.last_sample
        };
        let Some((_, force)) = contacts[at] else {
            continue;
        };
        let span = (press.last_sample - press.first_sample).max(1) as f64;
        for (i, o) in out
            .iter_mut()
            .enumerate()
            .take(press.last_sample + 1)
            .skip(press.first_sample)
        {
            let f = (i - press.first_sample) as f64 / span;
            let share = if inward { f } else { 1.0 - f };
            if contacts[i].is_none() {
                *o = Some((force * share, inward));
            }
        }
    }
    out
}

/// The simulated loaded tip's distance from the planned tip at every grinding sample of
/// `plan` (robot frame, mm), each sample held still on its loaded flanks (no history).
pub fn tip_errors(plan: &Plan, robot: &Robot, wc: &Workcell, arm: &GrindConfig) -> Vec<f64> {
    let sim = slack::Arm::new(arm);
    let sent = sent(plan, robot);
    let absorbed = absorbed(&sim, &sent, wc);
    let contacts = planned_contacts(plan, robot, wc, &sim.tip_m());
    let mut out = Vec::new();
    for (q, c) in sent.iter().zip(&contacts) {
        if let Some((planned, force)) = c {
            let loaded = sim.held(*q, *force).0 - absorbed;
            out.push((loaded - planned).norm() * 1e3);
        }
    }
    out
}

/// `plan` replayed in time order as the simulator runs it: every sample through the simulated
/// arm's mechanics with their history (a joint under the hold torque trails its motion by half
/// its band, or stays where a reversal left it), the contact force on at grinding samples.
pub struct Replayed {
    /// Per grinding sample, the loaded tip's distance from the planned tip, mm.
    pub errors: Vec<f64>,
    /// Per grinding sample, that error's part along the surface (across the normal), mm.
    pub lateral: Vec<f64>,
    /// The mean of the error vectors over the grinding samples (robot frame), mm.
    pub mean: Vector3<f64>,
    /// Per joint and grinding sample, how far the tip moves by that joint's gear sitting where
    /// its history put it instead of where a pose held still puts it, mm.
    pub per_joint: [Vec<f64>; 5],
    /// Per joint and grinding sample, the simulated load torque's size, N m.
    pub torque: [Vec<f64>; 5],
    /// Per joint and press onto a first contact: how far the tip sits from where the load
    /// flank puts it when the press starts (the gear where the approach left it), mm.
    pub press_start: [Vec<f64>; 5],
    /// The contact force summed over the samples of the presses in where some gear's history
    /// moves the tip more than [`HISTORY_MOVE_MM`], over the force summed over every sample in
    /// contact (grinding and presses): the share of the removal (Preston: the removed volume
    /// rate goes with the force) ground off the flank the model assumes.
    pub off_flank_share: f64,
    /// Per joint (1-4), how often its load torque changes sign between two grinding samples
    /// in a row (its gear crosses the band while grinding).
    pub sign_changes: [usize; 4],
}

/// [`Replayed::sign_changes`] of the commands `sent` under the grinding `contacts`.
pub fn sign_changes(
    sent: &[[f64; 5]],
    contacts: &[Option<(Point3<f64>, Vector3<f64>)>],
    tip: &[f64; 3],
) -> [usize; 4] {
    let signs: Vec<Option<[bool; 4]>> = sent
        .iter()
        .zip(contacts)
        .map(|(q, c)| {
            let t = slack::load_torques(q, tip, c.as_ref()?.1);
            Some(std::array::from_fn(|k| t[k] > 0.0))
        })
        .collect();
    std::array::from_fn(|k| {
        signs
            .windows(2)
            .filter(|w| matches!((w[0], w[1]), (Some(a), Some(b)) if a[k] != b[k]))
            .count()
    })
}

/// [`Replayed::press_start`]: per press in (a press before a grinding segment), how far each
/// joint's gear offset `offsets` (output minus command, per sample) at the press's first
/// sample moves the tip from where the first grinding sample's load flank puts it, mm.
pub fn press_starts(
    plan: &Plan,
    sent: &[[f64; 5]],
    contacts: &[Option<(Point3<f64>, Vector3<f64>)>],
    offsets: &[[f64; 5]],
    band: &[f64; 5],
    tip: &[f64; 3],
) -> [Vec<f64>; 5] {
    let mut out: [Vec<f64>; 5] = Default::default();
    for pair in plan.segments.windows(2) {
        let (press, grind) = (&pair[0], &pair[1]);
        if press.kind != SegmentKind::Press || grind.kind != SegmentKind::Grind {
            continue;
        }
        let g = grind.first_sample;
        let Some((_, force)) = contacts[g] else {
            continue;
        };
        let torque = slack::load_torques(&sent[g], tip, force);
        let still = slack::Backlash::new(band).follow(sent[g], torque);
        for (k, per) in out.iter_mut().enumerate() {
            let mut one = still;
            one[k] = sent[g][k] + offsets[press.first_sample][k];
            per.push((fk::tool(&one, tip).0 - fk::tool(&still, tip).0).norm() * 1e3);
        }
    }
    out
}

/// [`Replayed`] of `plan` on the simulated arm `arm`.
pub fn replayed(plan: &Plan, robot: &Robot, wc: &Workcell, arm: &GrindConfig) -> Replayed {
    let mut sim = slack::Arm::new(arm);
    let tip = sim.tip_m();
    let sent = sent(plan, robot);
    let absorbed = absorbed(&sim, &sent, wc);
    let contacts = planned_contacts(plan, robot, wc, &tip);
    let band = if arm.ideal_arm {
        [0.0; 5]
    } else {
        arm.backlash_deg
    };
    let mut gear = slack::Backlash::new(&band);
    let mut out = Replayed {
        errors: Vec::new(),
        mean: Vector3::zeros(),
        lateral: Vec::new(),
        per_joint: Default::default(),
        torque: Default::default(),
        press_start: Default::default(),
        off_flank_share: 0.0,
        sign_changes: [0; 4],
    };
    let presses = press_forces(plan, &contacts);
    let (mut off_flank, mut in_contact) = (0.0, 0.0);
    out.sign_changes = sign_changes(&sent, &contacts, &tip);
    let mut offsets = Vec::with_capacity(sent.len());
    for ((q, c), press) in sent.iter().zip(&contacts).zip(&presses) {
        let force = c.map(|c| c.1).or(press.map(|p| p.0)).unwrap_or_default();
        let loaded = sim.tool(*q, force).0 - absorbed;
        let torque = slack::load_torques(q, &tip, force);
        let trailed = gear.follow(*q, torque);
        offsets.push(std::array::from_fn::<f64, 5, _>(|k| trailed[k] - q[k]));
        in_contact += force.norm();
        let still = slack::Backlash::new(&band).follow(*q, torque);
        let moved = |k: usize| {
            let mut one = still;
            one[k] = trailed[k];
            (fk::tool(&one, &tip).0 - fk::tool(&still, &tip).0).norm() * 1e3
        };
        if press.is_some_and(|p| p.1) && (0..5).any(|k| moved(k) > HISTORY_MOVE_MM) {
            off_flank += force.norm();
        }
        let Some((planned, _)) = c else { continue };
        let err = loaded - planned;
        let normal = force.normalize();
        out.errors.push(err.norm() * 1e3);
        out.mean += err * 1e3;
        out.lateral
            .push((err - normal * err.dot(&normal)).norm() * 1e3);
        for (k, t) in out.torque.iter_mut().enumerate() {
            t.push(torque[k].abs());
        }
        for (k, per) in out.per_joint.iter_mut().enumerate() {
            per.push(moved(k));
        }
    }
    out.off_flank_share = off_flank / in_contact;
    out.mean /= out.errors.len().max(1) as f64;
    out.press_start = press_starts(plan, &sent, &contacts, &offsets, &band, &tip);
    out
}

/// Median, 95th percentile and largest of `x`.
pub fn quantiles(mut x: Vec<f64>) -> [f64; 3] {
    assert!(!x.is_empty(), "no grinding sample");
    x.sort_by(f64::total_cmp);
    let at = |q: f64| x[((x.len() - 1) as f64 * q).round() as usize];
    [at(0.5), at(0.95), x[x.len() - 1]]
}

/// The 95th percentile of the tip error over the grinding samples the plan compensated in
/// full, mm: the plan reports how many it corrected only in part (a joint at its limit:
/// region 1's elbow), and those are the largest errors, so the fully compensated samples' p95
/// is the `0.95 x (1 - partial share)` quantile of all of them. Under the rim guard the plan
/// grinds 1,110 samples where it ground 3,668, the partial ones (72) are 6.5 % of them and the
/// p95 of all (0.762 mm) is one of them (2026-12-06; tests/compensation.rs and tests/flank.rs).
pub fn fully_compensated_p95(errors: &[f64], report: Option<&CompensationReport>) -> f64 {
    let share = report.map_or(0.0, |r| {
        r.partial_samples as f64 / r.grinding_samples as f64
    });
    let mut x = errors.to_vec();
    x.sort_by(f64::total_cmp);
    x[((x.len() - 1) as f64 * 0.95 * (1.0 - share)).round() as usize]
}

/// Prints [`Replayed`] of `plan` on `arm` (and the error of each sample held still) and
/// returns the error along the surface of every grinding sample (mm), the share of grinding
/// samples where some gear's history moves the tip more than [`HISTORY_MOVE_MM`], and the
/// 95th percentile over the presses onto a first contact of how far the base yaw's gear then
/// sits from its load's flank (mm at the tip, [`Replayed::press_start`]; NaN with no press).
pub fn print_replayed(
    plan: &Plan,
    robot: &Robot,
    wc: &Workcell,
    arm: &GrindConfig,
) -> (Vec<f64>, f64, f64) {
    let held = quantiles(tip_errors(plan, robot, wc, arm));
    let r = replayed(plan, robot, wc, arm);
    let yaw_press = match r.press_start[0].is_empty() {
        true => f64::NAN,
        false => quantiles(r.press_start[0].clone())[1],
    };
    for (k, n) in r.sign_changes.iter().enumerate() {
        println!(
            "joint {}: load torque changes sign {n} times while grinding",
            k + 1
        );
    }
    for (k, per) in r.press_start.iter().enumerate() {
        if !per.is_empty() {
            println!(
                "joint {}: at the start of {} presses onto a first contact its gear moves the \
                 tip {:.3?} mm from the load's flank",
                k + 1,
                per.len(),
                quantiles(per.clone())
            );
        }
    }
    println!(
        "share of the contact force over time (grinding and presses) on the presses in with a \
         gear off its load's flank: {:.4}",
        r.off_flank_share
    );
    let moved = (0..r.errors.len())
        .filter(|&i| r.per_joint.iter().any(|p| p[i] > HISTORY_MOVE_MM))
        .count() as f64
        / r.errors.len() as f64;
    println!(
        "share of grinding samples a gear's history moves by over {HISTORY_MOVE_MM} mm: {moved:.4}"
    );
    println!("mean error vector (robot frame): {:.3?} mm", r.mean);
    let total = quantiles(r.errors);
    let lateral = quantiles(r.lateral.clone());
    println!(
        "median / p95 / max, mm: held still {held:.3?}; replayed {total:.3?}, along the \
         surface {lateral:.3?}"
    );
    for (k, (per, t)) in r.per_joint.into_iter().zip(r.torque).enumerate() {
        let under = |x: f64| t.iter().filter(|v| **v < x).count();
        println!(
            "joint {}: tip move by its gear's history {:.3?} mm; |load torque| {:.4?} N m, \
             least {:.4} N m, {} / {} / {} of {} samples under 0.005 / 0.01 / 0.02",
            k + 1,
            quantiles(per),
            quantiles(t.clone()),
            t.iter().copied().fold(f64::INFINITY, f64::min),
            under(0.005),
            under(0.01),
            under(0.02),
            t.len()
        );
    }
    (r.lateral, moved, yaw_press)
}

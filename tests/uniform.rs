//! Cases like users' (issue 51): defects spread uniformly over the real femoral component's
//! articular surface (../shared/data/femoral_dm_contact.stl on femoral_dm.stl), placed by the
//! seed and not filtered by the arm's reach, the part held as each cell's workcell.toml
//! mounts it. Measures the share of the repairable area `plan` covers and tallies the reasons
//! plan.json gives for what it leaves out.
mod common;

use std::collections::BTreeMap;

use nalgebra::Vector3;
use polishbot::motion::{plan, Inspection, Plan, PlanMode};
use polishbot::report::escape;
use polishbot::report::plan_html::write_plan_html;
use polishbot::report::provenance::Provenance;
use polishbot::robot::{angle_between, Turntable, Workcell};

use common::femoral::{
    cell, library, parametric_case, planned_area, reasons, setups, uniform_case, uniform_config,
};
use common::{calib, read_journal, tempdir};
use polishbot::bus::EntryKind;

/// Issue 51's 0.90 is the share planned in the shipped cell, and the shipped designed cell is
/// two setups (calibration/femoral/ and its setup-2/): [`TWO_SETUP_FLOOR`] holds it, on both
/// seeds. Setup 1 alone is measured here and printed, not held to 0.90: once coverage counts
/// where the spring-loaded spindle's patch lands (0.7-1.7 mm beside the aimed command point,
/// issue 50) and the press is limited to what the servos hold, setup 1 plans 0.942 (seed 5100,
/// with region 17 split by table angle; 0.899 without) and 0.896 (seed 5101). It planned 0.921
/// and 0.931 when coverage was counted at the command points. Setup 1 may not fall below
/// [`SETUP_ONE_FLOOR`].
const REMOVAL_FLOOR: f64 = 0.90;

/// Least share setup 1 alone plans on each seed (0.85): a guard against losing reach in the
/// first setup, a clear margin under the measured 0.896-0.942; the floor is
/// [`REMOVAL_FLOOR`] over both setups.
const SETUP_ONE_FLOOR: f64 = 0.85;

/// Least share of the repairable area planned over the shipped designed cell's two setups
/// (calibration/femoral/ and its setup-2/, the part re-fixtured between them), removal mode,
/// on each seed of [`uniform_defects_over_the_designed_cells_two_setups`]. Measured 0.957
/// (seed 5100; 0.942 with setup 1 alone) and 0.931 (seed 5101; 0.896): setup 2 takes regions
/// 9 and 45 (5100) and 35 and 52 (5101). What stays out: regions whose contacts lie beyond the
/// 45 degree cone in both setups, and contacts whose force a servo cannot hold in setup 2.
const TWO_SETUP_FLOOR: f64 = 0.925;

/// Coverage below which a region counts as left out: plan.json must say why.
const LEFT_OUT: f64 = 0.5;

/// Plans the seed's case in `calibration/DIR` and prints the planned share and the reasons.
fn measure(dir: &str, insp: &Inspection, seed: u64) -> (f64, f64) {
    let (c, t, _) = measure_plan(dir, insp, seed);
    (c, t)
}

/// [`measure`], with the plan.
fn measure_plan(dir: &str, insp: &Inspection, seed: u64) -> (f64, f64, Plan) {
    let (robot, wc, table, mut config) = cell(dir);
    // `plan`'s default mode, as a user runs it
    config.mode = PlanMode::Removal;
    let plan = plan(insp, &robot, &wc, table.as_ref(), &config).expect("plan");
    let (c, t) = planned_area(&plan);
    println!(
        "cell {dir:?} seed {seed}: repairable {t:.1} mm^2, planned {:.1} %, left out {:?}; {}",
        100.0 * c / t.max(1e-9),
        reasons(&plan),
        press_depths(&plan, &wc, table.as_ref())
    );
    (c, t, plan)
}

/// The pressed contacts of `plan` (placed by `wc`, turned to each region's table angle by
/// `table`) by the depth they are commanded below the surface: how many, how many shallower
/// than the deepest (the force a servo holds limits them: `motion::press_depth`), the
/// shallowest, and the range of the spindle's tilt from the normal at each kind.
fn press_depths(plan: &Plan, wc: &Workcell, table: Option<&Turntable>) -> String {
    let angle = |region: usize| {
        let t = plan.turntable.as_ref()?;
        let e = t.regions.iter().find(|e| e.region == region)?;
        Some(e.angle_deg.to_radians())
    };
    let points = plan.passes.iter().flat_map(|p| {
        let at = match (table, angle(p.region)) {
            (Some(t), Some(a)) => t.workcell_at(wc, a),
            _ => wc.clone(),
        };
        p.points.iter().filter(|q| q.offset_mm < 0.0).map(move |q| {
            let inward = -at.direction_from_reference(&Vector3::from(q.normal));
            let tilt = angle_between(&Vector3::from(q.axis), &inward).to_degrees();
            (-q.offset_mm, tilt)
        })
    });
    let all: Vec<(f64, f64)> = points.collect();
    let deepest = all.iter().map(|p| p.0).fold(0.0, f64::max);
    let range = |v: &[(f64, f64)]| {
        let lo = v.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let hi = v.iter().map(|p| p.1).fold(0.0, f64::max);
        format!("{lo:.1}-{hi:.1} deg")
    };
    let (shallow, full): (Vec<_>, Vec<_>) = all.iter().partition(|p| p.0 < deepest - 1e-9);
    format!(
        "{} pressed points, {} of them {deepest:.2} mm deep (tilt {}), {} shallower (least {:.2} mm, tilt {})",
        all.len(),
        full.len(),
        range(&full),
        shallow.len(),
        shallow.iter().map(|p| p.0).fold(deepest, f64::min),
        range(&shallow)
    )
}

/// The baseline of issue 51 on two uniform cases in the default and the turntable cell
/// (numbers only: the shipped cells are not designed for the part; `--nocapture`).
#[test]
#[ignore]
fn uniform_defects_in_the_shipped_cells() {
    let mut sums = BTreeMap::new();
    for seed in [5100, 5101] {
        for (part, insp) in [
            ("femoral_dm", uniform_case(seed)),
            ("parametric", parametric_case(seed)),
        ] {
            for dir in ["", "turntable/", "femoral/"] {
                println!("{part}:");
                let (c, t) = measure(dir, &insp, seed);
                let e = sums.entry((part, dir)).or_insert((0.0, 0.0));
                e.0 += c;
                e.1 += t;
            }
        }
    }
    for ((part, dir), (c, t)) in sums {
        println!(
            "{part}, cell {dir:?}: {:.1} % of the repairable area planned",
            100.0 * c / t
        );
    }
}

/// Regions split by table angle (issue 51, "the table as a sixth axis", at stroke
/// granularity): femoral_dm's uniform cases in the turntable and the designed cell, removal
/// mode, planned with each region at one angle (`table_pieces` 0) and split into up to 2
/// and 3 further pieces (numbers only: `--ignored --nocapture`).
#[test]
#[ignore]
fn uniform_defects_split_by_table_angle() {
    for seed in [5100, 5101] {
        let insp = uniform_case(seed);
        for dir in ["turntable/", "femoral/"] {
            let (robot, wc, table, mut config) = cell(dir);
            config.mode = PlanMode::Removal;
            for pieces in [0, 2, 3] {
                config.table_pieces = pieces;
                let plan = match plan(&insp, &robot, &wc, table.as_ref(), &config) {
                    Ok(p) => p,
                    Err(e) => {
                        println!("seed {seed}, cell {dir:?}, pieces {pieces}: refused: {e}");
                        continue;
                    }
                };
                let (c, t) = planned_area(&plan);
                let tp = plan.turntable.as_ref().expect("a table part");
                let split = tp.regions.iter().filter(|r| !r.pieces.is_empty()).count();
                let added: usize = tp.regions.iter().map(|r| r.pieces.len()).sum();
                println!(
                    "seed {seed}, cell {dir:?}, pieces {pieces}: planned {:.1} % of {t:.1} mm^2, {split} regions split, {added} pieces, {} table moves, {:.1} s",
                    100.0 * c / t,
                    tp.moves.len(),
                    plan.predicted_duration_s
                );
            }
        }
    }
}

/// Issue 51's acceptance case in removal mode (`plan`'s default) in the shipped designed cell,
/// seeds 5100 and 5101: the planned share on each (setup 1 alone, at least
/// [`SETUP_ONE_FLOOR`]; the shipped cell's two setups hold [`REMOVAL_FLOOR`]), and every
/// region left mostly unground names the rules that refused its contacts (plan.json's
/// unreachable list) and the other table angles tried for it with what each covered or why
/// it was refused (`turntable.regions[].tried`).
#[test]
fn uniform_defects_in_the_designed_cell_in_removal_mode() {
    let mut rules = 0;
    for seed in [5100, 5101] {
        let insp = uniform_case(seed);
        let (c, t, plan) = measure_plan("femoral/", &insp, seed);
        println!("seed {seed}: setup 1 alone planned {:.3}", c / t);
        assert!(
            c / t >= SETUP_ONE_FLOOR,
            "seed {seed}: planned {:.3}",
            c / t
        );
        rules += plan_page_says_what_is_left_out(&insp, &plan, seed);
        let table = plan.turntable.as_ref().expect("a table part");
        for r in &plan.reachability.regions {
            if !r.repairable || r.coverage_of_all >= LEFT_OUT {
                continue;
            }
            let why: Vec<_> = plan
                .reachability
                .unreachable
                .iter()
                .filter(|u| u.region == r.id)
                .collect();
            assert!(
                !why.is_empty() && why.iter().all(|u| !u.reason.is_empty()),
                "seed {seed}: region {} left out without a reason",
                r.id
            );
            let entry = table.regions.iter().find(|e| e.region == r.id).unwrap();
            println!(
                "seed {seed}: region {} ({:.1} mm^2) left out at {} deg: {}; tried {:?}",
                r.id, r.area_mm2, entry.angle_deg, why[0].reason, entry.tried
            );
            assert!(
                !entry.tried.is_empty(),
                "seed {seed}: region {}: no other table angle tried",
                r.id
            );
            // every angle tried covers it no better, and says why
            for a in &entry.tried {
                assert!(a.coverage < LEFT_OUT && a.refused.is_some(), "{a:?}");
            }
        }
    }
    assert!(
        rules > 0,
        "neither seed left a contact out: the page check saw no rule"
    );
}

/// The text of the first `<figcaption>` that starts with `start`.
fn caption<'a>(page: &'a str, start: &str) -> &'a str {
    let from = page
        .find(&format!("<figcaption>{start}"))
        .unwrap_or_else(|| panic!("no caption {start:?}"));
    &page[from..from + page[from..].find("</figcaption>").unwrap()]
}

/// Writes `plan`'s plan.html and checks what it says of the part left out (issue 51): every
/// rule of plan.json's unreachable list with its count, a coverage map whose planned area is
/// plan.json's (`coverage_of_all` x area), each region left mostly unground in the left-out
/// table with a rule plan.json gives and the table angles tried; and per predicted region the
/// three panels on one colour scale, the predicted one spanning plan.json's prediction.
/// Returns how many rules refused contacts.
fn plan_page_says_what_is_left_out(insp: &Inspection, plan: &Plan, seed: u64) -> usize {
    let dir = common::tempdir();
    let provenance = Provenance::of_inputs("plan", "mm", Vec::new(), &"test").unwrap();
    let html =
        write_plan_html(&dir.path().join("plan.json"), insp, plan, &provenance, None).unwrap();
    let page = std::fs::read_to_string(html).unwrap();
    let rules = reasons(plan);
    for (rule, n) in &rules {
        let row = format!("<tr><td>{}</td><td>{n}</td>", escape(rule));
        assert!(page.contains(&row), "seed {seed}: no row {row:?}");
    }
    let (c, t) = planned_area(plan);
    let map = caption(&page, "coverage map: ");
    let numbers: Vec<f64> = map["<figcaption>coverage map: ".len()..]
        .split(" mm²")
        .next()
        .unwrap()
        .split(" of ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!((numbers[1] - t).abs() < 0.01, "seed {seed}: {map} ({t:.2})");
    assert!(
        (numbers[0] - c).abs() <= 0.01 * t,
        "seed {seed}: {map} ({c:.2})"
    );
    assert!(dir.path().join("plan_coverage.png").is_file());
    let left = &page[page.find("<h2>left out: regions").expect("left-out table")..];
    let left = &left[..left.find("</table>").unwrap()];
    for r in &plan.reachability.regions {
        if !r.repairable || r.coverage_of_all >= LEFT_OUT {
            continue;
        }
        let row = left
            .split("<tr>")
            .find(|row| row.starts_with(&format!("<td>{}</td>", r.id)))
            .unwrap_or_else(|| panic!("seed {seed}: region {} not in {left}", r.id));
        let cells: Vec<&str> = row
            .split("<td>")
            .skip(1)
            .map(|c| &c[..c.find("</td>").unwrap()])
            .collect();
        assert!(
            rules.keys().any(|k| escape(k) == cells[4]),
            "seed {seed}: {row}"
        );
        assert!(cells[5].contains("best other: table"), "seed {seed}: {row}");
    }
    let removal = plan.removal.as_ref().expect("removal mode");
    for r in &removal.regions {
        let scale = |what: &str| {
            let c = caption(&page, &format!("region {}: {what};", r.region));
            c.split("colour scale ±")
                .nth(1)
                .unwrap()
                .split(' ')
                .next()
                .unwrap()
                .to_string()
        };
        let scales = [
            "deviation before",
            "predicted after",
            "Monte Carlo low quantile",
        ]
        .map(scale);
        assert!(
            scales.iter().all(|s| *s == scales[0]),
            "seed {seed}: {scales:?}"
        );
        let after = caption(&page, &format!("region {}: predicted after;", r.region));
        let pieces: Vec<_> = (removal.regions.iter())
            .filter(|p| p.region == r.region)
            .collect();
        if pieces.len() == 1 {
            let span = format!("{:+.4} to {:+.4} mm", r.after.lowest_mm, r.after.peak_mm);
            assert!(after.contains(&span), "seed {seed}: {after} ({span})");
        } else {
            // a region split by table angle: per point the lowest of its pieces' predictions,
            // so the span lies within the pieces' own
            let span: Vec<f64> = after
                .split("; ")
                .nth(1)
                .unwrap()
                .split(" mm")
                .next()
                .unwrap()
                .split(" to ")
                .map(|v| v.parse().unwrap())
                .collect();
            let lowest = pieces
                .iter()
                .map(|p| p.after.lowest_mm)
                .fold(f64::INFINITY, f64::min);
            let peak = pieces
                .iter()
                .map(|p| p.after.peak_mm)
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(
                span[0] >= lowest - 5e-5 && span[1] <= peak + 5e-5,
                "seed {seed}: {after} (pieces {lowest:+.4} to {peak:+.4} mm)"
            );
        }
    }
    rules.len()
}

/// Issue 51's case over the designed cell's two setups (`plan` reads setup-2/ beside the
/// workcell): the same seeds planned with setup 1 alone and with both, in removal mode. The
/// two-setup plan plans no less than setup 1 alone and at least [`TWO_SETUP_FLOOR`]; every
/// region names its setup, setup 2 holds exactly the regions moved to it, each setup states
/// its placement's hash, and every region setup 2 tried and left names why. Setup 2 takes a
/// region of at least one seed: since the removal planner grinds a contact softer before it
/// lifts it (motion/soften.rs), seed 5100's regions 17 and 22 plan in setup 1 (98.6 % with
/// setup 1 alone, 2026-12-06) and only seed 5101 moves a region.
#[test]
fn uniform_defects_over_the_designed_cells_two_setups() {
    let (_, cells, mut config) = setups("femoral/");
    let alone = library("femoral/", true);
    assert_eq!(cells.len(), 2, "the designed cell ships two setups");
    config.mode = PlanMode::Removal;
    let mut moved_any = false;
    for seed in [5100, 5101] {
        let insp = uniform_case(seed);
        let one = polishbot::motion::setups::plan(&insp, &alone, &cells[..1], &config).unwrap();
        let two = polishbot::motion::setups::plan(&insp, &alone, &cells, &config).unwrap();
        let (c1, t1) = planned_area(&one);
        let (c2, t2) = planned_area(&two);
        let moved = &two.setups[1].regions;
        println!(
            "seed {seed}: repairable {t2:.1} mm^2, planned {:.1} % with setup 1, {:.1} % with two setups; regions moved to setup 2: {moved:?}; tried there and left: {:?}",
            100.0 * c1 / t1,
            100.0 * c2 / t2,
            two.setups[1].tried
        );
        assert!(one.setups.is_empty(), "one setup: no setups list");
        moved_any |= !moved.is_empty();
        assert!(
            c2 / t2 >= REMOVAL_FLOOR,
            "seed {seed}: the shipped cell planned {c2}/{t2}"
        );
        assert!(
            c2 / t2 >= TWO_SETUP_FLOOR,
            "seed {seed}: planned {:.3}",
            c2 / t2
        );
        assert!(
            c2 / t2 >= c1 / t1 - 1e-9,
            "seed {seed}: two setups plan less"
        );
        assert_ne!(
            two.setups[0].placement_sha256,
            two.setups[1].placement_sha256
        );
        for r in &two.reachability.regions {
            let s = r.setup.expect("every region names its setup");
            assert_eq!(moved.contains(&r.id), s == 2, "region {}: setup {s}", r.id);
        }
        let sub = two.setups[1].plan.as_deref();
        assert_eq!(
            sub.is_some(),
            !moved.is_empty(),
            "setup 2's plan iff it has regions"
        );
        assert!(two.setups[1].tried.iter().all(|t| t.refused.is_some()));
    }
    assert!(moved_any, "setup 2 takes no region of either seed");
}

/// A copy of the shipped femoral cell (with its setup-2/) in `dir`.
fn copy_cell(dir: &std::path::Path) {
    let src = calib("femoral");
    for sub in ["", "setup-2"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        for e in std::fs::read_dir(src.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.is_file() {
                std::fs::copy(&p, dir.join(sub).join(p.file_name().unwrap())).unwrap();
            }
        }
    }
}

/// The operator's steps on a two-setup plan (seed 5101 in a copy of the designed cell, the
/// simulated arm): `run` streams setup 1 and ends with the operator stop (exit 5, journaled,
/// naming setup 2); `run --resume` refuses setup 2 on a placement other than the one planned
/// (the re-fixtured part measured 1 mm off), and on the planned one streams setup 2's frames
/// from its first, then ends normally.
#[test]
fn a_two_setup_plan_stops_for_the_refixture_and_resumes_with_setup_two() {
    let tmp = tempdir();
    let (cell_dir, insp) = (tmp.path().join("cell"), tmp.path().join("inspection"));
    copy_cell(&cell_dir);
    common::synthetic::inspection(&insp, &uniform_config(5101));
    let plan_file = tmp.path().join("plan.json");
    let plan = common::plan_in_cell(&insp, &cell_dir, &plan_file);
    let path = |p: &std::path::Path| p.display().to_string();
    let setup2 = plan.setups[1].plan.as_deref().expect("setup 2 has regions");
    let journal = tmp.path().join("journal.jsonl");
    let run = |extra: &[&str]| common::run_sim(&plan_file, &cell_dir, extra);
    let first = run(&[]);
    let err = String::from_utf8_lossy(&first.stderr);
    assert_eq!(first.status.code(), Some(5), "{err}");
    assert!(err.contains("re-fixture the part as setup 2"), "{err}");
    let entries = read_journal(&journal);
    let last = entries.last().unwrap();
    assert_eq!((last.kind, last.setup), (EntryKind::OperatorStop, Some(2)));
    let sent1 = common::motion_frames_sent(&entries);
    assert!(
        sent1 >= plan.frames.len(),
        "setup 1 streamed: {sent1} motion frames"
    );
    // the re-fixtured part measured 1 mm off the planned placement: refused
    let wc = cell_dir.join("setup-2/workcell.toml");
    let planned = std::fs::read_to_string(&wc).unwrap();
    let moved = planned.replace("0.026566881]", "0.027566881]");
    assert_ne!(moved, planned);
    std::fs::write(&wc, moved).unwrap();
    let resume = ["--resume", &path(&journal)];
    let refused = run(&resume);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("setup 2's placement is not the one"),
        "{err}"
    );
    std::fs::write(&wc, planned).unwrap();
    let second = run(&resume);
    assert!(
        second.status.success(),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );
    let entries = read_journal(&journal);
    let open2 = entries
        .iter()
        .rposition(|e| e.kind == EntryKind::Open)
        .unwrap();
    assert_eq!(entries[open2].setup, Some(2));
    let tx2: Vec<u64> = entries[open2..]
        .iter()
        .filter(|e| e.kind == EntryKind::Tx)
        .filter_map(|e| e.motion)
        .collect();
    assert_eq!(tx2.first(), Some(&0), "setup 2 starts at its first frame");
    assert!(
        tx2.len() >= setup2.frames.len(),
        "setup 2 streamed: {} motion frames",
        tx2.len()
    );
}

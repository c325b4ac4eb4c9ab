//! The table as a sixth axis within a stroke (issue 51, item 3; `motion::table_sync`).
mod common;

use common::femoral::{cell, inspection, planned_area, table_bus, uniform_case};
use polishbot::bus::{Bus, EntryKind, Journal};
use polishbot::cell::{execute, steps, RunConfig, Step};
use polishbot::motion::{plan, PlanMode};
use polishbot::sim::SimArm;

/// Tool-axis cones of the survey, degrees from the arm's plane: the IK's default (45), and
/// the stricter 10 of [`common::femoral::synced_plan`].
const SURVEY_CONES: [f64; 2] = [45.0, 10.0];

/// Survey: femoral_dm's uniform cases 5100 and 5101 and synth case 2000 in the designed and
/// the turntable cell, rigid mode, each tool-axis cone of [`SURVEY_CONES`], planned without
/// and with strokes ground while the table turns (numbers only: `--ignored --nocapture`).
#[test]
#[ignore]
fn uniform_defects_with_the_table_in_sync() {
    for seed in [5100, 5101, 2000] {
        let insp = if seed >= 5000 {
            uniform_case(seed)
        } else {
            inspection(seed, 4)
        };
        for dir in ["femoral/", "turntable/"] {
            let (robot, wc, table, mut config) = cell(dir);
            config.mode = PlanMode::Rigid;
            for cone in SURVEY_CONES {
                config.ik.max_axis_miss_deg = cone;
                for sync in [0, polishbot::motion::PlanConfig::default().table_sync] {
                    config.table_sync = sync;
                    let p = match plan(&insp, &robot, &wc, table.as_ref(), &config) {
                        Ok(p) => p,
                        Err(e) => {
                            println!("seed {seed} {dir} cone {cone} sync {sync}: refused: {e}");
                            continue;
                        }
                    };
                    let (c, t) = planned_area(&p);
                    let tp = p.turntable.as_ref().unwrap();
                    println!(
                        "seed {seed} {dir} cone {cone} sync {sync}: planned {:.1} % of {t:.1} mm^2, {} synced strokes, {} table moves, {:.1} s",
                        100.0 * c / t,
                        tp.synced.len(),
                        tp.moves.len(),
                        p.predicted_duration_s,
                    );
                }
            }
        }
    }
}

/// The simulated cell follows a plan with strokes ground while the table turns
/// (`common::femoral::synced_plan`): serving the table as bus servo 7, it receives every table
/// frame once (the moves' and the synced strokes', each synced one in the same period as its
/// arm frame), `run` reads the table back during the strokes within its read-back tolerance
/// (the run stops otherwise), and the table ends at the plan's last angle.
#[test]
fn the_simulated_cell_follows_the_table_turning_within_a_stroke() {
    let (robot, _, table, _, _, plan) = common::femoral::synced_plan();
    let tp = plan.turntable.clone().expect("a table part");
    assert!(!tp.synced.is_empty(), "no synced stroke");
    let checked = plan
        .check_cell(&robot, Some(&table), &Default::default())
        .expect("run's check");
    let (cfg, options) = table_bus(&robot, &table);
    let arm = SimArm::new(&options, &cfg.servo_map).unwrap();
    let dir = common::tempdir();
    let journal = dir.path().join("journal.jsonl");
    let mut bus = Bus::connect(arm.transport(), cfg, Journal::append(&journal).unwrap()).unwrap();
    let run = RunConfig::default();
    let report = execute(&mut bus, &checked, plan.period, 0, &run).unwrap();
    let t = checked.table.as_ref().unwrap();
    let moved: usize = t.moves.iter().map(|m| m.raw.len()).sum();
    let synced: usize = t.synced.iter().map(|s| s.raw.len()).sum();
    let received = arm.received();
    let sent = received.iter().filter(|f| f.func == 0x19).count();
    assert_eq!(sent, moved + synced, "every table frame once");
    // inside a stretch each table frame follows its arm frame directly
    let steps = steps(&checked);
    let paired = steps
        .iter()
        .filter(|s| matches!(s, Step::Synced { .. }))
        .count();
    assert_eq!(paired, synced);
    // the table read back during the strokes: verified entries of servo 7 at synced steps
    let entries = common::read_journal(&journal);
    let table_reads = entries
        .iter()
        .filter(|e| e.kind == EntryKind::Verified && e.name.as_deref() == Some("servo 7"))
        .filter(|e| {
            e.motion
                .is_some_and(|m| matches!(steps[m as usize], Step::Synced { .. }))
        })
        .count();
    assert!(
        table_reads > 0,
        "the table is not read back during the strokes"
    );
    assert!(report.worst_readback_counts <= run.readback_tolerance_counts);
    let want = table.raw(tp.end()).unwrap();
    assert_eq!(arm.extra_position(7), Some(want));
    println!(
        "{} synced strokes ({synced} table frames with their arm frames), {} table moves ({moved} frames); {table_reads} table read-backs during the strokes; worst read-back {} counts",
        t.synced.len(),
        t.moves.len(),
        report.worst_readback_counts
    );
}

/// A plan without strokes ground while the table turns is what it was before them: femoral_dm's
/// uniform case 5100 in the designed cell, rigid mode, leaves no region short after its pieces,
/// and its plan.json is byte for byte the same with `table_sync` at its default and at 0,
/// with no `synced` key anywhere.
#[test]
fn a_plan_without_in_stroke_table_motion_is_unchanged() {
    let insp = uniform_case(5100);
    let (robot, wc, table, mut config) = cell("femoral/");
    config.mode = PlanMode::Rigid;
    let with = plan(&insp, &robot, &wc, table.as_ref(), &config).expect("plan");
    config.table_sync = 0;
    let without = plan(&insp, &robot, &wc, table.as_ref(), &config).expect("plan");
    let (a, b) = (
        serde_json::to_string_pretty(&with).unwrap(),
        serde_json::to_string_pretty(&without).unwrap(),
    );
    assert!(
        !a.contains("synced"),
        "a `synced` key in a plan without synced strokes"
    );
    assert_eq!(a, b, "plan.json changed");
}

/// `run`'s check refuses a plan whose strokes ground with the table turning were tampered
/// with, naming the stretch or the region: its table angles deleted, one sample's angle moved
/// beyond the table's velocity limit, a frame that is not its sample's; and the plan streamed
/// to a cell without that table. The plan as made passes.
#[test]
fn a_tampered_synced_stretch_or_a_cell_without_the_table_is_refused() {
    let (robot, _, table, _, _, plan) = common::femoral::synced_plan();
    let check = |p: &polishbot::motion::Plan| {
        p.check_cell(&robot, Some(&table), &Default::default())
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    check(&plan).expect("the plan as made");
    let mut cut = plan.clone();
    cut.turntable.as_mut().unwrap().synced.clear();
    let err = check(&cut).unwrap_err();
    assert!(err.contains("turntable"), "{err}");
    let mut fast = plan.clone();
    let st = &mut fast.turntable.as_mut().unwrap().synced[0];
    let k = st.angles.len() / 2;
    st.angles[k] += 0.2;
    let err = check(&fast).unwrap_err();
    assert!(err.contains("synced stretch 0 sample"), "{err}");
    let mut frame = plan.clone();
    let st = &mut frame.turntable.as_mut().unwrap().synced[0];
    // the middle sample's frame sent first (its neighbours at rest share one raw count)
    let k = st.frames.len() / 2;
    st.frames.swap(0, k);
    let err = check(&frame).unwrap_err();
    assert!(err.contains("synced stretch 0 frame 0"), "{err}");
    let err = plan
        .check_cell(&robot, None, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("no [turntable]"), "{err}");
    let mut only_synced = plan.clone();
    only_synced.turntable.as_mut().unwrap().moves.clear();
    let err = only_synced
        .check(&robot, &Default::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("turntable"), "{err}");
}

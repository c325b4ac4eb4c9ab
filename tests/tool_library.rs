//! The tool library (issue 51, "a tool for every corner"): the shipped femoral cell's
//! calibration/femoral/tools/small.toml (a 4 mm ball on a longer, thinner shank) beside its
//! tool.toml (6 mm ball), and a library with a 12 mm ball above them. Per region the planner
//! takes the largest ball that fits and reaches; the run stops for the tool change
//! (journaled) and resumes with the next tool only on the tool file the plan was made with. A
//! cell with tool.toml alone plans as before.
mod common;

use polishbot::bus::EntryKind;
use polishbot::motion::{Plan, PlanMode};

use common::femoral::{planned_area, setups, uniform_case, uniform_config};
use common::{calib, read_journal, tempdir};
use polishbot::motion::tools::ToolRobot;
use polishbot::robot::FileText;

/// The uniform case the tests plan (one of tests/uniform.rs's two seeds). 5100: with the rim
/// budgets held in the dwell solve (`removal::guard`) the 12 mm ball covers every region of
/// seed 5101 well enough (96.5 % alone; it takes 31 regions and the 6 mm ball none), so 5101 no
/// longer has a region only a smaller ball reaches; on 5100 the 6 mm ball takes regions 9 and
/// 17 from it (95.7 % with the 12 mm ball alone, 100 % with the library; 2026-12-06). Seeds
/// 5100-5112 searched: 5106, 5110 and 5111 leave the 6 mm ball nothing either.
const SEED: u64 = 5100;

/// Radius of the large ball the tests add above the shipped library, m: a 12 mm abrasive
/// point (mounted rubber-bonded points come from 3 to 25 mm).
const LARGE_BALL: &str = "radius = 0.006\n";

/// The shipped tool.toml's ball radius line.
const SHIPPED_BALL: &str = "radius = 0.003\n";

/// The femoral cell's tool library (`alone`: tool.toml only), with `extra` tool files added
/// (library name, text).
fn femoral_library(alone: bool, extra: &[(&str, String)]) -> Vec<ToolRobot> {
    let mut cfg = polishbot::robot::RobotConfig::default();
    cfg.use_cell(&calib("femoral"));
    let mut cell = cfg.read_cell().expect("read the cell");
    if alone {
        cell.tools.clear();
    }
    for (name, text) in extra {
        let path = calib(&format!("femoral/tools/{name}.toml"));
        cell.tools.push(FileText {
            path,
            text: text.clone(),
        });
    }
    ToolRobot::of_cell(&cell).expect("the tool library")
}

/// The shipped tool.toml with a 12 mm ball.
fn large_tool() -> String {
    let text = std::fs::read_to_string(calib("femoral/tool.toml")).unwrap();
    assert!(text.contains(SHIPPED_BALL));
    text.replace(SHIPPED_BALL, LARGE_BALL)
}

/// The femoral cell's setup 1 planned on `seed`'s uniform case, removal mode (`plan`'s
/// default), with `tools`.
fn plan_case(seed: u64, tools: &[ToolRobot]) -> Plan {
    let (_, cells, mut config) = setups("femoral/");
    config.mode = PlanMode::Removal;
    let insp = uniform_case(seed);
    polishbot::motion::setups::plan(&insp, tools, &cells[..1], &config).expect("plan")
}

/// Issue 51's measure on femoral_dm's uniform case: the planned share with tool.toml alone,
/// with the shipped library (tool.toml and small.toml) and with a 12 mm ball above them. With
/// the large ball first, the regions it leaves short go to the next smaller ball that covers
/// more: each region the 6 mm ball took was short with the 12 mm one and is covered better;
/// every planned region names its tool, the tool sequence is largest first, and a library
/// never plans less than its first tool alone.
#[test]
fn the_library_plans_each_region_with_the_largest_ball_that_reaches_it() {
    let alone = plan_case(SEED, &femoral_library(true, &[]));
    let shipped = plan_case(SEED, &femoral_library(false, &[]));
    let large = femoral_library(false, &[("large", large_tool())]);
    let lib = plan_case(SEED, &large);
    let large_alone = plan_case(SEED, &large[..1]);
    let share = |p: &Plan| {
        let (c, t) = planned_area(p);
        c / t
    };
    println!(
        "seed {SEED}: femoral_dm uniform, setup 1, removal mode: planned {:.1} % with tool.toml alone, {:.1} % with the shipped library (small ball takes {:?}), {:.1} % with the 12 mm ball alone, {:.1} % with the 12 mm ball above the library (takes {:?})",
        100.0 * share(&alone),
        100.0 * share(&shipped),
        shipped.tools[1].regions,
        100.0 * share(&large_alone),
        100.0 * share(&lib),
        lib.tools.iter().map(|t| (&t.tool, &t.regions)).collect::<Vec<_>>()
    );
    assert!(alone.tools.is_empty(), "one tool: no tools list");
    let names: Vec<&str> = lib.tools.iter().map(|t| t.tool.as_str()).collect();
    assert_eq!(names, ["large", "tool", "small"], "largest ball first");
    assert!(share(&shipped) >= share(&alone) - 1e-9);
    assert!(share(&lib) >= share(&large_alone) - 1e-9);
    let cov = |p: &Plan, id: usize| {
        let r = p.reachability.regions.iter().find(|r| r.id == id).unwrap();
        r.coverage_of_all
    };
    let moved = &lib.tools[1].regions;
    assert!(!moved.is_empty(), "no region only a smaller ball reaches");
    for &id in moved {
        assert!(
            cov(&large_alone, id) < 0.95,
            "region {id} moved though covered"
        );
        assert!(cov(&lib, id) > cov(&large_alone, id), "region {id}");
    }
    for (k, t) in lib.tools.iter().enumerate() {
        assert_eq!(
            t.plan.is_some(),
            k > 0 && !t.regions.is_empty(),
            "{}",
            t.tool
        );
    }
    for r in lib.reachability.regions.iter().filter(|r| r.layers > 0) {
        let tool = r.tool.as_deref().expect("every region names its tool");
        let t = lib.tools.iter().find(|t| t.tool == tool).unwrap();
        assert!(t.regions.contains(&r.id), "region {}", r.id);
    }
    // a region left out names each other tool tried on it
    for t in &lib.tools[1].tried {
        if let Some(u) = (lib.reachability.unreachable.iter()).find(|u| u.region == t.region) {
            assert!(
                u.reason.contains("tools tried: tool (ball 3.0 mm"),
                "{}",
                u.reason
            );
        }
    }
}

/// A copy of the shipped femoral cell (setup 1) in `dir` whose tool.toml is the 12 mm ball
/// and whose library holds the shipped 6 mm ball as `tools/mid.toml`.
fn copy_cell(dir: &std::path::Path) {
    let src = calib("femoral");
    std::fs::create_dir_all(dir.join("tools")).unwrap();
    for e in std::fs::read_dir(&src).unwrap() {
        let p = e.unwrap().path();
        if p.is_file() {
            std::fs::copy(&p, dir.join(p.file_name().unwrap())).unwrap();
        }
    }
    std::fs::copy(src.join("tool.toml"), dir.join("tools/mid.toml")).unwrap();
    std::fs::write(dir.join("tool.toml"), large_tool()).unwrap();
}

/// The operator's steps on a plan with a tool change (seed [`SEED`] in a copy of the femoral cell
/// with a 12 mm ball as tool.toml and the 6 mm one as `mid`, the simulated arm): `run --sim`
/// streams the 12 mm ball's stage, journals the `tool_change` stop naming `mid`, and its
/// simulated operator resumes; a `mid` whose file changed since the plan is refused there
/// (exit 1, the run stopped at the change); with the planned file back, `run --resume`
/// streams mid's stage from its first frame and ends normally.
#[test]
fn a_tool_change_stops_the_run_and_resumes_with_the_planned_tool() {
    let tmp = tempdir();
    let (cell_dir, insp) = (tmp.path().join("cell"), tmp.path().join("inspection"));
    copy_cell(&cell_dir);
    common::synthetic::inspection(&insp, &uniform_config(SEED));
    let plan_file = tmp.path().join("plan.json");
    let plan: Plan = common::plan_in_cell(&insp, &cell_dir, &plan_file);
    let path = |p: &std::path::Path| p.display().to_string();
    let names: Vec<&str> = plan.tools.iter().map(|t| t.tool.as_str()).collect();
    assert_eq!(names, ["tool", "mid"], "the plan lists the library");
    let mid = plan.tools[1]
        .plan
        .as_deref()
        .expect("the 6 mm ball has regions");
    let journal = tmp.path().join("journal.jsonl");
    let run = |extra: &[&str]| common::run_sim(&plan_file, &cell_dir, extra);
    // the 6 mm tool re-made (its file changed) after the plan: refused at the change
    let tool = cell_dir.join("tools/mid.toml");
    let planned = std::fs::read_to_string(&tool).unwrap();
    let changed = planned.replace("preston_k_mm2_n = 5e-6", "preston_k_mm2_n = 6e-6");
    assert_ne!(changed, planned);
    std::fs::write(&tool, changed).unwrap();
    let first = run(&[]);
    let out = String::from_utf8_lossy(&first.stdout);
    let err = String::from_utf8_lossy(&first.stderr);
    assert_eq!(first.status.code(), Some(1), "{out}{err}");
    assert!(out.contains("mount tool `mid`"), "{out}");
    assert!(
        err.contains("tool `mid` is not the one the plan was made with"),
        "{err}"
    );
    let entries = read_journal(&journal);
    let last = entries.last().unwrap();
    assert_eq!((last.kind, last.setup), (EntryKind::OperatorStop, Some(2)));
    assert_eq!(last.code.as_deref(), Some("tool_change"));
    let sent1 = common::motion_frames_sent(&entries);
    assert!(
        sent1 >= plan.frames.len(),
        "stage 1 streamed: {sent1} motion frames"
    );
    std::fs::write(&tool, planned).unwrap();
    let second = run(&["--resume", &path(&journal)]);
    assert!(
        second.status.success(),
        "{}",
        String::from_utf8_lossy(&second.stderr)
    );
    let entries = read_journal(&journal);
    let open2 = (entries.iter())
        .rposition(|e| e.kind == EntryKind::Open)
        .unwrap();
    assert_eq!(entries[open2].setup, Some(2));
    let tx2: Vec<u64> = (entries[open2..].iter())
        .filter(|e| e.kind == EntryKind::Tx)
        .filter_map(|e| e.motion)
        .collect();
    assert_eq!(
        tx2.first(),
        Some(&0),
        "mid's stage starts at its first frame"
    );
    assert!(
        tx2.len() >= mid.frames.len(),
        "stage 2 streamed: {}",
        tx2.len()
    );
}

/// A cell with tool.toml alone is the library of one tool: plan.json has no `tools` and no
/// region names a tool (the file is what it was before the library).
#[test]
fn a_cell_with_tool_toml_alone_has_no_tool_list() {
    let plan = plan_case(SEED, &femoral_library(true, &[]));
    let text = serde_json::to_string(&plan).unwrap();
    assert!(
        !text.contains("\"tools\"") && !text.contains("\"tool\":"),
        "tools in a one-tool plan"
    );
}

//! The tool library (issue 51, "a tool for every corner"): the shipped femoral cell's
//! calibration/femoral/tools/small.toml (a 4 mm ball on a longer, thinner shank) beside its
//! tool.toml (6 mm ball). Per region the planner takes the largest ball that fits and reaches;
//! the run stops for the tool change (journaled) and resumes with the next tool only on the
//! tool file the plan was made with. A cell with tool.toml alone plans as before.
mod common;

use polishbot::bus::EntryKind;
use polishbot::motion::{Plan, PlanMode};

use common::femoral::{library, planned_area, setups, uniform_case, uniform_config};
use common::{calib, polishbot, read_journal, succeed, tempdir};

/// The uniform case the run test plans (seed of tests/uniform.rs's cases).
const SEED: u64 = 5101;

/// The femoral cell's setup 1 planned on `seed`'s uniform case, removal mode, with the tool
/// library (`alone`: tool.toml only).
fn plan_case(seed: u64, alone: bool) -> Plan {
    let (_, cells, mut config) = setups("femoral/");
    config.mode = PlanMode::Removal;
    let tools = library("femoral/", alone);
    let insp = uniform_case(seed);
    polishbot::motion::setups::plan(&insp, &tools, &cells[..1], &config).expect("plan")
}

/// With the library, every region the small ball took was short of good coverage with the
/// 6 mm ball and is covered better with the small one; each region names its tool, the tool
/// sequence is largest first, the regions of the tools partition the planned regions, and
/// the planned share is no less than with tool.toml alone (printed: issue 51's measure).
#[test]
fn the_library_plans_with_the_small_ball_where_the_large_one_does_not_fit() {
    let mut moved_any = false;
    for seed in [5100, 5101] {
        let alone = plan_case(seed, true);
        let lib = plan_case(seed, false);
        let (ca, ta) = planned_area(&alone);
        let (cl, tl) = planned_area(&lib);
        println!(
            "seed {seed}: femoral_dm uniform, setup 1: planned {:.1} % with tool.toml alone, {:.1} % with the library; small ball takes {:?}, tried and left {:?}",
            100.0 * ca / ta,
            100.0 * cl / tl,
            lib.tools[1].regions,
            lib.tools[1].tried
        );
        assert!(alone.tools.is_empty(), "one tool: no tools list");
        assert_eq!(lib.tools.len(), 2);
        assert_eq!(
            (lib.tools[0].tool.as_str(), lib.tools[1].tool.as_str()),
            ("tool", "small")
        );
        assert!(lib.tools[0].ball_radius_mm > lib.tools[1].ball_radius_mm);
        assert!(
            cl / tl >= ca / ta - 1e-9,
            "seed {seed}: the library plans less"
        );
        let cov = |p: &Plan, id: usize| {
            let r = p.reachability.regions.iter().find(|r| r.id == id).unwrap();
            r.coverage_of_all
        };
        for &id in &lib.tools[1].regions {
            moved_any = true;
            assert!(cov(&alone, id) < 0.95, "region {id} moved though covered");
            assert!(cov(&lib, id) > cov(&alone, id), "region {id}");
        }
        assert_eq!(
            lib.tools[1].plan.is_some(),
            !lib.tools[1].regions.is_empty()
        );
        for r in lib.reachability.regions.iter().filter(|r| r.layers > 0) {
            let tool = r.tool.as_deref().expect("every region names its tool");
            let k = usize::from(tool == "small");
            assert!(lib.tools[k].regions.contains(&r.id), "region {}", r.id);
        }
        // a region left out names each other tool tried on it
        for t in &lib.tools[1].tried {
            let u = lib
                .reachability
                .unreachable
                .iter()
                .find(|u| u.region == t.region);
            if let Some(u) = u {
                assert!(u.reason.contains("tools tried: small"), "{}", u.reason);
            }
        }
    }
    assert!(
        moved_any,
        "neither seed has a region only the small ball fits"
    );
}

/// A copy of the shipped femoral cell (setup 1 and its tool library) in `dir`.
fn copy_cell(dir: &std::path::Path) {
    let src = calib("femoral");
    for sub in ["", "tools"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        for e in std::fs::read_dir(src.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.is_file() {
                std::fs::copy(&p, dir.join(sub).join(p.file_name().unwrap())).unwrap();
            }
        }
    }
}

/// The operator's steps on a plan with a tool change (seed 5101 in a copy of the femoral cell
/// with its library, the simulated arm): `run --sim` streams the 6 mm ball's stage, journals
/// the `tool_change` stop naming the small tool, and its simulated operator resumes; a small
/// tool whose file changed since the plan is refused there (exit 1, the run stopped at the
/// change); with the planned file back, `run --resume` streams the small tool's stage from its
/// first frame and ends normally.
#[test]
fn a_tool_change_stops_the_run_and_resumes_with_the_planned_tool() {
    let tmp = tempdir();
    let (cell_dir, insp) = (tmp.path().join("cell"), tmp.path().join("inspection"));
    copy_cell(&cell_dir);
    common::synthetic::inspection(&insp, &uniform_config(SEED));
    let plan_file = tmp.path().join("plan.json");
    let path = |p: &std::path::Path| p.display().to_string();
    succeed(polishbot().args([
        "plan",
        "--inspection",
        &path(&insp),
        "--cell",
        &path(&cell_dir),
        "-o",
        &path(&plan_file),
    ]));
    let plan: Plan = serde_json::from_str(&std::fs::read_to_string(&plan_file).unwrap()).unwrap();
    assert_eq!(plan.tools.len(), 2, "the plan lists the library");
    let small = plan.tools[1]
        .plan
        .as_deref()
        .expect("the small ball has regions");
    let journal = tmp.path().join("journal.jsonl");
    let run = |extra: &[&str]| {
        let mut cmd = polishbot();
        cmd.args([
            "run",
            "--plan",
            &path(&plan_file),
            "--sim",
            "--cell",
            &path(&cell_dir),
        ])
        .args(extra);
        cmd.output().unwrap()
    };
    // the small tool re-made (its file changed) after the plan: refused at the change
    let tool = cell_dir.join("tools/small.toml");
    let planned = std::fs::read_to_string(&tool).unwrap();
    std::fs::write(
        &tool,
        planned.replace("preston_k_mm2_n = 5e-6", "preston_k_mm2_n = 6e-6"),
    )
    .unwrap();
    let first = run(&[]);
    let out = String::from_utf8_lossy(&first.stdout);
    let err = String::from_utf8_lossy(&first.stderr);
    assert_eq!(first.status.code(), Some(1), "{out}{err}");
    assert!(out.contains("mount tool `small`"), "{out}");
    assert!(
        err.contains("tool `small` is not the one the plan was made with"),
        "{err}"
    );
    let entries = read_journal(&journal);
    let last = entries.last().unwrap();
    assert_eq!((last.kind, last.setup), (EntryKind::OperatorStop, Some(2)));
    assert_eq!(last.code.as_deref(), Some("tool_change"));
    let sent1 = (entries.iter())
        .filter(|e| e.kind == EntryKind::Tx && e.motion.is_some())
        .count();
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
        "the small tool's stage starts at its first frame"
    );
    assert!(
        tx2.len() >= small.frames.len(),
        "stage 2 streamed: {}",
        tx2.len()
    );
}

/// A cell with tool.toml alone is the library of one tool: plan.json has no `tools` and no
/// region names a tool (the file is what it was before the library).
#[test]
fn a_cell_with_tool_toml_alone_has_no_tool_list() {
    let plan = plan_case(SEED, true);
    let text = serde_json::to_string(&plan).unwrap();
    assert!(
        !text.contains("\"tools\"") && !text.contains("\"tool\":"),
        "tools in a one-tool plan"
    );
}

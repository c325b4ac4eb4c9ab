//! Hostile inputs against the built binary (issue 34, "checked inputs and settings"): every
//! case must end in well under 20 s with a non-zero exit and one line naming the file and the
//! place (line, key, point index), never a panic; and the checks must not refuse the valid
//! case they guard.
mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use common::{pair_args, polishbot, succeed};
use polishbot::cloud::{self, PlyPrecision, PointCloud};
use serde_json::Value;

/// Each case's bound (the probe allows 20 s; these are small inputs).
const CASE_LIMIT: Duration = Duration::from_secs(20);

/// synth -> inspect -> plan once (e2e's case: seed 9, three defects, one layer per region).
struct Case {
    dir: PathBuf,
}

impl Case {
    fn path(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn case() -> &'static Case {
    static CASE: OnceLock<Case> = OnceLock::new();
    CASE.get_or_init(|| Case {
        dir: common::hostile::synth_inspect_plan("hostile", 200_000, 150_000, false),
    })
}

/// Runs `cmd`, which must fail within [`CASE_LIMIT`] with one line on stderr that contains
/// every one of `needles` and no panic; returns that line.
fn refused(cmd: &mut Command, needles: &[&str]) -> String {
    let start = Instant::now();
    let out: Output = cmd.output().expect("start polishbot");
    let took = start.elapsed();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(took < CASE_LIMIT, "took {took:?}: {err}");
    assert!(!out.status.success(), "accepted: {err}");
    assert_eq!(out.status.code(), Some(1), "exit status: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    let line = err
        .lines()
        .find(|l| l.starts_with("polishbot: "))
        .unwrap_or_else(|| panic!("no error line: {err}"))
        .to_string();
    for n in needles {
        assert!(line.contains(n), "{n:?} not in {line:?}");
    }
    assert!(!line.contains(" { "), "Debug text in {line:?}");
    line
}

/// `inspect` of the case's scan against `reference` with `extra` arguments, into `out`.
fn inspect(reference: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut cmd = polishbot();
    cmd.args(["inspect", "--reference", arg(reference), "--scan"])
        .arg(case().path("scan.ply"))
        .args(["-o", arg(out)])
        .args(extra);
    cmd
}

/// The case's reference cloud with `edit` applied, written to `name` in a fresh folder.
fn edited_reference(tmp: &Path, name: &str, edit: impl FnOnce(&mut PointCloud)) -> PathBuf {
    let mut c = cloud::load_cloud(&case().path("reference.ply"), None, None).unwrap();
    edit(&mut c);
    let path = tmp.join(name);
    cloud::write_ply(&path, &c, None, PlyPrecision::F64).unwrap();
    path
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Region peaks of an inspection folder, in file order.
fn peaks(dir: &Path) -> Vec<f64> {
    read_json(&dir.join("regions.json"))["regions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["peak"].as_f64().unwrap())
        .collect()
}

#[test]
fn a_pose_from_a_failed_registration_is_refused() {
    let tmp = common::tempdir();
    let pose = tmp.path().join("registration.json");
    let mut truth = read_json(&case().path("truth.json"));
    truth["status"] = "failed".into();
    truth["reason"] = "too few correspondences".into();
    std::fs::write(&pose, truth.to_string()).unwrap();
    let out = tmp.path().join("out");
    refused(
        &mut inspect(&case().path("reference.ply"), &out, &["--pose", arg(&pose)]),
        &["registration.json", "--pose", "\"failed\""],
    );
}

#[test]
fn a_reference_in_metres_read_as_millimetres_against_a_millimetre_scan_names_units() {
    let tmp = common::tempdir();
    let metres = edited_reference(tmp.path(), "reference_m.ply", |c| {
        c.points.iter_mut().for_each(|p| *p *= 1e-3);
    });
    // --units m makes the reference right and the millimetre scan 1000 times too large.
    let out = tmp.path().join("out");
    refused(
        &mut inspect(&metres, &out, &["--units", "m"]),
        &["scan.ply", "--units", "ratio"],
    );
}

#[test]
fn inward_reference_normals_are_turned_round_and_mixed_ones_refused() {
    let c = case();
    let tmp = common::tempdir();
    let truth = c.path("truth.json");
    let pose = ["--pose", arg(&truth)];
    let straight = tmp.path().join("straight");
    succeed(&mut inspect(&c.path("reference.ply"), &straight, &pose));
    let inward = edited_reference(tmp.path(), "inward.ply", |c| {
        c.normals
            .as_mut()
            .unwrap()
            .iter_mut()
            .for_each(|n| *n = -*n);
    });
    let turned = tmp.path().join("turned");
    let out = succeed(&mut inspect(&inward, &turned, &pose));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("inward.ply") && err.contains("turned round"),
        "{err}"
    );
    // A bump stays a bump: the same regions with the same signed peaks as the straight run.
    assert_eq!(peaks(&turned), peaks(&straight));
    assert!(peaks(&straight).iter().any(|p| *p > 0.0));
    // Half the part (x above its median) inward, half outward.
    let mixed = edited_reference(tmp.path(), "mixed.ply", |c| {
        let mut xs: Vec<f64> = c.points.iter().map(|p| p.x).collect();
        let mid = xs.len() / 2;
        let median = *xs.select_nth_unstable_by(mid, f64::total_cmp).1;
        let n = c.normals.as_mut().unwrap();
        for (p, n) in c.points.iter().zip(n.iter_mut()) {
            if p.x > median {
                *n = -*n;
            }
        }
    });
    refused(
        &mut inspect(&mixed, &tmp.path().join("mixed"), &pose),
        &["mixed.ply", "not consistently oriented"],
    );
}

#[test]
fn a_reference_without_normals_gets_estimated_ones_as_the_help_says() {
    let help = succeed(polishbot().args(["inspect", "--help"]));
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(help.contains("without normals gets PCA normals"), "{help}");
    let tmp = common::tempdir();
    let bare = edited_reference(tmp.path(), "bare.ply", |c| c.normals = None);
    let truth = case().path("truth.json");
    let pose = ["--pose", arg(&truth)];
    let out = succeed(&mut inspect(&bare, &tmp.path().join("out"), &pose));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bare.ply") && err.contains("has no normals: estimated"),
        "{err}"
    );
    // The same part with its own (correct) normals measures at least as well (issue 52: a
    // reference with normals must inspect as accurately as without): each of its regions
    // (the three bumps) is one of the estimated run's, its peak within 0.02 mm (a tenth of
    // the smallest bump), and no more regions (the estimated normals add 0.06-0.09 mm ones).
    let own = tmp.path().join("own");
    succeed(&mut inspect(&case().path("reference.ply"), &own, &pose));
    let (a, b) = (peaks(&own), peaks(&tmp.path().join("out")));
    assert!(a.len() == 3 && a.len() <= b.len(), "{a:?} {b:?}");
    assert!(
        a.iter().all(|x| b.iter().any(|y| (x - y).abs() < 0.02)),
        "{a:?} {b:?}"
    );
}

#[test]
fn a_bad_normal_names_the_file_and_the_point_and_the_core_file_is_not_the_reference() {
    let tmp = common::tempdir();
    let bad = edited_reference(tmp.path(), "bad_normal.ply", |c| {
        c.normals.as_mut().unwrap()[0] *= 2.0;
    });
    let truth = case().path("truth.json");
    let pose = ["--pose", arg(&truth)];
    refused(
        &mut inspect(&bad, &tmp.path().join("a"), &pose),
        &["bad_normal.ply", "reference point 0", "not a unit vector"],
    );
    let core = edited_reference(tmp.path(), "core.ply", |c| {
        c.points.truncate(50);
        let n = c.normals.as_mut().unwrap();
        n.truncate(50);
        n[7] *= 0.5;
    });
    let extra = [pose[0], pose[1], "--core", arg(&core)];
    let line = refused(
        &mut inspect(&case().path("reference.ply"), &tmp.path().join("b"), &extra),
        &["core.ply", "--core file point 7", "not a unit vector"],
    );
    assert!(!line.contains("the reference"), "{line}");
}

/// Writes `text` as a config file and returns its path.
fn config(tmp: &Path, text: &str) -> PathBuf {
    let path = tmp.join("settings.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn config_errors_name_the_file_the_line_and_the_key() {
    let tmp = common::tempdir();
    let plan = case().path("plan.json");
    let cases: [(&str, &[&str], &[&str]); 7] = [
        (
            "[bus]\nframe_gap_ms = 10\nsettle_ms = 1e300\n",
            &["arm", "read", "--sim"],
            &["line 3", "`settle_ms`", "ms"],
        ),
        (
            "[sim.timing]\n\nbaud = 0.0\n",
            &["arm", "read", "--sim"],
            &["line 3", "`baud`"],
        ),
        (
            "[bus]\nattempts = -1\n",
            &["arm", "read", "--sim"],
            &["line 2"],
        ),
        (
            "[bus]\nsettle_ms = \"soon\"\n",
            &["arm", "read", "--sim"],
            &["line 2"],
        ),
        (
            "[bus\nsettle_ms = 3\n",
            &["arm", "read", "--sim"],
            &["line 1"],
        ),
        (
            "[run]\nsettle_ms = 1e300\n",
            &["run", "--dry-run", "--plan", arg(&plan)],
            &["line 2", "[run]", "`settle_ms`"],
        ),
        (
            "reference_points = 7\n[compare]\nmethd = \"classic\"\n",
            &pair_args("inspect"),
            &["line 3", "unknown key `compare.methd`"],
        ),
    ];
    for (text, args, needles) in cases {
        let file = config(tmp.path(), text);
        let mut cmd = polishbot();
        cmd.arg("--config").arg(&file).args(args);
        let mut needles = needles.to_vec();
        needles.push("settings.toml");
        refused(&mut cmd, &needles);
    }
}

#[test]
fn absurd_arm_move_times_are_refused_without_a_panic() {
    for t in ["1e300", "-1", "NaN"] {
        let time = format!("--time={t}");
        refused(
            polishbot().args(["arm", "move", "--sim", "--joints", "0,0,0,0,0", &time]),
            &["--time"],
        );
    }
}

/// `plan` of `insp` with the settings `text`, into a fresh plan file under `tmp`.
fn plan(tmp: &Path, insp: &Path, text: &str) -> Command {
    let cfg = config(tmp, text);
    let mut cmd = polishbot();
    cmd.arg("--config")
        .arg(cfg)
        .args(["plan", "--inspection", arg(insp), "-o"])
        .arg(tmp.join("plan.json"));
    cmd
}

#[test]
fn plan_settings_out_of_range_are_refused_at_their_line() {
    let insp = case().path("inspection");
    let tmp = common::tempdir();
    for (text, key) in [
        ("[plan]\n\nallowance_mm = -1\n", "`allowance_mm`"),
        ("[plan]\n\ndepth_step_mm = 1e-9\n", "`depth_step_mm`"),
        ("[plan]\n\nspacing_mm = 1e-9\n", "`spacing_mm`"),
    ] {
        refused(&mut plan(tmp.path(), &insp, text), &["line 3", key, "mm"]);
    }
}

/// A copy of the case's inspection folder with regions.json's first repairable region (and
/// deviations.csv's text) edited.
fn tampered(
    tmp: &Path,
    region: impl FnOnce(&mut Value),
    csv: impl FnOnce(String) -> String,
) -> PathBuf {
    let from = case().path("inspection");
    let dir = tmp.join("inspection");
    std::fs::create_dir_all(&dir).unwrap();
    let mut regions = read_json(&from.join("regions.json"));
    let list = regions["regions"].as_array_mut().unwrap();
    region(
        list.iter_mut()
            .find(|r| r["repairable"] == true)
            .expect("a repairable region"),
    );
    std::fs::write(dir.join("regions.json"), regions.to_string()).unwrap();
    let text = std::fs::read_to_string(from.join("deviations.csv")).unwrap();
    std::fs::write(dir.join("deviations.csv"), csv(text)).unwrap();
    dir
}

/// An edit of a region of regions.json.
type RegionEdit = Box<dyn FnOnce(&mut Value)>;
/// An edit of deviations.csv's text.
type CsvEdit = Box<dyn FnOnce(String) -> String>;

#[test]
fn an_inspection_whose_files_contradict_each_other_is_refused() {
    let keep = |t: String| t;
    let cases: Vec<(RegionEdit, CsvEdit, &str)> = vec![
        (
            Box::new(|r| r["peak"] = 1e6.into()),
            Box::new(keep),
            "layers",
        ),
        (
            Box::new(|r| r["peak"] = (-r["peak"].as_f64().unwrap()).into()),
            Box::new(keep),
            "repairable",
        ),
        (
            Box::new(|r| {
                r["peak"] = (-r["peak"].as_f64().unwrap()).into();
                r["repairable"] = false.into();
            }),
            Box::new(keep),
            "differ in sign",
        ),
        (Box::new(|r| r["area"] = 1e9.into()), Box::new(keep), "area"),
        (
            Box::new(|_| {}),
            Box::new(|t: String| {
                let mut lines: Vec<String> = t.lines().map(str::to_string).collect();
                let last = lines.last_mut().unwrap();
                let cut = last.rfind(',').unwrap();
                last.replace_range(cut.., ",77");
                lines.join("\n") + "\n"
            }),
            "region 77",
        ),
    ];
    for (region, csv, needle) in cases {
        let tmp = common::tempdir();
        let insp = tampered(tmp.path(), region, csv);
        refused(
            &mut plan(
                tmp.path(),
                &insp,
                "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n",
            ),
            &["inspection", needle],
        );
    }
}

#[test]
fn a_core_point_far_away_in_a_region_is_refused_at_once() {
    let tmp = common::tempdir();
    let mut id = 0;
    let insp = tampered(tmp.path(), |r| id = r["id"].as_i64().unwrap(), |t| t);
    // Move one row of that region 5 m away: regions.json no longer describes it.
    let csv = insp.join("deviations.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut done = false;
    let edited: Vec<String> = text
        .lines()
        .map(|l| match !done && l.ends_with(&format!(",{id}")) {
            true => {
                done = true;
                let rest = l.split_once(',').unwrap().1;
                format!("5000,{rest}")
            }
            false => l.to_string(),
        })
        .collect();
    assert!(done);
    std::fs::write(&csv, edited.join("\n") + "\n").unwrap();
    refused(
        &mut plan(
            tmp.path(),
            &insp,
            "[plan]\nmode = \"rigid\"\ndepth_step_mm = 1.0\n",
        ),
        &["regions.json", "regions["],
    );
}

/// `run --dry-run` of the case's plan with `extra` arguments.
fn dry_run(extra: &[&str]) -> Command {
    let mut cmd = polishbot();
    cmd.args([
        "run",
        "--dry-run",
        "--sim",
        "--plan",
        arg(&case().path("plan.json")),
    ])
    .args(extra);
    cmd
}

#[test]
fn a_journal_is_tied_to_its_plan_and_a_garbage_journal_is_an_error() {
    let c = case();
    let tmp = common::tempdir();
    let journal = tmp.path().join("journal.jsonl");
    let out = succeed(polishbot().args([
        "run",
        "--sim",
        "--plan",
        arg(&c.path("plan.json")),
        "--journal",
        arg(&journal),
    ]));
    assert!(out.status.success());
    let text = std::fs::read_to_string(&journal).unwrap();
    let open: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
    let sha = open["plan_sha256"]
        .as_str()
        .expect("plan_sha256 on the open line");
    assert_eq!(sha.len(), 64);
    // The same plan resumes (from its last frame); a plan differing by one byte does not.
    succeed(&mut dry_run(&["--resume", arg(&journal)]));
    let other = tmp.path().join("other.json");
    let plan_text = std::fs::read_to_string(c.path("plan.json")).unwrap();
    std::fs::write(&other, format!("{plan_text}\n")).unwrap();
    refused(
        polishbot().args([
            "run",
            "--dry-run",
            "--sim",
            "--plan",
            arg(&other),
            "--resume",
            arg(&journal),
        ]),
        &["journal.jsonl", "another plan"],
    );
    // A journal claiming a frame beyond the plan.
    let far = tmp.path().join("far.jsonl");
    let tx = format!(
        "{}\n{{\"seq\":1,\"t\":0.1,\"unix_ms\":0,\"kind\":\"tx\",\"motion\":999999}}\n",
        text.lines().next().unwrap()
    );
    std::fs::write(&far, tx).unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&far)]),
        &["far.jsonl", "frame 999999"],
    );
    // Garbage, a journal without a plan hash, and a cut line in the middle.
    let garbage = tmp.path().join("garbage.jsonl");
    std::fs::write(&garbage, "this is not a journal\n").unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&garbage)]),
        &["garbage.jsonl", "line 1"],
    );
    let old = tmp.path().join("old.jsonl");
    std::fs::write(
        &old,
        text.replace(&format!(",\"plan_sha256\":\"{sha}\""), ""),
    )
    .unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&old)]),
        &["old.jsonl", "no plan SHA-256"],
    );
    let cut = tmp.path().join("cut.jsonl");
    let lines: Vec<&str> = text.lines().collect();
    std::fs::write(
        &cut,
        format!("{}\n{{\"seq\":1,\"t\n{}\n", lines[0], lines[1]),
    )
    .unwrap();
    refused(
        &mut dry_run(&["--resume", arg(&cut)]),
        &["cut.jsonl", "line 2"],
    );
}

#[test]
fn calibrate_verify_with_no_targets_is_an_error() {
    let tmp = common::tempdir();
    let targets = tmp.path().join("targets.txt");
    std::fs::write(&targets, "# no poses\n\n").unwrap();
    refused(
        polishbot()
            .args([
                "calibrate",
                "verify",
                "--sim",
                "--targets",
                arg(&targets),
                "--out",
            ])
            .arg(tmp.path()),
        &["targets.txt", "no joint targets"],
    );
}

#[test]
fn synth_refuses_nan_and_absurd_settings_up_front() {
    let tmp = common::tempdir();
    let out = tmp.path().join("case");
    for (flag, value, key) in [
        ("--noise", "NaN", "`noise`"),
        ("--reference-points", "100000000000", "`reference_points`"),
        ("--max-translation", "1e300", "`max_translation`"),
    ] {
        refused(
            polishbot().args(["synth", "--out", arg(&out), flag, value]),
            &[key],
        );
        assert!(
            !out.join("reference.ply").exists(),
            "{flag} {value} wrote files"
        );
    }
    let cfg = config(tmp.path(), "[shape]\nwidth = 64\ngroove_sigma = nan\n");
    refused(
        polishbot()
            .arg("--config")
            .arg(&cfg)
            .args(["synth", "--out", arg(&out)]),
        &["settings.toml", "line 3", "`groove_sigma`"],
    );
}

#[test]
fn calibration_files_come_from_the_working_directory_not_the_source_tree() {
    let tmp = common::tempdir();
    let out = polishbot()
        .current_dir(tmp.path())
        .args(["arm", "read", "--sim"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "ran without ./calibration/: {err}");
    assert!(err.contains("calibration/"), "{err}");
    assert!(!err.contains(env!("CARGO_MANIFEST_DIR")), "{err}");
}

/// The femoral component of `femoral_dm.stl` (shared data, metres) sampled with `n` points
/// and its facet normals (outward: the mesh is closed and oriented by its volume).
fn femoral_dm(file: &str, n: usize, seed: u64) -> PointCloud {
    let path = common::shared_data(file);
    let cloud::Geometry::Mesh { mut mesh, .. } = cloud::load(&path, None, Some(cloud::Units::M))
        .unwrap()
        .geometry
    else {
        panic!("{file} is a mesh")
    };
    if file == "femoral_dm.stl" {
        mesh.orient_outward();
    }
    cloud::sample_mesh(&mesh, n, seed).unwrap().cloud
}

/// `orient_outward` on a copy of `c`: Ok(true) when kept as it is, Ok(false) when turned
/// round, Err(message) when refused.
fn orientation(c: &PointCloud) -> Result<bool, String> {
    let mut c2 = c.clone();
    match polishbot::inspect::checks::orient_outward(Path::new("thin.ply"), &mut c2) {
        Ok(None) => {
            assert_eq!(c2.normals, c.normals, "changed without a note");
            Ok(true)
        }
        Ok(Some(note)) => {
            assert!(
                note.contains("thin.ply") && note.contains("turned round"),
                "{note}"
            );
            Ok(false)
        }
        Err(e) => Err(e.to_string()),
    }
}

fn flipped(c: &PointCloud, which: impl Fn(usize, &nalgebra::Point3<f64>) -> bool) -> PointCloud {
    let mut f = c.clone();
    for (i, (p, n)) in c.points.iter().zip(f.normals.as_mut().unwrap()).enumerate() {
        if which(i, p) {
            *n = -*n;
        }
    }
    f
}

/// The thin-walled reference: the femoral component's outer (articular) surface and
/// its inner box cuts, a 3-6 mm wall apart, sampled with correct outward normals as CAD
/// sampling tools export them (issue 52: refused at 20k points, "65 % agree"). Kept as it is
/// at any density; turned round when every normal points in; refused when the box cuts alone
/// point in. The same with two parallel sheets (the articular surface and a copy 6 mm / 3 mm
/// behind it, facing away from the material between them): kept, and refused with one whole
/// sheet or one patch turned in.
#[test]
fn a_thin_walled_reference_with_correct_normals_is_kept_and_a_flipped_sheet_refused() {
    let contact = femoral_dm("femoral_dm_contact.stl", 50_000, 9);
    let on_contact = polishbot::spatial::Neighbours::new(&contact.points);
    for (n, seed) in [(4_000, 1), (20_000, 2), (100_000, 3)] {
        let c = femoral_dm("femoral_dm.stl", n, seed);
        assert_eq!(orientation(&c), Ok(true), "{n} points");
        assert_eq!(orientation(&flipped(&c, |_, _| true)), Ok(false), "{n}");
        // The box cuts (points over 1 mm from the articular surface) turned in.
        let cuts = flipped(&c, |_, p| on_contact.nearest(p).unwrap().dist2 > 1.0);
        let err = orientation(&cuts).unwrap_err();
        assert!(err.contains("thin.ply: reference normals"), "{n}: {err}");
    }
    for (wall_mm, n, seed) in [(6.0, 20_000, 4), (3.0, 40_000, 5)] {
        let mut c = femoral_dm("femoral_dm_contact.stl", n / 2, seed);
        let normals = c.normals.clone().unwrap();
        for (p, m) in c.points.clone().iter().zip(&normals) {
            c.points.push(p - wall_mm * m);
            c.normals.as_mut().unwrap().push(-m);
        }
        let half = c.len() / 2;
        assert_eq!(orientation(&c), Ok(true), "{wall_mm} mm, {n} points");
        assert_eq!(orientation(&flipped(&c, |_, _| true)), Ok(false));
        let inner = orientation(&flipped(&c, |i, _| i >= half)).unwrap_err();
        assert!(
            inner.contains("point into the material on one sheet"),
            "{inner}"
        );
        let patch = orientation(&flipped(&c, |i, p| i < half && p.x > 10.0)).unwrap_err();
        assert!(patch.contains("not consistently oriented"), "{patch}");
    }
}

/// The hang list, inspect side: `--tolerance 0` is refused at its floor; the floor
/// itself (0.01 mm: regions all over the part's noise) gets an answer from inspect and from
/// plan over all its regions (issue 52: 19 s, then plan past 200 s); a 100-point scan with
/// `--pose` is refused as too sparse by both methods (was 65 s, classic past 45 s); `--units
/// m` on millimetre files names the scan's spacing, not a 309-digit `depth_step_mm`.
#[test]
fn tolerance_at_its_floor_sparse_scans_and_a_unit_slip_answer() {
    let c = case();
    let tmp = common::tempdir();
    let truth = c.path("truth.json");
    let pose = ["--pose", arg(&truth)];
    refused(
        &mut inspect(
            &c.path("reference.ply"),
            &tmp.path().join("t0"),
            &["--tolerance", "0"],
        ),
        &[
            "--tolerance",
            "`tolerance` = 0.0 mm is outside 0.01..=10.0 mm",
        ],
    );
    let floor = tmp.path().join("floor");
    let mut cmd = inspect(
        &c.path("reference.ply"),
        &floor,
        &[&pose[..], &["--tolerance", "0.01"]].concat(),
    );
    let out = cmd.output().unwrap();
    assert!(matches!(out.status.code(), Some(0 | 3)), "{out:?}");
    let regions = read_json(&floor.join("regions.json"))["regions"]
        .as_array()
        .unwrap()
        .len();
    assert!(regions > 20, "{regions} regions at 0.01 mm");
    let plan = tmp.path().join("plan.json");
    let mut cmd = polishbot();
    cmd.arg("--config").arg(c.path("plan.toml"));
    succeed(cmd.args(["plan", "--inspection", arg(&floor), "-o", arg(&plan)]));
    // Every 1,500th point of the scan: 100 points.
    let sparse = {
        let mut s = cloud::load_cloud(&c.path("scan.ply"), None, None).unwrap();
        s.points = s.points.iter().step_by(s.len() / 100).copied().collect();
        s.normals = None;
        s.fields.clear();
        let path = tmp.path().join("s100.ply");
        cloud::write_ply(&path, &s, None, PlyPrecision::F64).unwrap();
        path
    };
    for method in [&[][..], &["--method", "classic"][..]] {
        let mut cmd = polishbot();
        cmd.args([
            "inspect",
            "--reference",
            arg(&c.path("reference.ply")),
            "--scan",
        ])
        .arg(&sparse)
        .args(["-o", arg(&tmp.path().join("sparse"))])
        .args(pose)
        .args(method);
        refused(&mut cmd, &["s100.ply", "too sparse"]);
    }
    let line = refused(
        &mut inspect(
            &c.path("reference.ply"),
            &tmp.path().join("m"),
            &["--units", "m"],
        ),
        &["scan.ply"],
    );
    assert!(
        !line.contains("config") && !line.contains("depth_step_mm"),
        "{line}"
    );
    assert!(
        line.split(|ch: char| !ch.is_ascii_digit())
            .all(|d| d.len() <= 12),
        "{line}"
    );
}

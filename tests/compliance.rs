//! `calibrate compliance` against planted truth (issue 50 acceptance): the simulated arm
//! carries a joint stiffness and per-joint backlash (the simulator's own model and masses,
//! src/sim/grind/slack.rs); the simulated operator touches the built-in poses through the
//! bus; the fit must recover the stiffness within 10 % and the backlash within 0.1 degree for
//! every joint the touches observe, on a worn arm and on the documented default arm.
mod common;

use polishbot::calibrate::compliance::FITTED_JOINTS;
use polishbot::sim::grind::slack;
use polishbot::sim::GrindConfig;

/// A worn arm: 1.5 times the documented sag (a softer arm) and uneven backlash.
fn planted() -> GrindConfig {
    GrindConfig {
        sag_full_reach_mm: 7.5,
        backlash_deg: [0.8, 0.35, 0.65, 0.9, 0.5],
        ..GrindConfig::default()
    }
}

/// The simulator's default arm with `band_deg` of backlash on every joint and `sag_mm` of sag
/// at full reach.
fn even(band_deg: f64, sag_mm: f64) -> GrindConfig {
    GrindConfig {
        sag_full_reach_mm: sag_mm,
        backlash_deg: [band_deg; 5],
        ..GrindConfig::default()
    }
}

/// Fits on the arm `truth` and checks every observed joint against the planted values.
fn recovers(truth: &GrindConfig) {
    let stiffness = slack::Arm::new(truth).stiffness_nm_rad();
    let (_, fit) = common::compensation::run_fit(truth);
    let c = &fit.compliance;
    eprintln!(
        "true stiffness {stiffness:.1} N m/rad, fitted {:.1?} (sd {:.1?}); true backlash {:?}, \
         fitted {:.3?} (sd {:.3?}); masses {:.3?}; rms {:.3} mm, {} set aside",
        c.stiffness_nm_rad,
        fit.stiffness_sd,
        truth.backlash_deg,
        c.backlash_deg,
        fit.backlash_sd,
        c.masses_kg,
        fit.rms_mm,
        fit.set_aside
    );
    for k in 0..FITTED_JOINTS {
        let rel = c.stiffness_nm_rad[k] / stiffness - 1.0;
        assert!(
            rel.abs() <= 0.10,
            "joint {}: stiffness {:.1} N m/rad, true {stiffness:.1} ({:+.1} %)",
            k + 1,
            c.stiffness_nm_rad[k],
            rel * 100.0
        );
        let off = c.backlash_deg[k] - truth.backlash_deg[k];
        assert!(
            off.abs() <= 0.1,
            "joint {}: backlash {:.3} deg, true {} ({off:+.3})",
            k + 1,
            c.backlash_deg[k],
            truth.backlash_deg[k]
        );
    }
}

#[test]
fn compliance_calibration_recovers_planted_stiffness_and_backlash() {
    recovers(&planted());
}

#[test]
fn compliance_calibration_recovers_the_documented_arm() {
    // the simulator's defaults: 0.5 deg everywhere, 5 mm of sag at full reach
    recovers(&GrindConfig::default());
}

#[test]
fn compliance_calibration_recovers_an_arm_with_one_degree_of_backlash() {
    // shared/DOFBOT.md's "up to 1 deg per servo" on every joint (issue 50's acceptance runs the
    // loop on it): the fit's second pass ran off to 110 mm RMS before the best round stood
    recovers(&GrindConfig {
        backlash_deg: [1.0; 5],
        ..GrindConfig::default()
    });
}

/// shared/DOFBOT.md's upper sag, "5..10 mm at full reach", with the documented 0.5 degree
/// bands (issue 50: a user's arm may be there): refused on main (24 mm RMS) because the
/// simulated operator, holding the listed servo tilt, recorded touches 1-4 mm beside points
/// the loaded arm could not reach at that tilt, and the first fit ran off on them.
#[test]
fn compliance_calibration_recovers_an_arm_with_ten_millimetres_of_sag() {
    recovers(&even(0.5, 10.0));
}

/// A worn arm: DOFBOT.md's 1 degree on every joint with 7.5 mm of sag. Refused on main (8 mm
/// RMS); with the operator's tilt relaxed the fit settled but the elbow's and wrist pitch's
/// bands came out 0.909 and 1.108 degrees (the pitch joints' gears crossed their bands
/// together under every load), hence the two load directions that turn them apart.
#[test]
fn compliance_calibration_recovers_a_worn_arm_with_one_degree_and_seven_and_a_half_mm() {
    recovers(&even(1.0, 7.5));
}

/// DOFBOT.md's worst arm on both counts: 1 degree on every joint and 10 mm of sag at full
/// reach (refused on main at 103 mm RMS).
#[test]
fn compliance_calibration_recovers_the_worst_documented_arm() {
    recovers(&even(1.0, 10.0));
}

#[test]
fn calibrate_compliance_cli_writes_the_fitted_table_into_servos_toml() {
    let dir = tempfile::tempdir().unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_polishbot"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(["calibrate", "compliance", "--sim", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{stdout}");
    for k in 1..=FITTED_JOINTS {
        assert!(
            stdout.contains(&format!("joint {k}: stiffness ")) && stdout.contains("deg"),
            "{stdout}"
        );
    }
    assert!(stdout.contains("RMS"), "{stdout}");
    let written = dir.path().join("servos.toml");
    let text = std::fs::read_to_string(&written).unwrap();
    // every line of the shipped file outside its [compliance] table is kept
    let shipped_text = std::fs::read_to_string(common::calib("servos.toml")).unwrap();
    let before = shipped_text.split("\n[compliance]").next().unwrap();
    for line in before.lines().filter(|l| !l.trim().is_empty()) {
        assert!(text.contains(line), "line {line:?} lost");
    }
    let servos = polishbot::robot::Servos::load(&written).unwrap();
    let c = servos.compliance.expect("[compliance] written");
    let truth = GrindConfig::default();
    let stiffness = slack::Arm::new(&truth).stiffness_nm_rad();
    for k in 0..FITTED_JOINTS {
        assert!(
            (c.stiffness_nm_rad[k] / stiffness - 1.0).abs() <= 0.10,
            "joint {}: {:?} against {stiffness}",
            k + 1,
            c.stiffness_nm_rad
        );
        assert!(
            (c.backlash_deg[k] - truth.backlash_deg[k]).abs() <= 0.1,
            "joint {}: {:?}",
            k + 1,
            c.backlash_deg
        );
    }
}

/// `polishbot calibrate ROUTINE --sim` on the shipped cell with `[sim.grinding]` lines
/// `grinding` (the simulated arm), reading and writing the cell's files in `out`.
fn calibrate_sim(routine: &str, grinding: &str, out: &std::path::Path) -> std::process::Output {
    let cfg = out.join(format!("{routine}-sim.toml"));
    std::fs::write(&cfg, format!("[sim.grinding]\n{grinding}\n")).unwrap();
    common::polishbot()
        .args(["calibrate", routine, "--sim", "--cell"])
        .arg(common::calib(""))
        .arg("--out")
        .arg(out)
        .arg("--config")
        .arg(&cfg)
        .output()
        .unwrap()
}

/// The scatter with and without the table on `calibrate verify`'s verdict line.
fn verdict(stdout: &str) -> (f64, f64) {
    let line = stdout
        .lines()
        .find(|l| l.contains("[compliance]: loaded touch-offs scatter"))
        .unwrap_or_else(|| panic!("no verdict: {stdout}"));
    let words: Vec<&str> = line.split_whitespace().collect();
    let at = |w: &str, by: isize| -> f64 {
        let i = words.iter().position(|x| x.starts_with(w)).unwrap();
        words[(i as isize + by) as usize].parse().unwrap()
    };
    (at("scatter", 1), at("without", -2))
}

/// The guard (issue 50: the compliance table must be the cell's own): `calibrate verify` on the
/// simulated ideal arm (no backlash, no sag) with the shipped cell's table, which was learned
/// on the documented arm, refuses it in one line naming servos.toml, `[compliance]` and the
/// bound; on the documented arm the same table passes, and so does the table `calibrate
/// compliance` measures on the ideal arm itself. The verdict comes from the read-back joints
/// and the applied loads only.
#[test]
fn calibrate_verify_refuses_a_compliance_table_the_arm_contradicts() {
    let ideal = "ideal_arm = true";
    let dir = common::tempdir();
    let out = calibrate_sim("verify", ideal, dir.path());
    let line = common::one_line_failure(&out);
    eprintln!("ideal arm, shipped table: {line}");
    for want in ["servos.toml", "[compliance]", "max_compliance_check_rms_mm"] {
        assert!(line.contains(want), "{want}: {line}");
    }
    let (with, without) = verdict(&String::from_utf8_lossy(&out.stdout));
    assert!(with > 0.3 && without < with, "{with} / {without}");

    // the documented arm (the simulator's default) with the same table
    let dir = common::tempdir();
    let out = calibrate_sim("verify", "", dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("{stdout}");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (with, without) = verdict(&stdout);
    eprintln!("documented arm, shipped table: {with} mm with, {without} mm without");
    assert!(with < 0.3 && with < without, "{with} / {without}");

    // the ideal arm with the table measured on it
    let dir = common::tempdir();
    let fit = calibrate_sim("compliance", ideal, dir.path());
    let stdout = String::from_utf8_lossy(&fit.stdout);
    eprintln!("{stdout}");
    assert!(
        fit.status.success(),
        "{}",
        String::from_utf8_lossy(&fit.stderr)
    );
    let out = calibrate_sim("verify", ideal, dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (with, without) = verdict(&stdout);
    eprintln!("ideal arm, its own table: {with} mm with, {without} mm without");
    assert!(with < 0.3, "{with} / {without}");
}

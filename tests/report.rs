//! The report renders, and every image loads in a real browser (headless Chromium).
mod common;

use std::process::Command;

use common::{in_ci, tempdir};
use polishbot::report::{write_report, ReportConfig, ReportInput, Table};
use polishbot::synth::{synth, SynthConfig};

/// A report of true deviations on a synthetic part.
fn make_report(dir: &std::path::Path) {
    let case = synth(&SynthConfig {
        reference_points: 150_000,
        scan_points: 1_000,
        seed: 2,
        ..SynthConfig::default()
    })
    .unwrap();
    let normals = case.reference.normals.clone().unwrap();
    let mut distances: Vec<f64> = case
        .reference
        .points
        .iter()
        .zip(&normals)
        .map(|(p, n)| case.truth.deviation_at(p, n))
        .collect();
    distances[0] = f64::NAN;
    let input = ReportInput {
        title: "polishbot inspection: synthetic part".into(),
        points: &case.reference.points,
        normals: &normals,
        distances: &distances,
        tolerance: 0.05,
        summary: vec![
            ("verdict".into(), "repairable".into()),
            ("registration".into(), "fitness 1.0 <script>".into()),
        ],
        tables: vec![Table {
            title: "regions".into(),
            header: vec!["id".into(), "peak mm".into()],
            rows: vec![vec!["0".into(), "0.31".into()]],
        }],
        labels: &[],
        regions: Vec::new(),
        provenance: None,
    };
    let files = write_report(dir, &input, &ReportConfig::default()).unwrap();
    assert_eq!(files.figures.len(), 2);
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert!(
        html.contains("&lt;script&gt;"),
        "summary text must be escaped"
    );
    assert!(
        !html.contains("http://") && !html.contains("https://"),
        "the report must work offline"
    );
}

fn chromium() -> Option<String> {
    for c in ["chromium", "chromium-browser"] {
        if Command::new(c)
            .arg("--version")
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false)
        {
            return Some(c.to_string());
        }
    }
    assert!(
        !in_ci(),
        "chromium is missing: scripts/test.sh installs it; the report test must run in CI"
    );
    eprintln!("skipping: no chromium (run scripts/test.sh)");
    None
}

const FLAGS: [&str; 10] = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--allow-file-access-from-files",
    "--virtual-time-budget=10000",
];

#[test]
fn every_image_of_the_report_loads_in_chromium() {
    let dir = tempdir();
    make_report(dir.path());
    let Some(browser) = chromium() else { return };
    // The page itself plus a probe that records whether every image decoded.
    let page = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    let probe = "<script>window.addEventListener('load',()=>{const i=[...document.images];\
document.body.setAttribute('data-images',i.length);\
document.body.setAttribute('data-loaded',i.filter(x=>x.complete&&x.naturalWidth>0).length);});</script></body>";
    std::fs::write(
        dir.path().join("probe.html"),
        page.replace("</body>", probe),
    )
    .unwrap();
    let profile = tempdir();
    let url = format!("file://{}", dir.path().join("probe.html").display());
    let out = Command::new(&browser)
        .args(FLAGS)
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .args(["--dump-dom", &url])
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&out.stdout);
    assert!(
        dom.contains("data-images=\"2\""),
        "images not counted: {}",
        &dom[..dom.len().min(400)]
    );
    assert!(
        dom.contains("data-loaded=\"2\""),
        "not every image loaded: {}",
        &dom[..dom.len().min(400)]
    );
    // A screenshot to look at (kept when POLISHBOT_KEEP_SCREENSHOT names a path).
    if let Some(keep) = std::env::var_os("POLISHBOT_KEEP_SCREENSHOT") {
        let url = format!("file://{}", dir.path().join("report.html").display());
        let shot = Command::new(&browser)
            .args(FLAGS)
            .arg(format!("--user-data-dir={}", profile.path().display()))
            .args([
                "--window-size=1720,1500",
                &format!("--screenshot={}", std::path::Path::new(&keep).display()),
                &url,
            ])
            .output()
            .unwrap();
        assert!(
            shot.status.success(),
            "{}",
            String::from_utf8_lossy(&shot.stderr)
        );
    }
}

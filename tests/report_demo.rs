//! The demo's report in a real browser (headless Chromium): the viewer renders, every image
//! loads, nothing is asked of the network, it prints; and its plan and cycle pages load.
mod common;

use common::chromium::{assert_local_only, attr, chromium, chromium_run, dump_dom, probe};
use common::tempdir;

/// Share of non-white pixels of a PNG screenshot, and how many of them are clearly red
/// (material in excess) or blue (below nominal).
fn screenshot_shares(path: &std::path::Path) -> (f64, usize) {
    let decoder = png::Decoder::new(std::fs::File::open(path).unwrap());
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).unwrap();
    let step = info.color_type.samples();
    let px = &buf[..info.buffer_size()];
    let (mut drawn, mut strong, mut total) = (0usize, 0usize, 0usize);
    for p in px.chunks(step) {
        let (r, g, b) = (p[0] as i32, p[1] as i32, p[2] as i32);
        total += 1;
        drawn += usize::from(r.min(g).min(b) < 235);
        strong += usize::from(r > g + 60 && r > b + 60 || b > r + 60);
    }
    (drawn as f64 / total as f64, strong)
}

/// Counts `needle` in `hay` (bytes).
fn count(hay: &[u8], needle: &[u8]) -> usize {
    hay.windows(needle.len()).filter(|w| *w == needle).count()
}

/// The acceptance test of issue 31 on the demo's report: the viewer renders (its self-check
/// and a screenshot), every region is numbered in a figure, every image loads, nothing is
/// asked of the network, no script error; print-to-PDF gives pages with the figures.
#[test]
fn the_demo_report_works_offline_in_chromium_and_prints() {
    let Some(browser) = chromium() else { return };
    let dir = tempdir();
    let out = dir.path().join("demo");
    let demo = common::succeed(
        common::polishbot()
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["demo", "--out"])
            .arg(&out),
    );
    let insp = out.join("inspection");
    let regions: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(insp.join("regions.json")).unwrap()).unwrap();
    let ids: Vec<u64> = regions["regions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].as_u64().unwrap())
        .collect();
    assert!(ids.len() >= 5, "the demo plants five defects: {ids:?}");
    let (page, figures) = report_page_loads(&browser, dir.path(), &insp, &ids);
    let planned = planned_regions(&out, &ids);
    plan_page_loads(&browser, &out, &planned);
    cycle_page_loads(&browser, &out, &String::from_utf8_lossy(&demo.stdout));
    viewer_draws_the_part(&browser, dir.path(), &insp, &page);
    prints_on_a4(&browser, dir.path(), &insp, figures);
}

/// The inspection report `insp` of the demo with the probe, in the browser: the viewer's
/// self-check read every deviation row, no script error, a figure per region besides the
/// overview and the histogram and every one decoded, every region numbered on the overview and
/// on its close-up, nothing asked of the network (`tmp`: the net log's folder). Returns the
/// page and its number of figures.
fn report_page_loads(
    browser: &str,
    tmp: &std::path::Path,
    insp: &std::path::Path,
    ids: &[u64],
) -> (String, usize) {
    let rows = std::fs::read_to_string(insp.join("deviations.csv"))
        .unwrap()
        .lines()
        .count()
        - 1;
    let page = std::fs::read_to_string(insp.join("report.html")).unwrap();
    std::fs::write(insp.join("probe.html"), probe(&page)).unwrap();
    let netlog = tmp.join("netlog.json");
    let dom = dump_dom(browser, &insp.join("probe.html"), &netlog);
    assert_eq!(
        attr(&dom, "id=\"viewer-check\"", "data-ok"),
        "true",
        "{dom}"
    );
    assert_eq!(
        attr(&dom, "id=\"viewer-check\"", "data-points"),
        rows.to_string()
    );
    assert_eq!(attr(&dom, "<body", "data-errors"), "0", "{dom}");
    let figures = dom.matches("<figure").count();
    assert_eq!(
        figures,
        2 + ids.len(),
        "overview, histogram, one close-up a region"
    );
    assert_eq!(attr(&dom, "<body", "data-images"), figures.to_string());
    assert_eq!(attr(&dom, "<body", "data-loaded"), figures.to_string());
    let labelled: Vec<u64> = dom
        .split("data-regions=\"")
        .skip(1)
        .flat_map(|s| s[..s.find('"').unwrap()].split_whitespace())
        .map(|s| s.parse().unwrap())
        .collect();
    for id in ids {
        let overview = attr(&dom, "<figure", "data-regions");
        assert!(
            overview.split_whitespace().any(|s| s == id.to_string()),
            "region {id} is not numbered on the overview ({overview})"
        );
        assert!(labelled.iter().filter(|&&l| l == *id).count() >= 2, "{id}");
        assert!(dom.contains(&format!("<figcaption>region {id}: ")), "{id}");
    }
    assert_local_only(&dom, &netlog);
    (page, figures)
}

/// The plan's regions: those with passes (the removal planner may leave a region out, with its
/// reason in plan.json), a subset of the inspection's `ids`.
fn planned_regions(out: &std::path::Path, ids: &[u64]) -> Vec<u64> {
    let plan: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap();
    let mut planned: Vec<u64> = plan["passes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["region"].as_u64().unwrap())
        .collect();
    planned.sort_unstable();
    planned.dedup();
    assert!(
        planned.len() >= 4 && planned.iter().all(|id| ids.contains(id)),
        "planned {planned:?} of {ids:?}"
    );
    planned
}

/// The viewer alone on screen: the part is drawn and its defects are coloured.
fn viewer_draws_the_part(browser: &str, tmp: &std::path::Path, insp: &std::path::Path, page: &str) {
    let only_viewer = page.replacen(
        "</head>",
        "<style>body>*:not(#viewer){display:none}</style></head>",
        1,
    );
    std::fs::write(insp.join("viewer.html"), only_viewer).unwrap();
    let shot = tmp.join("viewer.png");
    let flags = [
        "--window-size=1000,800".into(),
        format!("--screenshot={}", shot.display()),
    ];
    chromium_run(browser, &flags, &insp.join("viewer.html"), true);
    let (drawn, strong) = screenshot_shares(&shot);
    assert!(
        drawn > 0.15,
        "the viewer drew {:.1} % of the window",
        100.0 * drawn
    );
    assert!(strong >= 100, "only {strong} px show a defect's colour");
}

/// Print to PDF: A4 pages, every one of the report's `figures` inside.
fn prints_on_a4(browser: &str, tmp: &std::path::Path, insp: &std::path::Path, figures: usize) {
    let pdf = tmp.join("report.pdf");
    let flags = [
        "--no-pdf-header-footer".into(),
        format!("--print-to-pdf={}", pdf.display()),
    ];
    chromium_run(browser, &flags, &insp.join("report.html"), true);
    let bytes = std::fs::read(&pdf).unwrap();
    assert!(bytes.starts_with(b"%PDF"));
    let pages = count(&bytes, b"/Type /Page") - count(&bytes, b"/Type /Pages");
    let images = count(&bytes, b"/Subtype /Image");
    assert!(pages >= 2, "{pages} pages");
    assert!(
        images >= figures,
        "{images} images in the PDF for {figures} figures"
    );
    // A4 portrait: 210 x 297 mm = 595.3 x 841.9 pt.
    let a4 = count(&bytes, b"/MediaBox [0 0 594.9") + count(&bytes, b"/MediaBox [0 0 595.");
    assert!(a4 >= pages, "pages are not A4");
}

/// The demo's plan.html: linked from the inspection report and back, a tool-path figure per
/// planned region (every image decodes), no script error, nothing but relative links.
fn plan_page_loads(browser: &str, out: &std::path::Path, ids: &[u64]) {
    let report = std::fs::read_to_string(out.join("inspection/report.html")).unwrap();
    assert!(
        report.contains("<a href=\"../plan.html\">"),
        "no link to the plan"
    );
    let page = std::fs::read_to_string(out.join("plan.html")).unwrap();
    assert!(
        page.contains("<a href=\"inspection/report.html\">"),
        "no link back"
    );
    std::fs::write(out.join("plan-probe.html"), probe(&page)).unwrap();
    let netlog = out.join("plan-netlog.json");
    let dom = dump_dom(browser, &out.join("plan-probe.html"), &netlog);
    assert_eq!(attr(&dom, "<body", "data-errors"), "0", "{dom}");
    let figures = dom.matches("<figure").count();
    // the coverage map, then per planned region (the demo's plan predicts every one) its tool
    // path, and the deviation before, the predicted part after and the Monte Carlo's low
    // quantile
    assert_eq!(
        figures,
        1 + 4 * ids.len(),
        "a coverage map and four figures per planned region"
    );
    assert_eq!(attr(&dom, "<body", "data-loaded"), figures.to_string());
    for id in ids {
        let own = format!("<figure data-regions=\"{id}\">");
        assert_eq!(dom.matches(&own).count(), 4, "{id}");
        let scales: Vec<&str> = dom
            .split(&format!("<figcaption>region {id}: "))
            .skip(1)
            .filter_map(|c| c.split("colour scale ±").nth(1))
            .map(|c| &c[..c.find(' ').unwrap()])
            .collect();
        assert_eq!(
            scales.len(),
            3,
            "region {id}: three panels on a colour scale"
        );
        assert!(scales.iter().all(|s| *s == scales[0]), "{scales:?}");
    }
    for table in [
        "left out by rule",
        "left out: regions and strokes",
        "reach and time per region",
        "time per kind of motion",
        "provenance",
    ] {
        assert!(dom.contains(table), "plan.html has no {table}");
    }
    assert_local_only(&dom, &netlog);
}

/// cycle.html of the demo's loop: the convergence plot and per grind each planned region's map
/// with the shift the loop printed (`log`, its "cycle: region N: removal shift S mm" lines) or
/// "no shift measured", and the removal scatter; every image loads.
fn cycle_page_loads(browser: &str, out: &std::path::Path, log: &str) {
    let dir = out.join("cycle");
    let page = std::fs::read_to_string(dir.join("cycle.html")).unwrap();
    let shifts: Vec<(&str, &str)> = log
        .lines()
        .filter_map(|l| l.strip_prefix("cycle: region "))
        .filter_map(|l| {
            let (id, rest) = l.split_once(": removal shift ")?;
            Some((id, rest.split_once(" mm")?.0))
        })
        .collect();
    assert!(
        !shifts.is_empty(),
        "the demo's loop printed no shift:\n{log}"
    );
    for (id, shift) in &shifts {
        let caption = format!("region {id}: deviation before; measured shift {shift} mm");
        assert!(page.contains(&caption), "cycle.html lacks {caption:?}");
    }
    let grinds = page.matches(": removal predicted by the plan").count();
    assert!(grinds >= 1, "no removal scatter");
    // a region ground without a registered removal (too little of it above the noise: under
    // the rim guard the demo's region 0 in grind 2) has its map, captioned so
    let unshifted = page
        .matches("deviation before; no shift measured (no removal registered)")
        .count();
    assert!(
        page.contains("src=\"convergence.png\""),
        "no convergence plot"
    );
    std::fs::write(dir.join("cycle-probe.html"), probe(&page)).unwrap();
    let netlog = dir.join("cycle-netlog.json");
    let dom = dump_dom(browser, &dir.join("cycle-probe.html"), &netlog);
    assert_eq!(attr(&dom, "<body", "data-errors"), "0", "{dom}");
    let images = attr(&dom, "<body", "data-images");
    assert_eq!(
        images,
        (1 + grinds + shifts.len() + unshifted).to_string(),
        "convergence, a map per region ground, a scatter per grind"
    );
    assert_eq!(attr(&dom, "<body", "data-loaded"), images);
    assert_local_only(&dom, &netlog);
}

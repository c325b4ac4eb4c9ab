//! Headless Chromium for the report tests (tests/report.rs, report_demo.rs): the browser,
//! the suite's flags, a probe that counts decoded images and script errors, a page's DOM
//! after load, and the check that a page asked nothing of the network.
use std::path::Path;
use std::process::Command;

use super::{in_ci, tempdir};

/// The Chromium on PATH (None, with a message, where there is none outside CI; in CI a
/// missing browser fails the test).
pub fn chromium() -> Option<String> {
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

/// The suite's flags: headless without sandbox or GPU, none of the browser's own network
/// traffic, file pages may load files, and 10 s of virtual time for a page to load.
pub const FLAGS: [&str; 10] = [
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

/// A copy of `page` with a probe first in its head: it records script errors, console errors
/// and rejected promises, and on load writes into `<body>` how many images there are and how
/// many decoded, the errors, and the navigation's load time.
pub fn probe(page: &str) -> String {
    let probe = "<head><script>window.__err=[];\
addEventListener('error',e=>__err.push('error: '+e.message));\
addEventListener('unhandledrejection',e=>__err.push('rejection: '+e.reason));\
const __ce=console.error.bind(console);console.error=(...a)=>{__err.push(a.join(' '));__ce(...a)};\
addEventListener('load',()=>{const i=[...document.images],b=document.body;\
b.setAttribute('data-images',i.length);\
b.setAttribute('data-loaded',i.filter(x=>x.complete&&x.naturalWidth>0).length);\
b.setAttribute('data-errors',__err.length);b.setAttribute('data-error-text',__err.join(' | '));\
b.setAttribute('data-load-ms',Math.round(performance.getEntriesByType('navigation')[0].loadEventStart));});\
</script>";
    page.replacen("<head>", probe, 1)
}

/// The value of the first `name="..."` attribute after `after` in `dom`.
pub fn attr<'a>(dom: &'a str, after: &str, name: &str) -> &'a str {
    let from = dom
        .find(after)
        .unwrap_or_else(|| panic!("{after} not in the DOM"));
    let key = format!("{name}=\"");
    let at = dom[from..]
        .find(&key)
        .unwrap_or_else(|| panic!("no {name}"))
        + from
        + key.len();
    &dom[at..at + dom[at..].find('"').unwrap()]
}

/// Chromium with the suite's flags, a fresh profile and `flags` on the page `page`; with
/// `settle` the page gets 10 s of virtual time to load (off where its load time is measured).
pub fn chromium_run(
    browser: &str,
    flags: &[String],
    page: &Path,
    settle: bool,
) -> std::process::Output {
    let profile = tempdir();
    let mut cmd = Command::new(browser);
    cmd.args(
        FLAGS
            .iter()
            .filter(|f| settle || !f.starts_with("--virtual-time")),
    )
    .arg(format!("--user-data-dir={}", profile.path().display()))
    .args(flags)
    .arg(format!("file://{}", page.display()));
    super::succeed(&mut cmd)
}

/// The DOM of `page` after load, with the browser's net log written to `netlog`.
pub fn dump_dom(browser: &str, page: &Path, netlog: &Path) -> String {
    let flags = [
        format!("--log-net-log={}", netlog.display()),
        "--dump-dom".into(),
    ];
    String::from_utf8_lossy(&chromium_run(browser, &flags, page, true).stdout).to_string()
}

/// Nothing the page asked for left the file system: every `src` and `href` of the DOM is a
/// relative path (Chromium keeps file loads out of resource timing and the net log), and the
/// browser's net log holds no request made for the page (the browser's own update and
/// account checks carry the initiator "not an origin"; a page's request carries the page's
/// origin).
pub fn assert_local_only(dom: &str, netlog: &Path) {
    let mut links = 0;
    for key in ["src=\"", "href=\""] {
        for part in dom.split(key).skip(1) {
            let url = &part[..part.find('"').unwrap()];
            links += 1;
            assert!(
                !url.contains(':') && !url.starts_with("//") && !url.starts_with('/'),
                "the page links {url}"
            );
        }
    }
    assert!(links > 0, "the page links nothing: not the report");
    let log: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(netlog).expect("no net log")).unwrap();
    for e in log["events"].as_array().unwrap() {
        let p = &e["params"];
        if let (Some(url), Some(from)) = (p["url"].as_str(), p["initiator"].as_str()) {
            assert!(
                from == "not an origin" || url.starts_with("file://") || url.starts_with("data:"),
                "the page ({from}) asked for {url}"
            );
        }
    }
}

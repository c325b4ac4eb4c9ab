//! The report page: plain HTML with inline CSS, figures referenced by relative file names.
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use super::input::{Figure, ReportInput};

/// `s` with HTML's special characters escaped.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The id of the paragraph that holds links to other pages (`plan` adds its own there).
pub const LINKS_ID: &str = "links";

/// How a page is laid out besides its [`ReportInput`].
#[derive(Debug, Clone, Copy)]
pub struct Layout<'p> {
    /// Figures at full width, after the summary.
    pub whole: &'p [Figure],
    /// Heading of the close-ups.
    pub closeup_title: &'p str,
    /// Figures side by side under that heading.
    pub closeups: &'p [Figure],
    /// HTML of the 3D viewer's section (empty: none).
    pub viewer: &'p str,
    /// Links to other pages: (text, relative href).
    pub links: &'p [(String, String)],
}

/// Writes the page: title, links, summary, whole figures, close-ups, viewer, tables,
/// provenance. Returns the page's text as written.
pub fn write(path: &Path, input: &ReportInput, layout: &Layout) -> Result<String> {
    let mut s = String::new();
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\n<style>\
body{{font-family:sans-serif;margin:24px;color:#222}} table{{border-collapse:collapse;margin:8px 0 24px}}\
td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}} th{{background:#eee}}\
td:first-child,th:first-child{{text-align:left}} img{{max-width:100%;border:1px solid #ddd;margin:8px 0}}\
figure{{margin:8px 0 16px}} figcaption{{font-size:90%;color:#444}}\
.provenance td{{text-align:left;word-break:break-all;font-family:monospace;font-size:85%}}\
.closeups{{display:flex;flex-wrap:wrap;gap:12px}} .closeups figure{{flex:0 0 auto;max-width:600px}}\
.viewer canvas{{border:1px solid #bbb;max-width:100%;cursor:grab}} .viewer input{{width:6em}}\
#viewer-check{{font-size:85%;color:#555}}\
@page{{size:A4;margin:12mm}}\
@media print{{body{{margin:0;font-size:10pt}} .viewer{{display:none}} figure,tr{{break-inside:avoid}}\
img{{max-width:100%;max-height:250mm}} .closeups figure{{max-width:48%}} .closeups img{{width:100%}}}}\
</style></head><body>\n<h1>{t}</h1>\n<p id=\"{LINKS_ID}\">",
        t = escape(&input.title)
    );
    for (text, href) in layout.links {
        let _ = write!(s, "<a href=\"{}\">{}</a> ", escape(href), escape(text));
    }
    s += "</p>\n";
    s += "<table>\n";
    for (k, v) in &input.summary {
        let _ = writeln!(s, "<tr><th>{}</th><td>{}</td></tr>", escape(k), escape(v));
    }
    s += "</table>\n";
    let fig = |s: &mut String, f: &Figure| {
        let name = f
            .path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        let ids: Vec<String> = f.regions.iter().map(|i| i.to_string()).collect();
        let _ = writeln!(
            s,
            "<figure data-regions=\"{}\"><img src=\"{n}\" alt=\"{n}\"><figcaption>{}</figcaption></figure>",
            ids.join(" "),
            escape(&f.caption),
            n = escape(name),
        );
    };
    for f in layout.whole {
        fig(&mut s, f);
    }
    if !layout.closeups.is_empty() {
        let _ = writeln!(
            s,
            "<h2>{}</h2>\n<div class=\"closeups\">",
            escape(layout.closeup_title)
        );
        for f in layout.closeups {
            fig(&mut s, f);
        }
        s += "</div>\n";
    }
    s += layout.viewer;
    for t in &input.tables {
        let _ = writeln!(s, "<h2>{}</h2>\n<table>", escape(&t.title));
        s += "<tr>";
        for h in &t.header {
            let _ = write!(s, "<th>{}</th>", escape(h));
        }
        s += "</tr>\n";
        for row in &t.rows {
            s += "<tr>";
            for c in row {
                let _ = write!(s, "<td>{}</td>", escape(c));
            }
            s += "</tr>\n";
        }
        s += "</table>\n";
    }
    if let Some(p) = input.provenance {
        s += "<h2>provenance</h2>\n<table class=\"provenance\">\n";
        for (k, v) in p.lines() {
            let _ = writeln!(s, "<tr><th>{}</th><td>{}</td></tr>", escape(&k), escape(&v));
        }
        s += "</table>\n";
    }
    s += "</body></html>\n";
    std::fs::write(path, &s).with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(s)
}

/// A plain page without scripts or figures: `title`, one table (`header`, `rows`; cells
/// escaped) and `paragraphs` after it (given as HTML). The closed loop's cycle.html.
pub fn table_page(
    title: &str,
    header: &[String],
    rows: &[Vec<String>],
    paragraphs: &[String],
) -> String {
    let cells = |row: &[String], tag: &str| {
        row.iter()
            .map(|c| format!("<{tag}>{}</{tag}>", escape(c)))
            .collect::<String>()
    };
    let title = escape(title);
    let mut html = format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{title}</title>\n\
         <style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}\
         td,th{{border:1px solid #999;padding:4px 8px;text-align:right}}</style></head><body>\n\
         <h1>{title}</h1>\n<table>\n"
    );
    html += &format!("<tr>{}</tr>\n", cells(header, "th"));
    for row in rows {
        html += &format!("<tr>{}</tr>\n", cells(row, "td"));
    }
    html += "</table>\n";
    for p in paragraphs {
        html += &format!("<p>{p}</p>\n");
    }
    html += "</body></html>\n";
    html
}

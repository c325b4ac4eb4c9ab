//! The inspection report: `report.html` with PNG figures beside it (an overview from the
//! standard views that show every defect region, numbered; a close-up per region along its
//! normal; the histogram of deviations; tables). Works offline: no CDN, a shipped font.
mod closeup;
mod colour;
pub mod coverage;
pub mod cycle_page;
pub(crate) mod font;
mod histogram;
mod html;
mod input;
pub mod inspection;
mod marks;
pub mod plan_html;
pub mod plan_page;
pub mod plan_reach;
pub mod provenance;
mod raster;
mod viewer;
mod views;

use std::path::Path;

use anyhow::Result;

pub use colour::diverging;
pub use html::{escape, table_page};
pub use input::{
    colour_range, Figure, RegionMark, ReportConfig, ReportFiles, ReportInput, Table, Unmeasured,
};

/// Writes report.html and its figures into `dir`.
pub fn write_report(dir: &Path, input: &ReportInput, cfg: &ReportConfig) -> Result<ReportFiles> {
    let n = input.points.len();
    anyhow::ensure!(
        n == input.normals.len() && n == input.distances.len(),
        "report: points, normals and distances differ in length"
    );
    anyhow::ensure!(
        input.labels.is_empty() || input.labels.len() == n,
        "report: {} region labels for {n} points",
        input.labels.len()
    );
    anyhow::ensure!(
        input.uncertainties.is_empty() || input.uncertainties.len() == n,
        "report: {} uncertainties for {n} points",
        input.uncertainties.len()
    );
    anyhow::ensure!(
        input.regions.is_empty() || !input.labels.is_empty(),
        "report: regions without labels"
    );
    std::fs::create_dir_all(dir)?;
    let range = colour_range(input.distances, input.tolerance, cfg);
    let views = dir.join("deviation_views.png");
    let hist = dir.join("deviation_histogram.png");
    let ((overview, hist_done), closeups) = rayon::join(
        || {
            rayon::join(
                || views::draw(&views, input, range, cfg),
                || histogram::draw(&hist, input.distances, input.tolerance, range, cfg),
            )
        },
        || {
            use rayon::prelude::*;
            input
                .regions
                .par_iter()
                .map(|r| {
                    let path = dir.join(format!("region_{}.png", r.id));
                    Ok(closeup::draw(&path, input, r, range)?.then(|| Figure {
                        path,
                        caption: format!("region {}: {}", r.id, r.caption),
                        regions: vec![r.id],
                    }))
                })
                .collect::<Result<Vec<_>>>()
        },
    );
    let overview = overview?;
    hist_done?;
    let whole = vec![
        Figure {
            path: views,
            caption: overview_caption(&overview),
            regions: overview.panels.iter().flat_map(|p| p.1.clone()).collect(),
        },
        Figure {
            path: hist,
            caption: "histogram of signed deviations, tolerance band marked".into(),
            regions: Vec::new(),
        },
    ];
    let mut whole = whole;
    let unmeasured = dir.join("unmeasured.png");
    if let Some(panels) = views::draw_unmeasured(&unmeasured, input, cfg)? {
        let words = input
            .unmeasured
            .as_ref()
            .map_or("", |u| u.suggestion.as_str());
        whole.push(Figure {
            path: unmeasured,
            caption: format!(
                "unmeasured area to inspect (orange; grey: measured, pale: outside the area) \
                 from {}; {words}",
                panels.join(", ")
            ),
            regions: Vec::new(),
        });
    }
    let closeups: Vec<Figure> = closeups?.into_iter().flatten().collect();
    let viewer = viewer::write(dir, input, range)?;
    let html = dir.join("report.html");
    let layout = html::Layout {
        whole: &whole,
        closeup_title: "defect regions, close up",
        closeups: &closeups,
        viewer: &viewer,
        links: &[],
    };
    let page = html::write(&html, input, &layout)?;
    Ok(ReportFiles {
        html,
        page,
        figures: whole.into_iter().chain(closeups).map(|f| f.path).collect(),
    })
}

/// "views: anterior (+y) (regions 0, 2); ..." for the overview.
fn overview_caption(o: &views::Overview) -> String {
    let panels: Vec<String> = o
        .panels
        .iter()
        .map(|(name, ids)| match ids.as_slice() {
            [] => name.clone(),
            ids => {
                let ids: Vec<String> = ids.iter().map(|i| i.to_string()).collect();
                format!("{name}: regions {}", ids.join(", "))
            }
        })
        .collect();
    format!("deviation colour map; {}", panels.join("; "))
}

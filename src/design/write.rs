//! The designed cell's folder: workcell.toml (placement and `[turntable]`), solids.toml,
//! tool.toml (the source's with the designed shank), the source's dofbot.urdf and servos.toml,
//! design.json (every sample's verdict) and coverage.png; each further setup's workcell.toml and
//! solids.toml in `setup-N/` (N = 2, 3, ...).
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{anyhow, Context, Result};
use plotters::prelude::*;

use super::{Candidate, Design, FurtherSetup, SourceCell};
pub use crate::motion::setups::SETUP_DIR;
use crate::report::font;

/// Side of one panel of the coverage picture, pixels.
const PANEL_PX: u32 = 420;
/// Height of the picture's title band, pixels.
const TITLE_PX: u32 = 40;

/// Writes the cell folder `out`.
pub fn write_cell(design: &Design, source: &SourceCell, out: &Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let put = |name: &str, text: &str| {
        let p = out.join(name);
        std::fs::write(&p, text).with_context(|| format!("{}: cannot write", p.display()))
    };
    put("workcell.toml", &workcell_text(design))?;
    put("solids.toml", &solids_text(&design.solids))?;
    let tool = std::fs::read_to_string(source.dir.join("tool.toml"))
        .with_context(|| format!("{}: cannot read", source.dir.join("tool.toml").display()))?;
    put("tool.toml", &tool_text(&tool, design.candidate.shank_m))?;
    for name in ["dofbot.urdf", "servos.toml"] {
        std::fs::copy(source.dir.join(name), out.join(name))
            .with_context(|| format!("{}: cannot copy", source.dir.join(name).display()))?;
    }
    for (k, cell) in design.setup_cells.iter().enumerate() {
        let n = k + 2;
        let dir = format!("{SETUP_DIR}{n}");
        std::fs::create_dir_all(out.join(&dir))
            .with_context(|| format!("{}: cannot create", out.join(&dir).display()))?;
        put(
            &format!("{dir}/workcell.toml"),
            &setup_workcell_text(n, cell),
        )?;
        put(&format!("{dir}/solids.toml"), &solids_text(&cell.solids))?;
    }
    put("design.json", &serde_json::to_string_pretty(design)?)?;
    picture(design, &out.join("coverage.png"))
}

fn vec3(v: &[f64; 3]) -> String {
    format!("[{:.6}, {:.6}, {:.6}]", v[0], v[1], v[2])
}

fn workcell_text(d: &Design) -> String {
    let c = &d.candidate;
    let header = format!(
        "# Designed by `polishbot cell design` (docs/ALGORITHMS.md, \"Cell design\"): the part's\n\
         # direction {} (reference frame) lies along the table axis, its centroid on the axis at\n\
         # the centre below; a sample of the articular surface counts as reached when some table\n\
         # angle lets the planner's IK and collision model place the ball on it: {:.1} % of the\n\
         # articular surface. Units and conventions as calibration/workcell.toml. Measure the\n\
         # cell as built with `polishbot calibrate workcell` and `calibrate turntable`.",
        vec3(&c.mount),
        100.0 * d.coverage
    );
    placement_text(&header, c, &d.robot_from_reference, 6)
}

/// Setup `n`'s workcell.toml (`setup-N/`): the part re-fixtured with another direction along
/// the same table axis.
fn setup_workcell_text(n: usize, s: &FurtherSetup) -> String {
    let header = format!(
        "# Setup {n} of the designed cell (`polishbot cell design`, docs/ALGORITHMS.md, \"Cell\n\
         # design\"): the part re-fixtured on the same table with its direction {} (reference\n\
         # frame) along the table axis; this setup alone reaches {:.1} % of the articular\n\
         # surface. `plan` plans here the regions setup 1 leaves short; `run` stops for the\n\
         # re-fixture. This placement is the design's: after re-fixturing, measure it with\n\
         # `polishbot calibrate workcell --setup {n}` (docs/CALIBRATION.md), which rewrites this file.",
        vec3(&s.candidate.mount),
        100.0 * s.coverage
    );
    // 9 decimals: the rotation of a mounting off the axes is orthonormal to 1e-9 there (at
    // 6 its error, 1e-6, is what Workcell::load refuses)
    placement_text(&header, &s.candidate, &s.robot_from_reference, 9)
}

/// A workcell.toml: `header`, the placement (`decimals` places) and the `[turntable]` of `c`.
fn placement_text(header: &str, c: &Candidate, m: &[[f64; 4]; 4], decimals: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{header}");
    s.push_str("robot_from_reference = [\n");
    for row in m {
        let _ = writeln!(
            s,
            "  [{:.p$}, {:.p$}, {:.p$}, {:.p$}],",
            row[0],
            row[1],
            row[2],
            row[3],
            p = decimals
        );
    }
    s.push_str(
        "]\n\n# The part turntable (robot frame): axis and a point of it, metres.\n[turntable]\n",
    );
    let _ = writeln!(s, "axis = {}\ncentre = {}", vec3(&c.axis), vec3(&c.centre));
    s
}

fn solids_text(solids: &[(String, [f64; 3], [f64; 3])]) -> String {
    let mut s = String::from(
        "# Fixed solids of the designed cell (robot frame, metres, axis-aligned boxes): the base\n\
         # plane, and the table's spindle (a chain of cubes along the axis), housing and post as\n\
         # the design assumed them. Measure the real fixture and write it here.\n",
    );
    for (name, min, max) in solids {
        let _ = writeln!(
            s,
            "\n[[solid]]\nname = {name:?}\nmin = {}\nmax = {}",
            vec3(min),
            vec3(max)
        );
    }
    s
}

/// The source tool.toml with `tip_offset` and `shank_length` set to the designed shank.
fn tool_text(source: &str, shank_m: f64) -> String {
    let mut out = String::new();
    let mut had_length = false;
    for line in source.lines() {
        if line.starts_with("tip_offset") {
            let _ = writeln!(out, "tip_offset = [0.0, 0.0, {shank_m:.4}]");
        } else if line.starts_with("shank_length") {
            had_length = true;
            let _ = writeln!(out, "shank_length = {shank_m:.4}");
        } else if line.starts_with("[removal]") && !had_length {
            had_length = true;
            let _ = writeln!(out, "shank_length = {shank_m:.4}\n\n{line}");
        } else {
            out.push_str(line);
            out.push('\n');
        }
    }
    if !had_length {
        let _ = writeln!(out, "shank_length = {shank_m:.4}");
    }
    out
}

/// Three views of the articular-surface samples (along the reference frame's x, y and z;
/// nearer samples drawn last), green reached, red not.
fn picture(d: &Design, path: &Path) -> Result<()> {
    font::register();
    let root = BitMapBackend::new(path, (3 * PANEL_PX, PANEL_PX + TITLE_PX)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| anyhow!("{}: drawing failed: {e:?}", path.display());
    root.fill(&WHITE).map_err(err)?;
    let title = format!(
        "articular surface reached: {:.1} % (green), along reference x | y | z",
        100.0 * d.coverage
    );
    let style = TextStyle::from((font::FAMILY, 20).into_font()).color(&BLACK);
    root.draw_text(&title, &style, (10, 10)).map_err(err)?;
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for v in &d.samples {
        for k in 0..3 {
            lo[k] = lo[k].min(v.position_mm[k]);
            hi[k] = hi[k].max(v.position_mm[k]);
        }
    }
    let span = (0..3).map(|k| hi[k] - lo[k]).fold(1e-9, f64::max);
    let scale = (PANEL_PX as f64 - 20.0) / span;
    for view in 0..3 {
        let (u, w) = ((view + 1) % 3, (view + 2) % 3);
        let mut order: Vec<_> = d.samples.iter().collect();
        order.sort_by(|a, b| a.position_mm[view].total_cmp(&b.position_mm[view]));
        for v in order {
            let x = view as f64 * PANEL_PX as f64 + 10.0 + (v.position_mm[u] - lo[u]) * scale;
            let y = TITLE_PX as f64 + PANEL_PX as f64 - 10.0 - (v.position_mm[w] - lo[w]) * scale;
            let colour = if v.angle_deg.is_some() {
                RGBColor(30, 160, 60)
            } else {
                RGBColor(210, 40, 40)
            };
            root.draw(&Circle::new((x as i32, y as i32), 3, colour.filled()))
                .map_err(err)?;
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

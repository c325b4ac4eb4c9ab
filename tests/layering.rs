//! The data-flow rule of DESIGN.md read from the source tree: no import against the flow.
//! A lower stage never imports a higher one (the shared neighbour search lives in
//! `src/spatial/`, not in `compare`), and a plan is data (nothing in `src/plan` imports `bus`).
use std::path::{Path, PathBuf};

/// Folders below the comparison in the flow: none of them may import `compare`.
const BELOW_COMPARE: [&str; 6] = [
    "cloud",
    "spatial",
    "preprocess",
    "register",
    "acquire",
    "synth",
];

/// Every `.rs` file under `dir`, sorted (empty when `dir` does not exist).
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries {
            let path = e.expect("a readable directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|x| x == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The source without comments (`//` to the end of the line; the lines stay where they were).
fn code_of(text: &str) -> String {
    text.lines()
        .map(|l| l.find("//").map_or(l, |at| &l[..at]))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Whether `s` starts with the path segment `module` (not a longer name such as `compare2`).
fn starts_with_segment(s: &str, module: &str) -> bool {
    s.strip_prefix(module)
        .is_some_and(|rest| !rest.starts_with(|c: char| c.is_alphanumeric() || c == '_'))
}

/// The names at the top level of a `{...}` group (`group`: the text after its `{`), trimmed.
fn top_level_names(group: &str) -> Vec<&str> {
    let mut depth = 0usize;
    let mut end = group.len();
    let mut cuts = vec![0];
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                end = i;
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => cuts.push(i + 1),
            _ => {}
        }
    }
    cuts.push(end + 1);
    cuts.windows(2)
        .map(|w| group[w[0]..w[1] - 1].trim())
        .collect()
}

/// Lines (1-based) of `text` whose code names the crate's module `module`: a path
/// `crate::module` (or `super::super::module` from a stage's file), or `module` at the top level
/// of a `crate::{...}` group.
fn imports_of(text: &str, module: &str) -> Vec<usize> {
    let code = code_of(text);
    let line_at = |byte: usize| code[..byte].matches('\n').count() + 1;
    let mut lines = Vec::new();
    for prefix in ["crate::", "super::super::"] {
        for (at, _) in code.match_indices(prefix) {
            let rest = &code[at + prefix.len()..];
            if starts_with_segment(rest, module) {
                lines.push(line_at(at));
            } else if let Some(group) = rest.strip_prefix('{') {
                if top_level_names(group)
                    .iter()
                    .any(|name| starts_with_segment(name, module))
                {
                    lines.push(line_at(at));
                }
            }
        }
    }
    lines.sort_unstable();
    lines.dedup();
    lines
}

/// "file:line" of every import of `module` by the files under `src/<folder>` for each folder.
fn violations(folders: &[&str], module: &str) -> Vec<String> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut found = Vec::new();
    for folder in folders {
        let dir = src.join(folder);
        assert!(dir.is_dir(), "{} is not a folder", dir.display());
        for file in rust_files(&dir) {
            let text = std::fs::read_to_string(&file).expect("a readable source file");
            for line in imports_of(&text, module) {
                found.push(format!("{}:{line}", file.display()));
            }
        }
    }
    found
}

#[test]
fn the_scanner_finds_imports_in_every_form() {
    let text = "use crate::compare::Grid;\n\
                // use crate::compare::Member; (a comment)\n\
                use crate::{cloud::PointCloud, compare};\n\
                use crate::{\n    cloud,\n    compare::{self, Method},\n};\n\
                use super::super::compare::x;\n\
                use crate::compared::Thing;\n\
                use crate::cloud::{compare, Aabb};\n\
                let v = crate::compare::run(x);\n";
    assert_eq!(imports_of(text, "compare"), [1, 3, 4, 8, 11]);
    assert!(imports_of("use crate::bus::Bus;", "bus") == [1]);
    assert!(imports_of("use crate::busy::Bus; // crate::bus", "bus").is_empty());
    assert!(imports_of("use dofbot_protocol::bus::Frame;", "bus").is_empty());
}

#[test]
fn no_stage_below_the_comparison_imports_compare() {
    let found = violations(&BELOW_COMPARE, "compare");
    assert!(
        found.is_empty(),
        "imports of compare against the flow: {found:?}"
    );
}

// A plan is data: its frames are made through dofbot-protocol and streamed by src/cell.
#[test]
fn the_plan_does_not_import_bus() {
    let found = violations(&["plan"], "bus");
    assert!(found.is_empty(), "imports of bus by the plan: {found:?}");
}

/// The motion half's floors, lowest first, as DESIGN.md's flow has them: the board's driver
/// and simulator (`bus`) and the arm's model (`robot`) know nothing of a plan, the cell that
/// streams it or the simulated grind that runs above the simulator.
const MOTION_RULES: [(&str, &[&str]); 4] = [
    ("robot", &["bus", "plan", "cell", "grind_sim", "inspect"]),
    ("bus", &["plan", "cell", "grind_sim", "inspect"]),
    ("plan", &["cell", "grind_sim", "inspect"]),
    ("grind_sim", &["plan", "cell"]),
];

#[test]
fn the_motion_floors_import_only_downwards() {
    let mut found = Vec::new();
    for (folder, above) in MOTION_RULES {
        for module in above {
            found.extend(violations(&[folder], module));
        }
    }
    assert!(found.is_empty(), "imports against the flow: {found:?}");
}

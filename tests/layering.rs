//! The data-flow rules of docs/ARCHITECTURE.md read from the source tree: every room imports
//! only the rooms its row of the table "What each room may import" lists, the table runs one
//! way, and no two files import each other.
use std::path::{Path, PathBuf};

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

/// The files of the room `room`: `src/<room>/**.rs`, or the single file `src/<room>.rs`.
fn room_files(room: &str) -> Vec<PathBuf> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let file = src.join(format!("{room}.rs"));
    if file.is_file() {
        return vec![file];
    }
    let dir = src.join(room);
    assert!(
        dir.is_dir(),
        "room {room} of docs/ARCHITECTURE.md is not in src/"
    );
    rust_files(&dir)
}

/// "file:line" of every import of `module` by the files of room `room`.
fn violations(room: &str, module: &str) -> Vec<String> {
    let mut found = Vec::new();
    for file in room_files(room) {
        let text = std::fs::read_to_string(&file).expect("a readable source file");
        for line in imports_of(&text, module) {
            found.push(format!("{}:{line} imports {module}", file.display()));
        }
    }
    found
}

/// The rows of the table "What each room may import" in docs/ARCHITECTURE.md, in order: each
/// room and the rooms it may import (`None`: `*`, every room).
fn architecture_rules() -> Vec<(String, Option<Vec<String>>)> {
    let doc = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/ARCHITECTURE.md");
    let text = std::fs::read_to_string(&doc).expect("docs/ARCHITECTURE.md");
    let table = text
        .split("## What each room may import")
        .nth(1)
        .expect("the section \"What each room may import\" in docs/ARCHITECTURE.md");
    table
        .lines()
        .filter(|l| l.starts_with('|'))
        .skip(2)
        .map(|row| {
            let cells: Vec<&str> = row.trim_matches('|').split('|').map(str::trim).collect();
            assert_eq!(cells.len(), 2, "a table row of two cells: {row}");
            let allowed = (cells[1] != "*").then(|| {
                cells[1]
                    .split(',')
                    .map(str::trim)
                    .filter(|m| !m.is_empty())
                    .map(str::to_string)
                    .collect()
            });
            (cells[0].to_string(), allowed)
        })
        .collect()
}

/// The crate's rooms as src/ has them: its folders and its files but lib.rs and main.rs.
fn rooms_in_src() -> Vec<String> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut rooms: Vec<String> = std::fs::read_dir(&src)
        .expect("src/")
        .map(|e| e.expect("a readable directory entry").path())
        .filter(|p| p.is_dir() || p.extension().is_some_and(|x| x == "rs"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .filter(|n| n != "lib" && n != "main")
        .collect();
    rooms.sort();
    rooms
}

#[test]
fn the_architecture_table_names_every_room_once_and_runs_one_way() {
    let rules = architecture_rules();
    let mut named: Vec<String> = rules.iter().map(|(r, _)| r.clone()).collect();
    named.sort();
    let before = named.len();
    named.dedup();
    assert_eq!(
        before,
        named.len(),
        "a room named twice in docs/ARCHITECTURE.md"
    );
    assert_eq!(
        named,
        rooms_in_src(),
        "the rooms of docs/ARCHITECTURE.md against src/"
    );
    for (at, (room, allowed)) in rules.iter().enumerate() {
        for m in allowed.iter().flatten() {
            assert!(
                rules[..at].iter().any(|(r, _)| r == m),
                "{room} may import {m}, which is not a row above it: the table runs one way"
            );
        }
    }
}

// A plan is data (no bus, no sim, no cell), nothing below the comparison imports compare, the
// simulator shares nothing with the planner: all of it is the table of docs/ARCHITECTURE.md.
#[test]
fn every_room_imports_only_what_the_architecture_allows() {
    let rules = architecture_rules();
    let mut found = Vec::new();
    for (room, allowed) in &rules {
        let Some(allowed) = allowed else { continue };
        for (other, _) in &rules {
            if other != room && !allowed.contains(other) {
                found.extend(violations(room, other));
            }
        }
    }
    assert!(
        found.is_empty(),
        "imports docs/ARCHITECTURE.md does not allow: {found:#?}"
    );
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

/// One source file of the crate: its module path (`src/a/b.rs` and `src/a/b/mod.rs` are
/// `[a, b]`, `src/lib.rs` is `[]`), whether it is a folder's `mod.rs` or the root, and its code.
struct Source {
    module: Vec<String>,
    folder: bool,
    code: String,
}

/// The library's files (src/main.rs is the binary, a crate of its own), code only: comments
/// and the unit tests (from the first `#[cfg(test)]`) cut away.
fn library_sources() -> (Vec<PathBuf>, Vec<Source>) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files: Vec<PathBuf> = rust_files(&src)
        .into_iter()
        .filter(|f| f != &src.join("main.rs"))
        .collect();
    let sources = files
        .iter()
        .map(|f| {
            let rel = f.strip_prefix(&src).expect("a file under src");
            let mut module: Vec<String> = rel
                .with_extension("")
                .iter()
                .map(|s| s.to_string_lossy().into_owned())
                .collect();
            let folder = matches!(module.last().map(String::as_str), Some("mod" | "lib"));
            if folder {
                module.pop();
            }
            let text = std::fs::read_to_string(f).expect("a readable source file");
            let text = text.split("#[cfg(test)]").next().unwrap_or_default();
            Source {
                module,
                folder,
                code: code_of(text),
            }
        })
        .collect();
    (files, sources)
}

/// The path segments at the start of `s` (`a::b::C` -> [a, b, C]), and the rest after them.
fn segments(s: &str) -> (Vec<String>, &str) {
    let mut out = Vec::new();
    let mut rest = s;
    loop {
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if end == 0 {
            return (out, rest);
        }
        out.push(rest[..end].to_string());
        rest = &rest[end..];
        match rest.strip_prefix("::") {
            Some(r) if !r.starts_with('{') => rest = r,
            _ => return (out, rest),
        }
    }
}

/// Whether a line declares a child module or re-exports (`pub use`) an item: structure, not a
/// use of the child's code.
fn declares_or_reexports(line: &str) -> bool {
    let l = line.trim_start();
    let l = l
        .strip_prefix("pub(crate) ")
        .or_else(|| l.strip_prefix("pub(super) "))
        .or_else(|| l.strip_prefix("pub "))
        .map_or((l, false), |r| (r, true));
    l.0.starts_with("mod ") || (l.1 && l.0.starts_with("use "))
}

/// The module paths each file's code names: `crate::`, `super::` and `self::` paths (with
/// their `{...}` groups), and in a folder's `mod.rs` the paths through its own children
/// (declarations and `pub use` re-exports left out).
fn named_paths(s: &Source, children: &dyn Fn(&str) -> bool) -> Vec<Vec<String>> {
    let mut paths = Vec::new();
    for line in s.code.lines().filter(|l| !declares_or_reexports(l)) {
        let mut at = 0;
        while at < line.len() {
            let rest = &line[at..];
            let prev = line[..at].chars().last();
            // `pub(in crate::x)` names a visibility, not an import
            let start = !prev.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':')
                && !line[..at].ends_with("(in ");
            let (segs, after) = segments(rest);
            let step = segs.first().map_or_else(
                || rest.chars().next().map_or(1, char::len_utf8),
                String::len,
            );
            if start && segs.len() + usize::from(after.starts_with("::{")) >= 2 {
                let mut base: Vec<String> = match segs[0].as_str() {
                    "crate" => Vec::new(),
                    "super" | "self" => s.module.clone(),
                    first if s.folder && children(first) => s.module.clone(),
                    _ => {
                        at += step;
                        continue;
                    }
                };
                let mut tail = segs.as_slice();
                if tail[0] == "crate" || tail[0] == "self" {
                    tail = &tail[1..];
                }
                while tail.first().is_some_and(|t| t == "super") {
                    base.pop();
                    tail = &tail[1..];
                }
                base.extend(tail.iter().cloned());
                match after.strip_prefix("::{") {
                    Some(group) => {
                        for name in top_level_names(group) {
                            let (more, _) = segments(name);
                            let mut p = base.clone();
                            p.extend(more.into_iter().filter(|m| m != "self"));
                            paths.push(p);
                        }
                    }
                    None => paths.push(base),
                }
            }
            at += step;
        }
    }
    paths
}

/// Each file's imports of other files: a named path goes to the file of its longest prefix
/// that is a module.
fn import_graph(sources: &[Source]) -> Vec<std::collections::BTreeSet<usize>> {
    let index: std::collections::HashMap<&[String], usize> = sources
        .iter()
        .enumerate()
        .map(|(i, s)| (s.module.as_slice(), i))
        .collect();
    sources
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let child = |name: &str| {
                let mut m = s.module.clone();
                m.push(name.to_string());
                index.contains_key(m.as_slice())
            };
            named_paths(s, &child)
                .iter()
                .filter_map(|p| (0..=p.len()).rev().find_map(|k| index.get(&p[..k])))
                .copied()
                .filter(|&j| j != i)
                .collect()
        })
        .collect()
}

/// The files that lie on an import circle, in groups of mutually importing files.
fn circles(graph: &[std::collections::BTreeSet<usize>]) -> Vec<Vec<usize>> {
    let reach = |from: usize| {
        let mut seen = vec![false; graph.len()];
        let mut stack = vec![from];
        while let Some(v) = stack.pop() {
            for &w in &graph[v] {
                if !seen[w] {
                    seen[w] = true;
                    stack.push(w);
                }
            }
        }
        seen
    };
    let reaches: Vec<Vec<bool>> = (0..graph.len()).map(reach).collect();
    let mut done = vec![false; graph.len()];
    let mut groups = Vec::new();
    for v in 0..graph.len() {
        if done[v] || !reaches[v][v] {
            continue;
        }
        let group: Vec<usize> = (0..graph.len())
            .filter(|&w| reaches[v][w] && reaches[w][v])
            .collect();
        group.iter().for_each(|&w| done[w] = true);
        groups.push(group);
    }
    groups
}

fn fake(module: &[&str], folder: bool, code: &str) -> Source {
    Source {
        module: module.iter().map(|s| s.to_string()).collect(),
        folder,
        code: code_of(code),
    }
}

#[test]
fn the_circle_finder_finds_parent_child_and_sibling_circles() {
    let parent_child = [
        fake(&[], true, "pub mod a;"),
        fake(
            &["a"],
            true,
            "mod b;\npub use b::Y;\npub struct X;\nfn f() { b::g(); }",
        ),
        fake(&["a", "b"], false, "use super::X;\npub struct Y;"),
    ];
    assert_eq!(circles(&import_graph(&parent_child)), [vec![1, 2]]);
    let reexport_only = [
        fake(&["a"], true, "mod b;\npub use b::Y;\npub struct X;"),
        fake(
            &["a", "b"],
            false,
            "use super::X;\npub(in crate::a) fn f() {}",
        ),
    ];
    assert!(circles(&import_graph(&reexport_only)).is_empty());
    let siblings = [
        fake(&["a"], true, "mod b;\nmod c;\nmod d;"),
        fake(&["a", "b"], false, "use super::c::Z;"),
        fake(&["a", "c"], false, "use crate::a::{d::{self, W}};"),
        fake(&["a", "d"], false, "fn f() { super::super::a::b::g() }"),
    ];
    assert_eq!(circles(&import_graph(&siblings)), [vec![1, 2, 3]]);
}

#[test]
fn no_import_circle_between_files() {
    let (files, sources) = library_sources();
    let found: Vec<Vec<String>> = circles(&import_graph(&sources))
        .into_iter()
        .map(|g| {
            g.iter()
                .map(|&i| files[i].display().to_string())
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(found.is_empty(), "files importing each other: {found:?}");
}

/// The names of the `pub struct|enum|type|trait` items `code` declares, with their lines
/// (`pub(crate)` and narrower items are not public and are left out).
fn public_type_names(code: &str) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for (i, line) in code.lines().enumerate() {
        let Some(rest) = line.trim_start().strip_prefix("pub ") else {
            continue;
        };
        let kinds = ["struct ", "enum ", "type ", "trait "];
        let Some(rest) = kinds.iter().find_map(|k| rest.strip_prefix(k)) else {
            continue;
        };
        let end = rest
            .find(|c: char| !(c.is_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        if end > 0 {
            out.push((rest[..end].to_string(), i + 1));
        }
    }
    out
}

#[test]
fn the_scanner_finds_public_type_declarations() {
    let code = "pub struct Part<'a> {\n\
                pub(crate) struct Hidden;\n\
                    pub enum Verdict {\n\
                // pub struct InAComment;\n\
                pub type Columns = Vec<f64>;\n\
                pub trait Arm: Send {\n\
                pub fn structure() {}\n\
                struct Private;\n";
    let found = public_type_names(&code_of(code));
    let names: Vec<(&str, usize)> = found.iter().map(|(n, l)| (n.as_str(), *l)).collect();
    assert_eq!(
        names,
        [("Part", 1), ("Verdict", 3), ("Columns", 5), ("Arm", 6)]
    );
}

#[test]
fn no_two_public_types_share_a_name() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut seen: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    for file in rust_files(&src) {
        let text = std::fs::read_to_string(&file).expect("a readable source file");
        let text = text.split("#[cfg(test)]").next().unwrap_or_default();
        for (name, line) in public_type_names(&code_of(text)) {
            let at = format!("{}:{line}", file.display());
            seen.entry(name).or_default().push(at);
        }
    }
    let twice: Vec<_> = seen.into_iter().filter(|(_, at)| at.len() > 1).collect();
    assert!(
        twice.is_empty(),
        "public types declared under one name more than once: {twice:#?}"
    );
}

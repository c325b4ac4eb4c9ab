//! Files of the calibration routines: the fixture file (fiducials in the reference frame),
//! joint target files (scripted touches), and the writers of servos.toml, tool.toml and
//! workcell.toml. servos.toml and tool.toml are updated in place (comments and other keys
//! kept); every written file is read back through the loaders `plan` and `run` use.
use std::path::Path;

use nalgebra::Matrix4;
use serde::Deserialize;

use super::config::CalibError;
use crate::bus::JOINT_COUNT;
use crate::robot::error::read_toml;
use crate::robot::{Servos, Tool, Workcell};

/// One fiducial of the fixture.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fiducial {
    /// Name shown when it is to be touched.
    pub name: String,
    /// Position in the part's reference frame, millimetres.
    pub position: [f64; 3],
}

/// The fixture file: `[[fiducial]]` tables with `name` and `position` (mm, reference frame).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fixture {
    /// The fiducials, in touch order.
    #[serde(rename = "fiducial")]
    pub fiducials: Vec<Fiducial>,
}

impl Fixture {
    /// Loads a fixture file; non-finite coordinates are refused naming the fiducial.
    pub fn load(file: &Path) -> Result<Fixture, CalibError> {
        let f: Fixture = read_toml(file)?;
        for (i, fid) in f.fiducials.iter().enumerate() {
            if fid.position.iter().any(|v| !v.is_finite()) {
                return Err(CalibError::file(
                    file,
                    format!("fiducial[{i}] ({}): position must be finite", fid.name),
                ));
            }
        }
        Ok(f)
    }
}

/// Reads a joint target file: one pose per line, five joint angles in radians separated by
/// commas or spaces; `#` starts a comment, blank lines are skipped. A file without a pose is
/// an error (a check over no poses proves nothing).
pub fn load_targets(file: &Path) -> Result<Vec<[f64; JOINT_COUNT]>, CalibError> {
    let text = std::fs::read_to_string(file).map_err(|e| CalibError::file(file, e))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let values: Result<Vec<f64>, _> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(str::parse::<f64>)
            .collect();
        let bad = |m: String| CalibError::file(file, format!("line {}: {m}", n + 1));
        let values = values.map_err(|e| bad(format!("{e}")))?;
        let q: [f64; JOINT_COUNT] = values.as_slice().try_into().map_err(|_| {
            bad(format!(
                "need {JOINT_COUNT} joint angles (rad), got {}",
                values.len()
            ))
        })?;
        if q.iter().any(|v| !v.is_finite()) {
            return Err(bad("joint angles must be finite".into()));
        }
        out.push(q);
    }
    if out.is_empty() {
        return Err(CalibError::file(
            file,
            "no joint targets (need at least one line of 5 joint angles, rad)",
        ));
    }
    Ok(out)
}

/// Shortest decimal that reads back as the same f64 (TOML float syntax).
fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

/// True when `line` sets `key` (`key = value`).
fn sets_key(line: &str, key: &str) -> bool {
    let t = line.trim_start();
    t.strip_prefix(key)
        .is_some_and(|rest| rest.trim_start().starts_with('='))
}

/// Sets `zero_offset_deg` of every listed servo id in the servos.toml text `text` (replacing
/// the key's line or adding it after the `id` line of its `[[servo]]` table).
pub fn patch_servos(text: &str, file: &Path, zero: &[(u8, f64)]) -> Result<String, CalibError> {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for &(id, deg) in zero {
        // Tables: each starts at a `[[servo]]` line and runs to the next table header.
        let starts: Vec<usize> = (0..lines.len())
            .filter(|&i| lines[i].trim_start().starts_with('['))
            .collect();
        let mut done = false;
        for (k, &s) in starts.iter().enumerate() {
            if lines[s].trim() != "[[servo]]" {
                continue;
            }
            let end = starts.get(k + 1).copied().unwrap_or(lines.len());
            let id_line = (s + 1..end).find(|&i| {
                sets_key(&lines[i], "id")
                    && lines[i].split('=').nth(1).and_then(|v| {
                        v.split('#')
                            .next()
                            .and_then(|v| v.trim().parse::<u8>().ok())
                    }) == Some(id)
            });
            let Some(id_line) = id_line else { continue };
            let new = format!("zero_offset_deg = {}", num(deg));
            match (s + 1..end).find(|&i| sets_key(&lines[i], "zero_offset_deg")) {
                Some(i) => lines[i] = new,
                None => lines.insert(id_line + 1, new),
            }
            done = true;
            break;
        }
        if !done {
            return Err(CalibError::file(
                file,
                format!("no [[servo]] table with id = {id} to update"),
            ));
        }
    }
    Ok(lines.join("\n") + "\n")
}

/// Sets the top-level `tip_offset` of the tool.toml text `text`.
pub fn patch_tool(text: &str, file: &Path, tip: [f64; 3]) -> Result<String, CalibError> {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let first_table = lines
        .iter()
        .position(|l| l.trim_start().starts_with('['))
        .unwrap_or(lines.len());
    let i = (0..first_table)
        .find(|&i| sets_key(&lines[i], "tip_offset"))
        .ok_or_else(|| CalibError::file(file, "no top-level tip_offset line to update"))?;
    lines[i] = format!(
        "tip_offset = [{}, {}, {}]",
        num(tip[0]),
        num(tip[1]),
        num(tip[2])
    );
    Ok(lines.join("\n") + "\n")
}

/// Sets each `(key, value)` of `set` in the `[removal]` table of the tool.toml text `text`:
/// replaces that key's one line (every comment and other key kept), adds it after the
/// `[removal]` header when the table lacks it, or appends the table when the file has none.
pub fn patch_removal(text: &str, set: &[(&str, f64)]) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    for &(key, value) in set {
        let new = format!("{key} = {}", num(value));
        let header = lines.iter().position(|l| l.trim() == "[removal]");
        match header {
            Some(h) => {
                let end = (h + 1..lines.len())
                    .find(|&i| lines[i].trim_start().starts_with('['))
                    .unwrap_or(lines.len());
                match (h + 1..end).find(|&i| sets_key(&lines[i], key)) {
                    Some(i) => lines[i] = new,
                    None => lines.insert(h + 1, new),
                }
            }
            None => {
                lines.push(String::new());
                lines.push("[removal]".into());
                lines.push(new);
            }
        }
    }
    lines.join("\n") + "\n"
}

/// workcell.toml text for `robot_from_reference` (metres), with a header comment.
pub fn workcell_text(m: &Matrix4<f64>, header: &str) -> String {
    let mut s = String::new();
    for line in header.lines() {
        s.push_str(&format!("# {line}\n"));
    }
    s.push_str(
        "# p_robot [m] = R * (p_reference [mm] / 1000) + t [m]; rows top to bottom.\n\
         robot_from_reference = [\n",
    );
    for r in 0..4 {
        let row: Vec<String> = (0..4).map(|c| num(m[(r, c)])).collect();
        s.push_str(&format!("  [{}],\n", row.join(", ")));
    }
    s.push_str("]\n");
    s
}

/// Writes `text` to `file`, creating its folder.
pub fn write(file: &Path, text: &str) -> Result<(), CalibError> {
    if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| CalibError::file(dir, e))?;
    }
    std::fs::write(file, text).map_err(|e| CalibError::file(file, e))
}

/// Writes `out` from `input` (servos.toml) with new zero offsets and reads it back.
pub fn write_servos(input: &Path, out: &Path, zero: &[(u8, f64)]) -> Result<Servos, CalibError> {
    let text = std::fs::read_to_string(input).map_err(|e| CalibError::file(input, e))?;
    write(out, &patch_servos(&text, input, zero)?)?;
    let servos = Servos::load(out)?;
    for &(id, deg) in zero {
        let got = servos
            .servos
            .iter()
            .find(|s| s.id == id)
            .map(|s| s.zero_offset_deg);
        if got != Some(deg) {
            return Err(CalibError::file(
                out,
                format!("servo {id}: zero_offset_deg reads back as {got:?}, wrote {deg}"),
            ));
        }
    }
    Ok(servos)
}

/// Writes `out` from `input` (tool.toml) with a new tip offset and reads it back.
pub fn write_tool(input: &Path, out: &Path, tip: [f64; 3]) -> Result<Tool, CalibError> {
    let text = std::fs::read_to_string(input).map_err(|e| CalibError::file(input, e))?;
    write(out, &patch_tool(&text, input, tip)?)?;
    let tool = Tool::load(out)?;
    if tool.tip_offset != tip {
        return Err(CalibError::file(
            out,
            "tip_offset does not read back as written",
        ));
    }
    Ok(tool)
}

/// Writes `out` from `input` (tool.toml) with `[removal] verified_tip_error_mm` set to
/// `worst_mm`, the worst tool tip `calibrate verify` measured: the plans' Monte Carlo draws
/// its tip error from it (`removal::montecarlo::tip_error`).
pub fn write_verified_tip(input: &Path, out: &Path, worst_mm: f64) -> Result<(), CalibError> {
    let text = std::fs::read_to_string(input).map_err(|e| CalibError::file(input, e))?;
    write(
        out,
        &patch_removal(&text, &[("verified_tip_error_mm", worst_mm)]),
    )
}

/// Writes workcell.toml and reads it back.
pub fn write_workcell(out: &Path, m: &Matrix4<f64>, header: &str) -> Result<Workcell, CalibError> {
    write_and_check(out, &workcell_text(m, header), m)
}

/// True when `line` is a TOML table header (`[name]`, `[[name]]`), not a row of an array.
fn is_table_header(line: &str) -> bool {
    let t = line.split('#').next().unwrap_or("").trim();
    let inner = t.trim_start_matches('[').trim_end_matches(']');
    t.starts_with('[')
        && t.ends_with(']')
        && !inner.is_empty()
        && inner
            .chars()
            .all(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | ' '))
}

/// The tables of the workcell.toml text `text` (`[turntable]`, ...) with the comment lines
/// right above the first one: everything after the top-level `robot_from_reference`, kept as
/// it is when the matrix is rewritten. Empty when the file has no table.
pub fn workcell_tables(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let Some(first) = lines.iter().position(|l| is_table_header(l)) else {
        return String::new();
    };
    let mut start = first;
    while start > 0 && lines[start - 1].trim_start().starts_with('#') {
        start -= 1;
    }
    lines[start..].join("\n") + "\n"
}

/// Writes `out` with a new `robot_from_reference` (and `header` comment), keeping the tables
/// of `input` (a turntable's `[turntable]` axis and centre, with their comments), and reads it
/// back: the matrix and every kept table must load as written.
pub fn update_workcell(
    input: &Path,
    out: &Path,
    m: &Matrix4<f64>,
    header: &str,
) -> Result<Workcell, CalibError> {
    let old = std::fs::read_to_string(input).map_err(|e| CalibError::file(input, e))?;
    let kept: toml::Table = read_toml(input)?;
    let tables = workcell_tables(&old);
    let mut text = workcell_text(m, header);
    if !tables.is_empty() {
        text.push('\n');
        text.push_str(&tables);
    }
    // Checked before writing: a table written inline (`turntable = {..}`) is not kept above.
    let others = |t: toml::Table| -> Vec<(String, toml::Value)> {
        t.into_iter()
            .filter(|(k, _)| k != "robot_from_reference")
            .collect()
    };
    let new: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| CalibError::file(out, e.message().replace('\n', " ")))?;
    if others(kept) != others(new) {
        return Err(CalibError::file(
            input,
            "its tables could not be kept (write [turntable] as a table, not inline)",
        ));
    }
    write_and_check(out, &text, m)
}

/// Writes workcell.toml text `text` and checks its matrix reads back as `m`.
fn write_and_check(out: &Path, text: &str, m: &Matrix4<f64>) -> Result<Workcell, CalibError> {
    write(out, text)?;
    let w = Workcell::load(out)?;
    if w.robot_from_reference != *m {
        return Err(CalibError::file(
            out,
            "robot_from_reference does not read back as written",
        ));
    }
    Ok(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removal_keys_are_replaced_in_place_or_added_under_the_table() {
        let text =
            "# tool\n[removal]\n# k\npreston_k_mm2_n = 1e-6\nspindle_rpm = 100.0\n[other]\nx = 1\n";
        let out = patch_removal(
            text,
            &[("preston_k_mm2_n", 2.5), ("preston_k_rel_sd", 0.25)],
        );
        assert_eq!(
            out,
            "# tool\n[removal]\npreston_k_rel_sd = 0.25\n# k\npreston_k_mm2_n = 2.5\nspindle_rpm = 100.0\n[other]\nx = 1\n"
        );
        assert_eq!(
            patch_removal("a = 1\n", &[("preston_k_mm2_n", 2.0)]),
            "a = 1\n\n[removal]\npreston_k_mm2_n = 2.0\n"
        );
    }

    #[test]
    fn table_headers_are_told_from_matrix_rows() {
        assert!(is_table_header("[turntable]  # the table"));
        assert!(is_table_header("[[servo]]"));
        assert!(!is_table_header("  [0.0, 1.0, 0.0, 0.28],"));
        assert!(!is_table_header("robot_from_reference = ["));
        assert!(!is_table_header("]"));
    }

    #[test]
    fn tables_keep_their_comments_and_an_inline_table_is_refused() {
        let text = "# head\nrobot_from_reference = [\n  [1.0, 0.0, 0.0, 0.0],\n]\n\n# axis\n# more\n[turntable]\naxis = [1.0, 0.0, 0.0]\n";
        assert_eq!(
            workcell_tables(text),
            "# axis\n# more\n[turntable]\naxis = [1.0, 0.0, 0.0]\n"
        );
        assert_eq!(workcell_tables("robot_from_reference = []\n"), "");
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.toml");
        let row = |r: usize| {
            format!(
                "[{}]",
                (0..4)
                    .map(|c| if c == r { "1.0" } else { "0.0" })
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        let m = (0..4).map(row).collect::<Vec<_>>().join(", ");
        let inline = format!(
            "robot_from_reference = [{m}]\nturntable = {{ axis = [1.0, 0.0, 0.0], centre = [0.0, 0.0, 0.0] }}\n"
        );
        std::fs::write(&input, inline).unwrap();
        let out = dir.path().join("out.toml");
        let e = update_workcell(&input, &out, &Matrix4::identity(), "t").unwrap_err();
        assert!(
            e.to_string()
                .contains("in.toml: its tables could not be kept"),
            "{e}"
        );
        assert!(!out.exists());
    }
}

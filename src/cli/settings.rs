//! Loading and checking the `--config` TOML of a command: syntax and type errors name the file
//! and the line (toml's spans), keys no setting reads are refused, and a setting out of its
//! range is reported at the line that sets it. Stage checks name the offending key in
//! backticks (`` `settle_ms` = 1e300 ms is outside 0..=60000 ms ``); [`ConfigFile::refuse`]
//! finds that key's line in the file.
use std::path::{Path, PathBuf};

use anyhow::anyhow;

/// A loaded `--config` file (or none: every setting at its default).
#[derive(Debug, Default)]
pub struct ConfigFile {
    /// The file, when one was given.
    pub path: Option<PathBuf>,
    /// Its text ("" without a file).
    pub text: String,
}

impl ConfigFile {
    /// Reads `path` (none: an empty file).
    pub fn read(path: Option<&Path>) -> anyhow::Result<ConfigFile> {
        let Some(path) = path else {
            return Ok(ConfigFile::default());
        };
        let meta =
            std::fs::metadata(path).map_err(|e| anyhow!("{}: --config: {e}", path.display()))?;
        anyhow::ensure!(
            meta.is_file() && meta.len() <= MAX_CONFIG_BYTES,
            "{}: --config: not a regular file of at most {MAX_CONFIG_BYTES} bytes",
            path.display()
        );
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow!("{}: --config: {e}", path.display()))?;
        Ok(ConfigFile {
            path: Some(path.to_path_buf()),
            text,
        })
    }

    /// Parses the text into `T` (missing keys at their defaults); errors name file and line.
    pub fn parse<T: serde::de::DeserializeOwned + Default>(&self) -> anyhow::Result<T> {
        if self.path.is_none() {
            return Ok(T::default());
        }
        toml::from_str(&self.text).map_err(|e| {
            let place = e
                .span()
                .map(|s| format!("line {}: ", line_at(&self.text, s.start)))
                .unwrap_or_default();
            let message = plain(&e.message().trim().replace('\n', " "));
            let message = match e.span() {
                Some(s) => unknown_key_message(&self.text, s.start, &message),
                None => message,
            };
            anyhow!("{}: {place}{message}", self.name())
        })
    }

    /// Like [`ConfigFile::parse`], and refuses keys that no field of `T` holds: `T` is written
    /// back to TOML and every key of the file must be there (for settings structs that do not
    /// deny unknown fields themselves).
    pub fn parse_strict<T>(&self) -> anyhow::Result<T>
    where
        T: serde::de::DeserializeOwned + serde::Serialize + Default,
    {
        let value: T = self.parse()?;
        if self.path.is_none() {
            return Ok(value);
        }
        let given: toml::Table = toml::from_str(&self.text)?;
        let known = toml::Table::try_from(&value).map_err(|e| anyhow!("{}: {e}", self.name()))?;
        if let Some(key) = unknown_key(&given, &known, "") {
            return Err(self.refuse("", &format!("unknown key `{key}`")));
        }
        Ok(value)
    }

    /// The error for a setting of `section` (a dotted table path, "" for the top level)
    /// refused with `message`, which names the key in backticks: "FILE: line N: message".
    pub fn refuse(&self, section: &str, message: &str) -> anyhow::Error {
        let key = message.split('`').nth(1).unwrap_or("");
        let line = match key.is_empty() {
            true => None,
            false => line_of_key(&self.text, section, key),
        };
        let place = line.map(|l| format!("line {l}: ")).unwrap_or_default();
        let scope = match section.is_empty() {
            true => String::new(),
            false => format!("[{section}] "),
        };
        anyhow!("{}: {place}{scope}{message}", self.name())
    }

    fn name(&self) -> String {
        match &self.path {
            Some(p) => p.display().to_string(),
            None => "settings (flags and defaults)".to_string(),
        }
    }
}

/// `message` without serde's Rust type names (issue 52: "expected struct GrindConfig",
/// "unsupported rust type"): a struct is a table of settings to the user, an enum one of
/// its names.
fn plain(message: &str) -> String {
    let mut out = message.replace("unsupported rust type", "a value no setting takes");
    for (rust, user) in [
        ("expected struct ", "expected a table of settings"),
        ("expected enum ", "expected one of the setting's names"),
    ] {
        while let Some(at) = out.find(rust) {
            let name_end = out[at + rust.len()..]
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .map_or(out.len(), |e| at + rust.len() + e);
            out.replace_range(at..name_end, user);
        }
    }
    out
}

/// Largest `--config` file read, bytes (a settings file is a few kB; this bounds the read).
const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// 1-based line of byte offset `at` in `text`.
fn line_at(text: &str, at: usize) -> usize {
    let at = at.min(text.len());
    text.as_bytes()[..at]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
        + 1
}

/// serde's "unknown field `k`, expected one of ..." (a struct that denies unknown fields) as
/// "unknown key `table.k`" with the table of the line at byte `at`, as
/// [`ConfigFile::parse_strict`] names it; any other message as it is.
fn unknown_key_message(text: &str, at: usize, message: &str) -> String {
    let Some(rest) = message.strip_prefix("unknown field `") else {
        return message.to_string();
    };
    let Some((key, expected)) = rest.split_once('`') else {
        return message.to_string();
    };
    let line = line_at(text, at);
    let table = text
        .lines()
        .take(line)
        .filter_map(|l| l.split('#').next()?.trim().strip_prefix('['))
        .last()
        .map(|h| h.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    let path = match table {
        Some(t) if !t.is_empty() => format!("{t}.{key}"),
        _ => key.to_string(),
    };
    format!("unknown key `{path}`{expected}")
}

/// The first key of `given` (dotted path) that `known` lacks.
fn unknown_key(given: &toml::Table, known: &toml::Table, prefix: &str) -> Option<String> {
    for (k, v) in given {
        let path = match prefix.is_empty() {
            true => k.clone(),
            false => format!("{prefix}.{k}"),
        };
        match (v, known.get(k)) {
            (_, None) => return Some(path),
            (toml::Value::Table(g), Some(toml::Value::Table(n))) => {
                if let Some(p) = unknown_key(g, n, &path) {
                    return Some(p);
                }
            }
            _ => {}
        }
    }
    None
}

/// An error `message` about a settings file `cycle` derived from the user's `--config`
/// (`OUT/inspect.toml`, `OUT/plan.toml`, `OUT/iter-K/run.toml`: the `[inspect]`, `[plan]` and
/// `[run]` tables of `source`) said again of `source`: its path, the line of the key in
/// backticks within that table, the table. None when the message is about no derived file
/// under `out` (issue 52: cycle blamed its own iter-1/run.toml for the user's setting).
pub fn blame_source(message: &str, out: &Path, source: &Path, text: &str) -> Option<String> {
    let (file, rest) = message.split_once(": ")?;
    let file = Path::new(file);
    let section = file.file_stem()?.to_str()?;
    let derived = ["inspect", "plan", "run"].contains(&section)
        && file.extension().is_some_and(|e| e == "toml")
        && file.starts_with(out);
    if !derived {
        return None;
    }
    let rest = match rest.strip_prefix("line ") {
        Some(r) => r.split_once(": ").map_or(r, |(_, m)| m),
        None => rest,
    };
    let (scope, rest) = match rest.strip_prefix('[').and_then(|r| r.split_once("] ")) {
        Some((inner, m)) => (format!("{section}.{inner}"), m),
        None => (section.to_string(), rest),
    };
    let key = rest.split('`').nth(1).unwrap_or("");
    let line = line_of_key(text, &scope, key)
        .or_else(|| line_of_key(text, section, key))
        .map(|l| format!("line {l}: "))
        .unwrap_or_default();
    Some(format!("{}: {line}[{scope}] {rest}", source.display()))
}

/// 1-based line where `key` (a name, or a dotted path ending in one) is set inside `section`
/// or one of its sub-tables.
pub fn line_of_key(text: &str, section: &str, key: &str) -> Option<usize> {
    let mut table = String::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if let Some(h) = line.strip_prefix('[') {
            table = h.trim_matches(|c| c == '[' || c == ']').trim().to_string();
            continue;
        }
        let Some((k, _)) = line.split_once('=') else {
            continue;
        };
        let k = k.trim().trim_matches('"');
        let full = match table.is_empty() {
            true => k.to_string(),
            false => format!("{table}.{k}"),
        };
        let in_section = section.is_empty() || full.starts_with(&format!("{section}."));
        if in_section && (full.ends_with(&format!(".{key}")) || full == key) {
            return Some(i + 1);
        }
    }
    None
}

pub use crate::settings::{above, at_least, in_range};

/// Slowest and fastest line speed the simulated board accepts, baud (the DOFBOT runs 115200;
/// outside this a byte's time is meaningless or overflows a wait).
const BAUD_RANGE: (f64, f64) = (300.0, 10_000_000.0);
/// Longest simulated reply latency or injected delay, ms (as the driver's waits).
const MAX_SIM_DELAY_MS: f64 = crate::bus::config::MAX_WAIT_MS;
/// Fastest simulated servo, raw counts per second (about 80 times the DOFBOT's no-load
/// speed).
const MAX_SERVO_SPEED: f64 = 250_000.0;
/// Largest simulated mounting offset, degrees (a servo a quarter turn off is not mounted).
const MAX_MOUNT_OFFSET_DEG: f64 = 90.0;

/// Checks the `[bus]` and `[sim]` settings of `arm`, `run` and `calibrate` before the link
/// opens: errors name the file, the line and the key.
pub fn check_link(
    file: &ConfigFile,
    bus: &crate::bus::BusConfig,
    sim: &crate::sim::SimOptions,
) -> anyhow::Result<()> {
    bus.check()
        .map_err(|e| file.refuse("bus", &e.to_string()))?;
    let t = &sim.timing;
    let checks = [
        in_range("baud", t.baud, BAUD_RANGE.0, BAUD_RANGE.1, "baud"),
        in_range(
            "reply_latency_ms",
            t.reply_latency_ms,
            0.0,
            MAX_SIM_DELAY_MS,
            "ms",
        ),
        in_range(
            "max_speed_counts_s",
            t.max_speed_counts_s,
            1.0,
            MAX_SERVO_SPEED,
            "counts/s",
        ),
        in_range("delay_ms", sim.faults.delay_ms, 0.0, MAX_SIM_DELAY_MS, "ms"),
        in_range("home_gripper_deg", sim.home_gripper_deg, 0.0, 180.0, "deg"),
    ];
    let offsets = sim.mechanics.mount_offset_deg.iter().map(|&d| {
        let m = MAX_MOUNT_OFFSET_DEG;
        in_range("mount_offset_deg", d, -m, m, "deg")
    });
    let start = sim.mechanics.start_physical_deg.iter().flatten();
    let start = start.map(|&d| in_range("start_physical_deg", d, 0.0, 270.0, "deg"));
    for c in checks.into_iter().chain(offsets).chain(start) {
        c.map_err(|m| file.refuse("sim", &m))?;
    }
    Ok(())
}

/// Checks the outlier filter's settings (`k`, `std_ratio` in `section`) and an optional voxel
/// edge (`voxel_mm`, top level) by the stage's own checks, naming the line that sets them.
/// What needs the cloud (k against its size, the voxel against its extent) the stage checks
/// when it runs.
pub fn check_filter(
    file: &ConfigFile,
    section: &str,
    sor: &crate::preprocess::SorConfig,
    voxel_mm: Option<f64>,
) -> anyhow::Result<()> {
    crate::preprocess::check_sor_settings(sor)
        .map_err(|(key, why)| file.refuse(section, &format!("`{key}`: {why}")))?;
    if let Some(v) = voxel_mm {
        crate::preprocess::check_voxel_value(v, "voxel down-sampling")
            .map_err(|e| file.refuse("", &format!("`voxel_mm`: {e}")))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serde_type_names_become_words() {
        let m = plain("invalid type: integer `5`, expected struct GrindConfig");
        assert_eq!(m, "invalid type: integer `5`, expected a table of settings");
        let m = plain("unsupported rust type; expected enum Mode_2 here");
        assert_eq!(
            m,
            "a value no setting takes; expected one of the setting's names here"
        );
    }

    #[test]
    fn keys_are_found_in_their_section() {
        let text = "[robot]\nurdf = \"x\"\n\n[bus]\n# gap\nframe_gap_ms = 2\nsettle_ms = 1e300\n\
                    [sim.timing]\nbaud = 0\n";
        assert_eq!(line_of_key(text, "bus", "settle_ms"), Some(7));
        assert_eq!(line_of_key(text, "sim", "baud"), Some(9));
        assert_eq!(line_of_key(text, "robot", "settle_ms"), None);
        assert_eq!(
            line_of_key("bus.settle_ms = 3\n", "bus", "settle_ms"),
            Some(1)
        );
        assert_eq!(line_at("a\nb\nc", 2), 2);
    }

    #[test]
    fn unknown_fields_are_named_with_their_table() {
        let text = "k = 3\n[compare.adaptive]\nrefine = 2\n";
        let at = text.find("refine").unwrap();
        let m = "unknown field `refine`, expected one of `a`, `b`";
        assert_eq!(
            unknown_key_message(text, at, m),
            "unknown key `compare.adaptive.refine`, expected one of `a`, `b`"
        );
        assert_eq!(
            unknown_key_message(text, 0, "unknown field `k`, expected `x`"),
            "unknown key `k`, expected `x`"
        );
        assert_eq!(unknown_key_message(text, 0, "invalid type"), "invalid type");
    }

    #[test]
    fn ranges_name_the_key_and_the_unit() {
        assert!(in_range("settle_ms", 100.0, 0.0, 1e3, "ms").is_ok());
        let e = in_range("settle_ms", 1e300, 0.0, 1e3, "ms").unwrap_err();
        assert!(e.starts_with("`settle_ms` = 1e300 ms"), "{e}");
        assert!(in_range("x", f64::NAN, 0.0, 1.0, "mm").is_err());
        assert!(above("h", 0.05, 0.0, 1.0, "mm").is_ok());
        assert!(above("h", 1.0, 0.0, 1.0, "mm").is_ok());
        let e = above("h", 0.0, 0.0, 1.0, "mm").unwrap_err();
        assert!(
            e.starts_with("`h` = 0.0 mm is outside 0.0 (excluded)"),
            "{e}"
        );
        assert!(above("h", f64::INFINITY, 0.0, f64::INFINITY, "mm").is_err());
    }
}

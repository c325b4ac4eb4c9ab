//! Provenance of a result, as a metrology record needs it: the input files (size, SHA-256),
//! units, the effective configuration (every setting, defaults included), the polishbot
//! version and git commit, the date and the host. The same block goes into the report page and,
//! as an added `provenance` key, into the JSON files of the run (docs/FORMATS.md).
use std::io::Read;
use std::path::Path;
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result};
use rayon::prelude::*;
use serde::Serialize;
use sha2::{Digest, Sha256};

/// The commit the binary was built from (build.rs; "unknown" without git).
pub const GIT_COMMIT: &str = env!("POLISHBOT_GIT_COMMIT");

/// Read buffer while hashing, bytes.
const CHUNK: usize = 1 << 20;

/// One input file.
#[derive(Debug, Clone, Serialize)]
pub struct InputFile {
    /// What it is to the command ("reference", "scan", ...).
    pub role: String,
    /// The path as given.
    pub path: String,
    /// Size, bytes.
    pub bytes: u64,
    /// SHA-256 of the contents, lower-case hex.
    pub sha256: String,
}

/// Where a result came from.
#[derive(Debug, Clone, Serialize)]
pub struct Provenance {
    /// The command that wrote it ("inspect", "plan").
    pub command: String,
    /// polishbot's version (Cargo.toml).
    pub polishbot_version: String,
    /// Git commit of the build, `-dirty` when built with changes, or "unknown".
    pub git_commit: String,
    /// When it was written, UTC, ISO 8601.
    pub date_utc: String,
    /// Host name ("unknown" when the system does not say).
    pub host: String,
    /// Units of the results.
    pub units: String,
    /// The input files.
    pub inputs: Vec<InputFile>,
    /// The effective configuration: every setting, defaults included.
    pub config: serde_json::Value,
}

impl Provenance {
    /// Hashes the `inputs` (role, path; in parallel) and records the rest now.
    pub fn new(
        command: &str,
        units: &str,
        inputs: &[(&str, &Path)],
        config: &impl Serialize,
    ) -> Result<Provenance> {
        let inputs = inputs
            .par_iter()
            .map(|(role, path)| InputFile::hash(role, path))
            .collect::<Result<Vec<_>>>()?;
        Provenance::of_inputs(command, units, inputs, config)
    }

    /// Records the `inputs` already hashed ([`InputFile::hash`], [`InputFile::held`]) and the
    /// rest now.
    pub fn of_inputs(
        command: &str,
        units: &str,
        inputs: Vec<InputFile>,
        config: &impl Serialize,
    ) -> Result<Provenance> {
        Ok(Provenance {
            command: command.to_string(),
            polishbot_version: env!("CARGO_PKG_VERSION").to_string(),
            git_commit: GIT_COMMIT.to_string(),
            date_utc: iso_utc(SystemTime::now()),
            host: host(),
            units: units.to_string(),
            inputs,
            config: serde_json::to_value(config).context("provenance: configuration")?,
        })
    }

    /// Key-value lines for a page: version, commit, date, host, units, one per input file,
    /// then the configuration as one JSON line.
    pub fn lines(&self) -> Vec<(String, String)> {
        let mut lines = vec![
            ("command".to_string(), self.command.clone()),
            (
                "polishbot".to_string(),
                format!(
                    "version {}, commit {}",
                    self.polishbot_version, self.git_commit
                ),
            ),
            ("date (UTC)".to_string(), self.date_utc.clone()),
            ("host".to_string(), self.host.clone()),
            ("units".to_string(), self.units.clone()),
        ];
        for f in &self.inputs {
            lines.push((
                format!("input: {}", f.role),
                format!("{} ({} bytes, SHA-256 {})", f.path, f.bytes, f.sha256),
            ));
        }
        lines.push(("configuration".to_string(), self.config.to_string()));
        lines
    }

    /// The JSON object `text` (pretty, by serde_json; the file `path`, named in errors) with
    /// this block added as its last key, `provenance`. The text before it stays byte for byte.
    pub fn stamp(&self, text: &str, path: &Path) -> Result<String> {
        let end = text
            .trim_end()
            .strip_suffix('}')
            .with_context(|| format!("{}: not a JSON object", path.display()))?;
        let block = serde_json::to_string_pretty(self)?.replace('\n', "\n  ");
        let body = end.trim_end();
        let sep = if body.ends_with('{') { "" } else { "," };
        Ok(format!("{body}{sep}\n  \"provenance\": {block}\n}}"))
    }
}

impl InputFile {
    /// A file this process holds in memory (`bytes`, as written to or read from `path`):
    /// recorded without reading the file back.
    pub fn held(role: &str, path: &Path, bytes: &[u8]) -> InputFile {
        InputFile {
            role: role.to_string(),
            path: path.display().to_string(),
            bytes: bytes.len() as u64,
            sha256: hex(Sha256::digest(bytes).as_slice()),
        }
    }

    /// Size and SHA-256 of the file `path`, read in chunks.
    pub fn hash(role: &str, path: &Path) -> Result<InputFile> {
        let mut f = std::fs::File::open(path)
            .with_context(|| format!("{}: cannot open", path.display()))?;
        let mut hasher = Sha256::new();
        let mut buf = vec![0u8; CHUNK];
        let mut bytes = 0u64;
        loop {
            let n = f
                .read(&mut buf)
                .with_context(|| format!("{}: byte {bytes}: cannot read", path.display()))?;
            if n == 0 {
                break;
            }
            hasher.update(&buf[..n]);
            bytes += n as u64;
        }
        Ok(InputFile {
            role: role.to_string(),
            path: path.display().to_string(),
            bytes,
            sha256: hex(hasher.finalize().as_slice()),
        })
    }
}

/// Lower-case hex of `bytes`.
fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The host's name, or "unknown".
fn host() -> String {
    let mut buf = [0u8; 256];
    // SAFETY: gethostname writes at most `buf.len()` bytes into the buffer we own.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
    match (rc, std::str::from_utf8(&buf[..end])) {
        (0, Ok(name)) if !name.is_empty() => name.to_string(),
        _ => "unknown".to_string(),
    }
}

/// `t` as `YYYY-MM-DDThh:mm:ssZ` (civil date from days since 1970, after H. Hinnant's
/// `civil_from_days`).
pub fn iso_utc(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn dates_match_known_calendar_days() {
        let at = |s| iso_utc(UNIX_EPOCH + Duration::from_secs(s));
        assert_eq!(at(0), "1970-01-01T00:00:00Z");
        // `date -u -d @951782400`: the leap day of 2000 (a year divisible by 400).
        assert_eq!(at(951_782_400), "2000-02-29T00:00:00Z");
        // `date -u -d @1798761599`: the last second of 2026.
        assert_eq!(at(1_798_761_599), "2026-12-31T23:59:59Z");
    }

    #[test]
    fn a_file_hashes_to_the_published_sha256_of_abc() {
        let dir = std::env::temp_dir().join(format!("pb-prov-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("abc.txt");
        std::fs::write(&f, "abc").unwrap();
        let h = InputFile::hash("x", &f).unwrap();
        // FIPS 180-2, appendix B.1.
        assert_eq!(
            h.sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(h.bytes, 3);
        let held = InputFile::held("x", &f, b"abc");
        assert_eq!((held.sha256.as_str(), held.bytes), (h.sha256.as_str(), 3));
        let json = dir.join("r.json");
        let p =
            Provenance::new("inspect", "mm", &[("x", &f)], &serde_json::json!({"k": 2})).unwrap();
        let text = p.stamp("{\n  \"a\": 1\n}", &json).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["a"], 1);
        assert_eq!(v["provenance"]["inputs"][0]["sha256"], h.sha256);
        assert_eq!(v["provenance"]["config"]["k"], 2);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

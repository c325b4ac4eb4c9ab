//! Each stage config's defaults are written once: in its `Default` impl. The doc comment of a
//! field states the same value ("default 20", "(default 0.6, ...)", "Default false"); the test
//! here reads every stage config's source and checks each stated default against
//! `Default::default()` serialised, so a default changed in one place and not the other fails.
//! A default the doc derives from something else ("default 2 voxel" for a `None` field, "default
//! [`VOXEL_SPACINGS`] mr") is not a literal and is left to the prose.
#![cfg(test)]

use serde::Serialize;

/// The literal defaults stated in the doc comments of the fields of `struct_name` in
/// `source`: (field, the text after "default"), for the fields that state one.
fn stated_defaults(source: &str, struct_name: &str) -> Vec<(String, String)> {
    let head = format!("pub struct {struct_name} {{");
    let Some(start) = source.find(&head) else {
        panic!("no `{head}` in the source");
    };
    let mut out = Vec::new();
    let mut doc = String::new();
    for line in source[start + head.len()..].lines() {
        let line = line.trim();
        if line == "}" {
            break;
        }
        if let Some(text) = line.strip_prefix("///") {
            doc.push(' ');
            doc.push_str(text.trim());
            continue;
        }
        let Some(field) = line.strip_prefix("pub ").and_then(|l| l.split_once(':')) else {
            continue;
        };
        if let Some(value) = default_in(&doc) {
            out.push((field.0.trim().to_string(), value));
        }
        doc.clear();
    }
    out
}

/// The token after the first "default" (or "Default", "default:") in `doc`: up to a space,
/// `;`, `)` or a `,` not inside a number ("30,000"); a closing `.` dropped.
fn default_in(doc: &str) -> Option<String> {
    let at = doc.find("default ").or_else(|| doc.find("Default "))?;
    let rest = doc[at + "default ".len()..].trim_start_matches(": ");
    let chars: Vec<char> = rest.chars().collect();
    let mut token = String::new();
    for (i, &c) in chars.iter().enumerate() {
        let thousands = c == ',' && chars.get(i + 1).is_some_and(char::is_ascii_digit);
        if c.is_whitespace() || c == ';' || c == ')' || (c == ',' && !thousands) {
            break;
        }
        token.push(c);
    }
    let token = token.strip_suffix('.').unwrap_or(&token).to_string();
    (!token.is_empty()).then_some(token)
}

/// Whether the stated `text` is the default `value`: numbers within 1e-12 (relative), a range
/// "a..b" the pair [a, b], bools equal, an enum variant ("[`Orientation::Auto`]", "auto") its
/// serialised name (case and `_` ignored).
fn agrees(text: &str, value: &toml::Value) -> bool {
    let plain: String = text.chars().filter(|c| !"[]`\"".contains(*c)).collect();
    let number = |t: &str| t.replace([',', '_'], "").parse::<f64>().ok();
    let close = |x: f64, n: f64| (x - n).abs() <= 1e-12 * x.abs().max(n.abs());
    match value {
        toml::Value::Integer(i) => number(&plain).is_some_and(|n| close(*i as f64, n)),
        toml::Value::Float(x) => number(&plain).is_some_and(|n| close(*x, n)),
        toml::Value::Boolean(b) => plain == b.to_string(),
        toml::Value::String(s) => {
            let variant = plain.rsplit("::").next().unwrap_or("").to_lowercase();
            variant == s.replace('_', "").to_lowercase()
        }
        toml::Value::Array(items) => {
            let parts: Vec<&str> = plain.split("..").collect();
            parts.len() == items.len() && parts.iter().zip(items).all(|(p, v)| agrees(p, v))
        }
        _ => false,
    }
}

/// The fields of `T`'s source whose stated default disagrees with `T::default()`, and the
/// number of stated defaults checked.
fn disagreements<T: Serialize + Default>(source: &str, name: &str) -> (Vec<String>, usize) {
    let value = toml::Table::try_from(T::default()).expect("a config serialises to TOML");
    let mut bad = Vec::new();
    let mut checked = 0;
    for (field, text) in stated_defaults(source, name) {
        // A `None` default is derived at run time ("default 2 voxel"): not a literal.
        let Some(v) = value.get(&field) else {
            continue;
        };
        // Tables (nested configs) have their own check.
        if v.is_table() {
            continue;
        }
        checked += 1;
        if !agrees(&text, v) {
            bad.push(format!("{name}.{field}: doc says {text}, Default is {v}"));
        }
    }
    (bad, checked)
}

/// Checks each config against its source file; all disagreements in one message.
macro_rules! check_configs {
    ($($ty:ty => $file:literal),* $(,)?) => {{
        let mut bad = Vec::new();
        let mut checked = 0;
        $(
            let (b, n) = disagreements::<$ty>(
                include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/", $file)),
                stringify!($ty).rsplit("::").next().unwrap(),
            );
            bad.extend(b);
            checked += n;
        )*
        (bad, checked)
    }};
}

#[test]
fn stated_defaults_are_parsed_as_written() {
    let src = "pub struct C {\n    /// Neighbours. Default 20.\n    pub k: usize,\n    \
               /// Cap (default 30,000; each start...).\n    pub cap: usize,\n    \
               /// Scale (default 2 voxel).\n    pub r: Option<f64>,\n    /// No word.\n    \
               pub x: f64,\n}\n";
    let got = stated_defaults(src, "C");
    let want = [("k", "20"), ("cap", "30,000"), ("r", "2")];
    let want: Vec<(String, String)> = want
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    assert_eq!(got, want);
    assert!(agrees("30,000", &toml::Value::Integer(30_000)));
    assert!(!agrees("0.5", &toml::Value::Float(0.6)));
    assert!(agrees("false", &toml::Value::Boolean(false)));
    assert!(agrees(
        "[`Orientation::FromExisting`]",
        &"from_existing".into()
    ));
    let pair = toml::Value::Array(vec![0.04.into(), 3.0.into()]);
    assert!(agrees("0.04..3", &pair));
    assert!(!agrees("0.04..2", &pair));
}

#[test]
fn every_stated_default_is_the_default_impl() {
    let (bad, checked) = check_configs!(
        crate::preprocess::SorConfig => "src/preprocess/sor.rs",
        crate::preprocess::NormalConfig => "src/preprocess/normals.rs",
        crate::preprocess::CurvatureSampleConfig => "src/preprocess/curvature.rs",
        crate::preprocess::PreprocessConfig => "src/preprocess/pipeline.rs",
        crate::register::RegisterConfig => "src/register/config.rs",
        crate::regions::RegionConfig => "src/regions/mod.rs",
        crate::report::ReportConfig => "src/report/mod.rs",
        crate::synth::SynthConfig => "src/synth/mod.rs",
        crate::acquire::MergeConfig => "src/acquire/mod.rs",
    );
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    assert!(checked >= 20, "only {checked} stated defaults found");
}

//! Each stage config's defaults are written once: in its `Default` impl. The doc comment of a
//! field states the same value ("default 20", "(default 0.6, ...)", "Default false"); the test
//! here reads every stage config's source and checks each stated default against
//! `Default::default()` serialised, so a default changed in one place and not the other fails.
//! A default the doc derives from something else ("default 2 voxel" for a `None` field, "default
//! [`VOXEL_SPACINGS`] mr") is not a literal and is left to the prose.

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
/// `;`, `)`, a `:` ending a word or a `,` that does not go on with a number ("30,000", "4, -3, 0"
/// stay whole, spaces dropped); a closing `.` dropped.
fn default_in(doc: &str) -> Option<String> {
    let at = doc.find("default ").or_else(|| doc.find("Default "))?;
    let rest = doc[at + "default ".len()..].trim_start_matches(": ");
    let chars: Vec<char> = rest.chars().collect();
    let mut token = String::new();
    let mut i = 0;
    while let Some(&c) = chars.get(i) {
        if c == ',' {
            let next: String = chars[i + 1..].iter().collect();
            let next = next.trim_start();
            let digit = |s: &str| s.chars().next().is_some_and(|d| d.is_ascii_digit());
            if !(digit(next) || next.strip_prefix('-').is_some_and(digit)) {
                break;
            }
            token.push(',');
            i += 1 + (chars.len() - i - 1 - next.chars().count());
            continue;
        }
        let colon = c == ':' && chars.get(i + 1).is_none_or(|n| n.is_whitespace());
        if c.is_whitespace() || c == ';' || c == ')' || colon {
            break;
        }
        token.push(c);
        i += 1;
    }
    let token = token.strip_suffix('.').unwrap_or(&token).to_string();
    (!token.is_empty()).then_some(token)
}

/// Whether the stated `text` is the default `value`, or `None` when the text is prose, not a
/// literal of the value's type ("default cell", "+z"). Numbers agree within 1e-12 (relative);
/// a list "4, -3, 0" or a range "a..b" is compared item by item, and one number stands for
/// every item; bools are equal; an enum variant ("[`Orientation::Auto`]", "auto") is its
/// serialised name (case and `_` ignored).
fn agrees(text: &str, value: &toml::Value) -> Option<bool> {
    let plain: String = text.chars().filter(|c| !"[]`\"".contains(*c)).collect();
    let number = |t: &str| t.replace([',', '_'], "").parse::<f64>().ok();
    let close = |x: f64, n: f64| (x - n).abs() <= 1e-12 * x.abs().max(n.abs());
    match value {
        toml::Value::Integer(i) => number(&plain).map(|n| close(*i as f64, n)),
        toml::Value::Float(x) => number(&plain).map(|n| close(*x, n)),
        toml::Value::Boolean(b) => ["true", "false"]
            .contains(&plain.as_str())
            .then(|| plain == b.to_string()),
        toml::Value::String(s) => {
            let variant = plain.rsplit("::").next().unwrap_or("").to_lowercase();
            Some(variant == s.replace('_', "").to_lowercase())
        }
        toml::Value::Array(items) => {
            let parts: Vec<&str> = plain.split([',']).flat_map(|p| p.split("..")).collect();
            let parts = match parts.len() {
                1 => vec![parts[0]; items.len()],
                _ => parts,
            };
            if parts.len() != items.len() {
                return parts.iter().all(|p| number(p).is_some()).then_some(false);
            }
            let each: Option<Vec<bool>> =
                parts.iter().zip(items).map(|(p, v)| agrees(p, v)).collect();
            each.map(|e| e.iter().all(|&ok| ok))
        }
        _ => None,
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
        match agrees(&text, v) {
            Some(true) => checked += 1,
            Some(false) => bad.push(format!("{name}.{field}: doc says {text}, Default is {v}")),
            None => {}
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
    assert_eq!(agrees("30,000", &toml::Value::Integer(30_000)), Some(true));
    assert_eq!(agrees("0.5", &toml::Value::Float(0.6)), Some(false));
    assert_eq!(agrees("cell", &toml::Value::Float(30.0)), None);
    assert_eq!(agrees("false", &toml::Value::Boolean(false)), Some(true));
    let variant = toml::Value::from("from_existing");
    assert_eq!(
        agrees("[`Orientation::FromExisting`]", &variant),
        Some(true)
    );
    let pair = toml::Value::Array(vec![0.04.into(), 3.0.into()]);
    assert_eq!(agrees("0.04..3", &pair), Some(true));
    assert_eq!(agrees("0.04..2", &pair), Some(false));
    let triple = toml::Value::Array(vec![4.0.into(), (-3.0).into(), 0.0.into()]);
    let doc = " A point (default 4, -3, 0: off-centre).";
    assert_eq!(default_in(doc).as_deref(), Some("4,-3,0"));
    assert_eq!(agrees("4,-3,0", &triple), Some(true));
    assert_eq!(
        agrees("0", &toml::Value::Array(vec![0.0.into(); 6])),
        Some(true)
    );
    assert_eq!(
        default_in(" Score (default 0.6, i.e. d).").as_deref(),
        Some("0.6")
    );
}

#[test]
fn every_stated_default_is_the_default_impl() {
    let (bad, checked) = check_configs!(
        polishbot::preprocess::SorConfig => "src/preprocess/sor.rs",
        polishbot::preprocess::NormalConfig => "src/preprocess/normals.rs",
        polishbot::preprocess::CurvatureSampleConfig => "src/preprocess/curvature.rs",
        polishbot::preprocess::PreprocessConfig => "src/preprocess/pipeline.rs",
        polishbot::register::RegisterConfig => "src/register/config.rs",
        polishbot::regions::RegionConfig => "src/regions/mod.rs",
        polishbot::report::ReportConfig => "src/report/input.rs",
        polishbot::synth::SynthConfig => "src/synth/config.rs",
        polishbot::acquire::MergeConfig => "src/acquire/config.rs",
        polishbot::synth::TurntableConfig => "src/synth/turntable.rs",
        polishbot::synth::FemoralShape => "src/synth/femoral.rs",
        polishbot::motion::PlanConfig => "src/motion/config.rs",
        polishbot::motion::TrajectoryConfig => "src/motion/trajectory.rs",
        polishbot::motion::ValidationConfig => "src/motion/validate.rs",
        polishbot::motion::CollisionConfig => "src/motion/collide/solids.rs",
        polishbot::robot::IkConfig => "src/robot/ik.rs",
        polishbot::bus::BusConfig => "src/bus/config.rs",
        polishbot::sim::SimTiming => "src/sim/model.rs",
        polishbot::sim::Faults => "src/sim/model.rs",
        polishbot::sim::Mechanics => "src/sim/model.rs",
        polishbot::sim::SimOptions => "src/sim/arm.rs",
        polishbot::calibrate::CalibrationConfig => "src/calibrate/config.rs",
        polishbot::cell::RunConfig => "src/cell/stream.rs",
        polishbot::removal::RemovalConfig => "src/removal/mod.rs",
        polishbot::sim::GrindConfig => "src/sim/grinding.rs",
    );
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    assert!(checked >= 50, "only {checked} stated defaults found");
}

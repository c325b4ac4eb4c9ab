//! cargo fuzz run config: the `--config` loader must return Ok or Err on any text, never
//! panic: TOML syntax and type errors with their line, unknown keys, the bus settings' ranges
//! and the line lookup of a refused key.
#![no_main]
use libfuzzer_sys::fuzz_target;
use polishbot::cli::settings::ConfigFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let file = ConfigFile {
        path: Some("fuzz.toml".into()),
        text: text.to_string(),
    };
    if let Ok(bus) = file.parse::<polishbot::bus::BusConfig>() {
        if let Err(e) = bus.check() {
            let _ = file.refuse("bus", &e.to_string());
        }
    }
    let _ = file.parse_strict::<polishbot::motion::PlanConfig>();
});

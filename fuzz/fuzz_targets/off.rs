//! cargo fuzz run off: the OFF reader must return Ok or Err on any bytes, never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = polishbot::cloud::parse(data, polishbot::cloud::Format::Off);
});

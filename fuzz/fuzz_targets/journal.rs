//! cargo fuzz run journal: the journal reader (`run --resume`) must return Ok or Err on any
//! bytes, never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = polishbot::bus::ResumePoint::parse(std::path::Path::new("fuzz.jsonl"), data);
});

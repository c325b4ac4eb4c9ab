//! cargo fuzz run obj: the OBJ reader must return Ok or Err on any bytes, never panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = polishbot::cloud::parse(data, polishbot::cloud::Format::Obj);
});

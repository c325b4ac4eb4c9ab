//! cargo-fuzz target for the reply decoder: `cargo fuzz run reply_decoder` from
//! `firmware-protocol/` (scripts/test.sh runs it for a bounded time, on stable with
//! RUSTC_BOOTSTRAP=1).
//! The body is shared with the stable smoke-fuzz test in dofbot-protocol.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dofbot_protocol::check::reply_decoder_invariants(data);
});

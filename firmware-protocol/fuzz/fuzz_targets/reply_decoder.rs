//! cargo-fuzz target for the reply decoder and the commands' I2C transactions:
//! `cargo fuzz run reply_decoder` from `firmware-protocol/` (scripts/test.sh runs it for a
//! bounded time, on stable with RUSTC_BOOTSTRAP=1). Every reply layout (position with and
//! without its echo, ping of 1 and 2 bytes) must round-trip, and every command frame in the
//! input must map onto its Arm_Lib I2C transactions.
//! The bodies are shared with the stable smoke-fuzz tests in dofbot-protocol.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dofbot_protocol::check::reply_decoder_invariants(data);
    dofbot_protocol::check::i2c_invariants(data);
});

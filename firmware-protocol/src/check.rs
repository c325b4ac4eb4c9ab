//! Invariants over arbitrary input: of the reply decoder (the body of the cargo-fuzz target
//! `firmware-protocol/fuzz/fuzz_targets/reply_decoder.rs`) and of the commands' I2C
//! transactions (`fuzz_targets/i2c_transactions.rs`), and of the stable smoke-fuzz tests, so
//! both check exactly the same thing.
use crate::commands::{Command, FUNC_MOVE_ALL};
use crate::frame::{checksum, Decoder, Direction, FrameError, MAX_LEN, MIN_LEN};
use crate::i2c::{i2c_reply, Transaction, MAX_BLOCK, REG_MOVE_ALL_TIME};
use crate::replies::Reply;

/// Feeds `data` to a reply decoder in chunks whose sizes are taken from `data` itself and
/// checks, panicking on a violation:
/// * every frame returned is well formed: re-encoding it gives bytes that appear in the
///   input, with a correct checksum;
/// * length errors only report LEN outside `MIN_LEN..=MAX_LEN`, checksum errors only
///   mismatching sums;
/// * decoding the same bytes in one piece yields the same events;
/// * [`Reply::parse`] never panics, and a reply it accepts (any layout: position with or
///   without its echo, ping status with or without the id) encodes back to the same frame.
pub fn reply_decoder_invariants(data: &[u8]) {
    let chunked = run(data, true);
    let whole = run(data, false);
    assert!(chunked == whole, "chunking changed the decoded events");
}

/// Events fingerprint: (ok frames, errors) counted and hashed in a fixed-size accumulator.
#[derive(PartialEq, Eq)]
struct Summary {
    frames: u32,
    errors: u32,
    hash: u64,
}

fn mix(h: u64, v: u64) -> u64 {
    (h ^ v).wrapping_mul(0x100_0000_01B3)
}

fn run(data: &[u8], chunked: bool) -> Summary {
    let mut dec = Decoder::replies();
    let mut s = Summary {
        frames: 0,
        errors: 0,
        hash: 0xCBF2_9CE4_8422_2325,
    };
    let mut rest = data;
    let mut i = 0usize;
    while !rest.is_empty() {
        let take = if chunked {
            1 + (rest[0] as usize % 7).min(rest.len() - 1)
        } else {
            rest.len()
        };
        let (chunk, tail) = rest.split_at(take);
        rest = tail;
        for ev in dec.feed(chunk) {
            i += 1;
            match ev {
                Ok(frame) => {
                    s.frames += 1;
                    let mut buf = [0u8; crate::frame::MAX_FRAME];
                    let n = frame.encode(Direction::ToHost, &mut buf).expect("fits");
                    assert!(
                        data.windows(n).any(|w| w == &buf[..n]),
                        "decoded a frame that is not in the input"
                    );
                    let len = buf[2];
                    assert_eq!(buf[n - 1], checksum(len, frame.kind(), frame.payload()));
                    if let Ok(reply) = Reply::parse(&frame) {
                        assert!(
                            reply.to_frame() == frame,
                            "reply layout does not round-trip"
                        );
                    }
                    s.hash = mix(s.hash, n as u64 ^ ((frame.kind() as u64) << 8));
                }
                Err(FrameError::BadLength { len }) => {
                    s.errors += 1;
                    assert!(!(MIN_LEN..=MAX_LEN).contains(&len));
                    s.hash = mix(s.hash, 0x1_0000 | len as u64);
                }
                Err(FrameError::BadChecksum { expected, got, .. }) => {
                    s.errors += 1;
                    assert_ne!(expected, got);
                    s.hash = mix(s.hash, 0x2_0000 | got as u64);
                }
            }
            s.hash = mix(s.hash, i as u64);
        }
    }
    s
}

/// Decodes host frames from `data` and checks, for every valid command among them, that its
/// I2C transactions carry the frame's bytes: a block write carries the payload (a six-servo
/// move: the time to 0x1E, then the twelve position bytes to 0x1D), a byte write the FUNC as
/// register, a request ends in a read of that register; and that [`i2c_reply`] of any value
/// (taken from `data`) never panics and swaps a position word.
pub fn i2c_invariants(data: &[u8]) {
    let mut dec = Decoder::commands();
    let value = match data {
        [a, b, ..] => u16::from_le_bytes([*a, *b]),
        _ => 0,
    };
    for frame in dec.feed(data).flatten() {
        let Ok(cmd) = Command::parse(&frame) else {
            continue;
        };
        let ops = cmd.to_i2c();
        let ops = ops.as_slice();
        let p = frame.payload();
        match ops {
            [Transaction::WriteBlock { reg: t, .. }, Transaction::WriteBlock { reg: m, .. }] => {
                assert!(*t == REG_MOVE_ALL_TIME && *m == FUNC_MOVE_ALL);
                assert!(ops[0].block_bytes() == &p[MAX_BLOCK..]);
                assert!(ops[1].block_bytes() == &p[..MAX_BLOCK]);
            }
            [Transaction::WriteBlock { reg, .. }] => {
                assert!(*reg == frame.kind() && ops[0].block_bytes() == p);
            }
            [Transaction::WriteByte { reg, .. }] => assert!(*reg == frame.kind()),
            [Transaction::WriteByte { reg, .. }, Transaction::Wait { .. }, read] => {
                assert!(*reg == frame.kind());
                assert!(
                    matches!(read, Transaction::ReadWord { reg: r } | Transaction::ReadByte { reg: r } if r == reg)
                );
            }
            _ => panic!("unexpected transactions for 0x{:02X}", frame.kind()),
        }
        if let Ok(Some(Reply::Position { raw, .. })) = i2c_reply(&cmd, value) {
            assert!(raw == value.swap_bytes());
        }
    }
}

//! Invariants of the reply decoder over arbitrary input: the body of the cargo-fuzz target
//! (`firmware-protocol/fuzz/fuzz_targets/reply_decoder.rs`) and of the stable smoke-fuzz
//! test, so both check exactly the same thing.
use crate::frame::{checksum, Decoder, Direction, FrameError, MAX_LEN, MIN_LEN};
use crate::replies::Reply;

/// Feeds `data` to a reply decoder in chunks whose sizes are taken from `data` itself and
/// checks, panicking on a violation:
/// * every frame returned is well formed: re-encoding it gives bytes that appear in the
///   input, with a correct checksum;
/// * length errors only report LEN outside `MIN_LEN..=MAX_LEN`, checksum errors only
///   mismatching sums;
/// * decoding the same bytes in one piece yields the same events;
/// * [`Reply::parse`] never panics.
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
                    let _ = Reply::parse(&frame);
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

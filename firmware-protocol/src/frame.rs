//! The frame envelope, its checksum and a streaming decoder.
//!
//! Byte layout (DOFBOT.md, "UART frame"):
//!
//! ```text
//! host -> board:  FF FC LEN FUNC payload... CHK
//! board -> host:  FF FB LEN TYPE payload... CHK
//! LEN = number of bytes from LEN through CHK = frame length - 2 = payload length + 3
//! CHK = (LEN + FUNC/TYPE + every payload byte) mod 256
//! ```
//!
//! Multi-byte values inside payloads are big-endian. The worked example of DOFBOT.md, servo 1
//! to raw 2000 in 500 ms, is `FF FC 07 11 07 D0 01 F4 E4`.
use core::fmt;

/// First header byte of both directions.
pub const SYNC: u8 = 0xFF;
/// Second header byte of host-to-board frames.
pub const HOST_MARK: u8 = 0xFC;
/// Second header byte of board-to-host frames.
pub const BOARD_MARK: u8 = 0xFB;
/// Smallest LEN: a frame with an empty payload (LEN, FUNC/TYPE, CHK).
pub const MIN_LEN: u8 = 3;
/// Largest LEN this crate accepts. The longest known frame (0x1D, six servos) has LEN 0x11;
/// anything above this is treated as a corrupted length byte.
pub const MAX_LEN: u8 = 0x20;
/// Largest payload: `MAX_LEN - 3`.
pub const MAX_PAYLOAD: usize = MAX_LEN as usize - 3;
/// Largest whole frame in bytes: `MAX_LEN + 2`.
pub const MAX_FRAME: usize = MAX_LEN as usize + 2;

/// Which way a frame travels: it sets the second header byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Host to board: `FF FC`.
    ToBoard,
    /// Board to host: `FF FB`.
    ToHost,
}

impl Direction {
    /// The second header byte of this direction.
    pub const fn mark(self) -> u8 {
        match self {
            Direction::ToBoard => HOST_MARK,
            Direction::ToHost => BOARD_MARK,
        }
    }
}

/// CHK of a frame: `(LEN + kind + payload bytes) mod 256`.
pub fn checksum(len: u8, kind: u8, payload: &[u8]) -> u8 {
    payload
        .iter()
        .fold(len.wrapping_add(kind), |acc, b| acc.wrapping_add(*b))
}

/// Failure to encode a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EncodeError {
    /// The caller's buffer is shorter than the frame.
    BufferTooSmall {
        /// Bytes the frame needs.
        needed: usize,
    },
    /// The payload is longer than [`MAX_PAYLOAD`].
    PayloadTooLong {
        /// Payload length given.
        len: usize,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::BufferTooSmall { needed } => {
                write!(f, "frame needs {needed} bytes, buffer is shorter")
            }
            EncodeError::PayloadTooLong { len } => {
                write!(f, "payload of {len} bytes exceeds {MAX_PAYLOAD}")
            }
        }
    }
}

/// A decoded (or to-be-encoded) frame: its FUNC/TYPE byte and payload, without header, LEN
/// and CHK.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    kind: u8,
    len: u8,
    payload: [u8; MAX_PAYLOAD],
}

impl Frame {
    /// A frame of FUNC/TYPE `kind` carrying `payload`.
    pub fn new(kind: u8, payload: &[u8]) -> Result<Frame, EncodeError> {
        if payload.len() > MAX_PAYLOAD {
            return Err(EncodeError::PayloadTooLong { len: payload.len() });
        }
        let mut p = [0u8; MAX_PAYLOAD];
        p[..payload.len()].copy_from_slice(payload);
        Ok(Frame {
            kind,
            len: payload.len() as u8,
            payload: p,
        })
    }

    /// The FUNC (host frames) or TYPE (board frames) byte.
    pub fn kind(&self) -> u8 {
        self.kind
    }

    /// The payload bytes.
    pub fn payload(&self) -> &[u8] {
        &self.payload[..self.len as usize]
    }

    /// Length in bytes of the whole encoded frame (header to CHK).
    pub fn encoded_len(&self) -> usize {
        self.len as usize + 5
    }

    /// Writes the whole frame for `direction` into `buf`; returns the number of bytes written.
    pub fn encode(&self, direction: Direction, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let n = self.encoded_len();
        if buf.len() < n {
            return Err(EncodeError::BufferTooSmall { needed: n });
        }
        let len = self.len + MIN_LEN;
        buf[0] = SYNC;
        buf[1] = direction.mark();
        buf[2] = len;
        buf[3] = self.kind;
        buf[4..4 + self.len as usize].copy_from_slice(self.payload());
        buf[n - 1] = checksum(len, self.kind, self.payload());
        Ok(n)
    }
}

impl fmt::Debug for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Frame")
            .field("kind", &self.kind)
            .field("payload", &self.payload())
            .finish()
    }
}

/// A framing error, reported by the decoder as a value (it then resynchronises).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// CHK does not match the sum of the received bytes.
    BadChecksum {
        /// FUNC/TYPE byte of the bad frame.
        kind: u8,
        /// Checksum computed from the received bytes.
        expected: u8,
        /// Checksum byte received.
        got: u8,
    },
    /// LEN outside `MIN_LEN..=MAX_LEN`.
    BadLength {
        /// LEN byte received.
        len: u8,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FrameError::BadChecksum {
                kind,
                expected,
                got,
            } => write!(
                f,
                "bad checksum in frame type 0x{kind:02X}: got 0x{got:02X}, expected 0x{expected:02X}"
            ),
            FrameError::BadLength { len } => write!(
                f,
                "bad frame length 0x{len:02X} (allowed 0x{MIN_LEN:02X}..0x{MAX_LEN:02X})"
            ),
        }
    }
}

/// Streaming decoder for one direction: push bytes in any chunking, take frames and errors out.
///
/// Bytes that cannot start a frame are skipped (counted by [`Decoder::skipped`]). After a bad
/// length or checksum only the first header byte is dropped and the rest rescanned, so a good
/// frame hidden behind a corrupted one is still found.
#[derive(Debug, Clone)]
pub struct Decoder {
    mark: u8,
    buf: [u8; MAX_FRAME],
    n: usize,
    skipped: u64,
}

impl Decoder {
    /// A decoder for frames travelling in `direction`.
    pub const fn new(direction: Direction) -> Decoder {
        Decoder {
            mark: direction.mark(),
            buf: [0; MAX_FRAME],
            n: 0,
            skipped: 0,
        }
    }

    /// Decoder for board replies (`FF FB`).
    pub const fn replies() -> Decoder {
        Decoder::new(Direction::ToHost)
    }

    /// Decoder for host commands (`FF FC`), as a simulated board uses it.
    pub const fn commands() -> Decoder {
        Decoder::new(Direction::ToBoard)
    }

    /// Bytes skipped so far because they could not start a frame.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Bytes held waiting for the rest of a frame.
    pub fn pending(&self) -> usize {
        self.n
    }

    /// Forgets any partial frame (the skip counter is kept).
    pub fn reset(&mut self) {
        self.n = 0;
    }

    /// Feeds `input`; the returned iterator yields every frame or error it completes.
    /// Bytes not consumed when the iterator is dropped early are lost, so drain it.
    pub fn feed<'a>(&'a mut self, input: &'a [u8]) -> Feed<'a> {
        Feed { dec: self, input }
    }

    fn drop_front(&mut self, k: usize) {
        self.buf.copy_within(k..self.n, 0);
        self.n -= k;
    }

    fn push(&mut self, b: u8) {
        if self.n == MAX_FRAME {
            // Unreachable when poll() runs after each push; keep the invariant anyway.
            self.drop_front(1);
            self.skipped += 1;
        }
        self.buf[self.n] = b;
        self.n += 1;
    }

    fn poll(&mut self) -> Option<Result<Frame, FrameError>> {
        loop {
            let junk = self.buf[..self.n]
                .iter()
                .position(|&b| b == SYNC)
                .unwrap_or(self.n);
            if junk > 0 {
                self.drop_front(junk);
                self.skipped += junk as u64;
            }
            if self.n < 2 {
                return None;
            }
            if self.buf[1] != self.mark {
                self.drop_front(1);
                self.skipped += 1;
                continue;
            }
            if self.n < 3 {
                return None;
            }
            let len = self.buf[2];
            if !(MIN_LEN..=MAX_LEN).contains(&len) {
                self.drop_front(1);
                return Some(Err(FrameError::BadLength { len }));
            }
            let total = len as usize + 2;
            if self.n < total {
                return None;
            }
            let kind = self.buf[3];
            let payload = &self.buf[4..total - 1];
            let expected = checksum(len, kind, payload);
            let got = self.buf[total - 1];
            if expected != got {
                self.drop_front(1);
                return Some(Err(FrameError::BadChecksum {
                    kind,
                    expected,
                    got,
                }));
            }
            let frame = Frame::new(kind, payload).expect("len <= MAX_LEN");
            self.drop_front(total);
            return Some(Ok(frame));
        }
    }
}

/// Iterator over the frames and errors completed by [`Decoder::feed`].
#[derive(Debug)]
pub struct Feed<'a> {
    dec: &'a mut Decoder,
    input: &'a [u8],
}

impl Iterator for Feed<'_> {
    type Item = Result<Frame, FrameError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(ev) = self.dec.poll() {
                return Some(ev);
            }
            let (&b, rest) = self.input.split_first()?;
            self.input = rest;
            self.dec.push(b);
        }
    }
}

/// A frame's bytes as upper-case hex pairs separated by single spaces (`FF FC 07 11 ...`): the
/// text form that journal.jsonl, plan.json's `frames` and the mock's log write.
#[derive(Debug, Clone, Copy)]
pub struct Hex<'a>(pub &'a [u8]);

impl fmt::Display for Hex<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, b) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::Hex;
    use std::string::ToString;

    #[test]
    fn hex_is_dofbot_md_worked_example() {
        // DOFBOT.md: servo 1 to raw 2000 in 500 ms.
        let frame = [0xFF, 0xFC, 0x07, 0x11, 0x07, 0xD0, 0x01, 0xF4, 0xE4];
        assert_eq!(Hex(&frame).to_string(), "FF FC 07 11 07 D0 01 F4 E4");
        assert_eq!(Hex(&[]).to_string(), "");
        assert_eq!(Hex(&[0x0A]).to_string(), "0A");
    }
}

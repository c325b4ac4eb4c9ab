//! Small parsing helpers shared by the readers: numbered text lines, numbers and a byte cursor.
use super::error::{fail, ParseError, Place};

/// Iterates `(1-based line number, byte offset of the line, line text)` over `bytes`, with
/// `\r\n` and `\n` endings. Invalid UTF-8 is an error naming the line.
pub fn lines(bytes: &[u8]) -> impl Iterator<Item = Result<(usize, usize, &str), ParseError>> {
    let mut offset = 0usize;
    bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .filter_map(move |(i, raw)| {
            let start = offset;
            offset += raw.len() + 1;
            if start >= bytes.len() && raw.is_empty() {
                return None; // the empty piece after a final newline
            }
            let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
            Some(match std::str::from_utf8(raw) {
                Ok(s) => Ok((i + 1, start, s)),
                Err(_) => fail(Place::Line(i + 1), "not valid UTF-8 text"),
            })
        })
}

/// Parses one number token, naming the place on failure.
pub fn number(token: &str, place: Place) -> Result<f64, ParseError> {
    match token.parse::<f64>() {
        Ok(v) => Ok(v),
        Err(_) => fail(
            place,
            format!("expected a number, found {:?}", shorten(token)),
        ),
    }
}

/// Parses one non-negative integer token (an index or a count).
pub fn count(token: &str, place: Place) -> Result<usize, ParseError> {
    match token.parse::<usize>() {
        Ok(v) => Ok(v),
        Err(_) => fail(
            place,
            format!(
                "expected a non-negative integer, found {:?}",
                shorten(token)
            ),
        ),
    }
}

/// Cuts a token for an error message.
pub fn shorten(token: &str) -> String {
    token.chars().take(32).collect()
}

/// Most values in one row of a delimited text file whose width is not declared (XYZ/CSV): a
/// scanner export has a dozen columns (x y z, normals, colour, intensity, ...). Each column
/// becomes a scalar field, so without a bound one 20 MB line of ten million numbers made ten
/// million fields (2.3 GB) before the row was even checked.
pub const MAX_COLUMNS: usize = 1024;

/// The first `width` tokens of a row that must hold exactly `width`, or an error naming the
/// place; never looks at more than `width + 1` tokens (a huge line costs no memory).
pub fn row<'a>(
    mut tokens: impl Iterator<Item = &'a str>,
    width: usize,
    place: Place,
) -> Result<Vec<&'a str>, ParseError> {
    let row: Vec<&str> = tokens.by_ref().take(width).collect();
    if row.len() < width {
        return fail(
            place,
            format!("expected {width} values, found {}", row.len()),
        );
    }
    if tokens.next().is_some() {
        return fail(place, format!("expected {width} values, found more"));
    }
    Ok(row)
}

/// Splits a line into tokens separated by white space.
pub fn tokens(line: &str) -> impl Iterator<Item = &str> {
    line.split_ascii_whitespace()
}

/// A read position over a byte slice that reports truncation with the byte offset.
pub struct Cursor<'a> {
    bytes: &'a [u8],
    /// Current byte offset.
    pub pos: usize,
}

impl<'a> Cursor<'a> {
    /// A cursor at `pos`.
    pub fn new(bytes: &'a [u8], pos: usize) -> Self {
        Cursor { bytes, pos }
    }

    /// The next `n` bytes, or a truncation error that says what was being read.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], ParseError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let s = &self.bytes[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => fail(
                Place::Byte(self.pos),
                format!(
                    "truncated: {what} needs {n} bytes, the file ends at byte {}",
                    self.bytes.len()
                ),
            ),
        }
    }

    /// Bytes left after the cursor.
    pub fn remaining(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }
}

/// A capacity hint that cannot be abused by a lying header: at most what the bytes could hold.
pub fn capacity(claimed: usize, remaining_bytes: usize, min_record: usize) -> usize {
    claimed.min(remaining_bytes / min_record.max(1) + 1)
}

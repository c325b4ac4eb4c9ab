//! Parse errors that name the place of the fault.
use std::fmt;

/// Where in a file a fault sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// A 1-based text line.
    Line(usize),
    /// A 0-based byte offset.
    Byte(usize),
    /// A 0-based point (vertex) index.
    Point(usize),
    /// A 0-based face index.
    Face(usize),
    /// The file as a whole.
    File,
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Place::Line(n) => write!(f, "line {n}"),
            Place::Byte(n) => write!(f, "byte {n}"),
            Place::Point(n) => write!(f, "point {n}"),
            Place::Face(n) => write!(f, "face {n}"),
            Place::File => write!(f, "file"),
        }
    }
}

/// A fault found while parsing: where and what.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{place}: {message}")]
pub struct ParseError {
    /// Where the fault is.
    pub place: Place,
    /// What is wrong, in one line.
    pub message: String,
}

impl ParseError {
    /// A fault at `place`.
    pub fn new(place: Place, message: impl Into<String>) -> Self {
        ParseError {
            place,
            message: message.into(),
        }
    }
}

/// Shorthand for a fault at a place.
pub(crate) fn fail<T>(place: Place, message: impl Into<String>) -> Result<T, ParseError> {
    Err(ParseError::new(place, message))
}

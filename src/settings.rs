//! Range checks of settings whose messages name the key in backticks, so that the CLI's
//! `ConfigFile::refuse` can find the key's line in the user's file. The lowest room: every
//! room that checks its own config struct (`register`, `compare`) and the CLI use them.

/// Checks that `value` (a setting `key` in `unit`) is finite and within `min..=max`; the
/// message names the key in backticks for `cli::settings::ConfigFile::refuse`.
pub fn in_range(key: &str, value: f64, min: f64, max: f64, unit: &str) -> Result<(), String> {
    match value.is_finite() && (min..=max).contains(&value) {
        true => Ok(()),
        false => Err(format!(
            "`{key}` = {value:?} {unit} is outside {min:?}..={max:?} {unit}"
        )),
    }
}

/// Checks that `value` (a setting `key` in `unit`) is finite, above `min` and at most `max`
/// (as [`in_range`] with `min` itself refused: a length or scale that must be positive).
pub fn above(key: &str, value: f64, min: f64, max: f64, unit: &str) -> Result<(), String> {
    match value.is_finite() && value > min && value <= max {
        true => Ok(()),
        false => Err(format!(
            "`{key}` = {value:?} {unit} is outside {min:?} (excluded)..={max:?} {unit}"
        )),
    }
}

/// Checks that a count `n` (a setting `key` in `unit`) is within `min..=max` (a count that
/// must not be 0, and past `max` only costs time or memory without changing the answer).
pub fn count_in(key: &str, n: usize, min: usize, max: usize, unit: &str) -> Result<(), String> {
    match (min..=max).contains(&n) {
        true => Ok(()),
        false => Err(format!(
            "`{key}` = {n} {unit} is outside {min}..={max} {unit}"
        )),
    }
}

/// Checks that a count `n` (a setting `key` in `unit`) is at least `min` (a count that must
/// not be 0: a search with no neighbours, a fit with no points).
pub fn at_least(key: &str, n: usize, min: usize, unit: &str) -> Result<(), String> {
    match n >= min {
        true => Ok(()),
        false => Err(format!("`{key}` = {n} {unit} is less than {min} {unit}")),
    }
}

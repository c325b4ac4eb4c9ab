//! XYZ / CSV / TXT reader: one point per line, numbers separated by white space or commas,
//! optional header line of column names, `#` comment lines.
use super::columns::Columns;
use super::error::{fail, ParseError, Place};
use super::text;
use super::types::{Geometry, PointCloud};

fn split(line: &str) -> impl Iterator<Item = &str> {
    line.split(|c: char| c == ',' || c == ';' || c.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// Parses a delimited text point file.
pub fn read(bytes: &[u8]) -> Result<Geometry, ParseError> {
    if bytes.is_empty() {
        return fail(Place::Byte(0), "empty file");
    }
    let mut columns: Option<Columns> = None;
    let mut cloud = PointCloud::default();
    let mut row = Vec::new();
    for item in text::lines(bytes) {
        let (line_no, _, line) = item?;
        let place = Place::Line(line_no);
        let trimmed = line.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') || trimmed.starts_with("//") {
            continue;
        }
        let layout = match &columns {
            Some(c) => c,
            None => {
                let toks: Vec<&str> = split(trimmed).take(text::MAX_COLUMNS + 1).collect();
                if toks.len() > text::MAX_COLUMNS {
                    return fail(
                        place,
                        format!("more than {} values in a row", text::MAX_COLUMNS),
                    );
                }
                let is_header = toks.iter().any(|t| t.parse::<f64>().is_err());
                let c = if is_header {
                    let names: Vec<String> = toks
                        .iter()
                        .map(|t| t.trim_matches('"').to_string())
                        .collect();
                    Columns::from_names(&names, place)?
                } else {
                    Columns::positional(toks.len(), place)?
                };
                cloud = c.empty_cloud(text::capacity(usize::MAX, bytes.len(), 6));
                columns = Some(c);
                if is_header {
                    continue;
                }
                columns.as_ref().expect("just set")
            }
        };
        let toks = text::row(split(trimmed), layout.width, place)?;
        row.clear();
        for t in &toks {
            row.push(text::number(t, place)?);
        }
        if let Some(bad) = row.iter().position(|v| !v.is_finite()) {
            return fail(
                place,
                format!(
                    "value {} is NaN or infinite (point {})",
                    bad + 1,
                    cloud.len()
                ),
            );
        }
        layout.push(&mut cloud, &row);
    }
    if cloud.is_empty() {
        return fail(Place::File, "no points");
    }
    Ok(Geometry::Cloud(cloud))
}

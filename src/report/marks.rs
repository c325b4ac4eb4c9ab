//! What figures draw over a rendered panel: the colour bar with the tolerance band, a
//! millimetre scale bar, numbered region badges and the panel's pixels themselves.
use plotters::coord::Shift;
use plotters::prelude::*;

use super::colour::diverging;
use super::font;

/// Width of the colour bar column beside the panels, px.
pub const BAR_W: u32 = 150;

/// A drawing error of the area `DB` draws on.
pub type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Copies a rendered panel (row-major, `width` wide) to `(x0, y0)`.
pub fn panel<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    (x0, y0): (i32, i32),
    colours: &[Option<RGBColor>],
    width: usize,
) -> DrawResult<DB> {
    for (k, c) in colours.iter().enumerate() {
        if let Some(c) = c {
            let (px, py) = ((k % width) as i32, (k / width) as i32);
            root.draw_pixel((x0 + px, y0 + py), c)?;
        }
    }
    Ok(())
}

/// A vertical colour bar from -range (bottom) to +range (top) at `x0` between `top` and
/// `bottom`, the tolerance band ±`tolerance` bracketed and labelled.
pub fn colour_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    x0: i32,
    (top, bottom): (i32, i32),
    range: f64,
    tolerance: f64,
) -> DrawResult<DB> {
    let bar_x = x0 + 20;
    let to_y = |v: f64| bottom - ((v + range) / (2.0 * range) * (bottom - top) as f64) as i32;
    for y in top..=bottom {
        let v = range - 2.0 * range * (y - top) as f64 / (bottom - top) as f64;
        root.draw(&Rectangle::new(
            [(bar_x, y), (bar_x + 24, y + 1)],
            diverging(v, range).filled(),
        ))?;
    }
    root.draw(&Rectangle::new(
        [(bar_x, top), (bar_x + 24, bottom)],
        BLACK.stroke_width(1),
    ))?;
    let label = TextStyle::from((font::FAMILY, 16).into_font()).color(&BLACK);
    for v in [-range, -range / 2.0, 0.0, range / 2.0, range] {
        root.draw(&PathElement::new(
            vec![(bar_x + 24, to_y(v)), (bar_x + 30, to_y(v))],
            BLACK,
        ))?;
        root.draw_text(&format!("{v:+.3}"), &label, (bar_x + 33, to_y(v) - 9))?;
    }
    let tol = TextStyle::from((font::FAMILY, 15).into_font()).color(&BLACK);
    for v in [-tolerance, tolerance] {
        if v.abs() < range {
            root.draw(&PathElement::new(
                vec![(bar_x - 6, to_y(v)), (bar_x + 30, to_y(v))],
                BLACK.stroke_width(2),
            ))?;
        }
    }
    root.draw_text(&format!("tol ±{tolerance}"), &tol, (bar_x - 10, bottom + 8))?;
    root.draw_text("mm", &label, (bar_x, top - 18))?;
    Ok(())
}

/// The round length (1, 2 or 5 × 10^k mm) nearest below `about_mm`.
pub fn nice_length(about_mm: f64) -> f64 {
    let e = 10f64.powf(about_mm.max(1e-9).log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * e)
        .find(|&l| l <= about_mm)
        .unwrap_or(e)
}

/// A scale bar of a round length near a quarter of `width_px`, its left end at `(x, y)`.
pub fn scale_bar<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    (x, y): (i32, i32),
    px_per_mm: f64,
    width_px: f64,
) -> DrawResult<DB> {
    let mm = nice_length(width_px / 4.0 / px_per_mm);
    let len = (mm * px_per_mm).round() as i32;
    root.draw(&Rectangle::new(
        [(x, y - 3), (x + len, y + 3)],
        BLACK.filled(),
    ))?;
    for end in [x, x + len] {
        root.draw(&PathElement::new(
            vec![(end, y - 8), (end, y + 8)],
            BLACK.stroke_width(2),
        ))?;
    }
    let style = TextStyle::from((font::FAMILY, 16).into_font()).color(&BLACK);
    root.draw_text(&format!("{mm} mm"), &style, (x + len + 8, y - 9))
}

/// A numbered badge pointing at `(x, y)` from up and to the right.
pub fn badge<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    (x, y): (i32, i32),
    text: &str,
) -> DrawResult<DB> {
    const OFFSET: i32 = 22;
    let c = (x + OFFSET, y - OFFSET);
    root.draw(&PathElement::new(vec![(x, y), c], BLACK.stroke_width(2)))?;
    root.draw(&Circle::new((x, y), 3, BLACK.filled()))?;
    let r = 8 + 5 * text.len() as i32;
    root.draw(&Circle::new(c, r, WHITE.filled()))?;
    root.draw(&Circle::new(c, r, BLACK.stroke_width(2)))?;
    let style = TextStyle::from((font::FAMILY, 18).into_font()).color(&BLACK);
    root.draw_text(text, &style, (c.0 - 5 * text.len() as i32, c.1 - 10))
}

//! The shipped font (DejaVu Sans Mono, assets/DejaVu-LICENSE.txt), registered once for plotters.
use std::sync::Once;

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSansMono.ttf");

/// The family name figures use.
pub const FAMILY: &str = "sans-serif";

/// Registers the shipped font under [`FAMILY`] (idempotent).
pub fn register() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is compiled in: failing to parse it is a build defect, reported by tests.
        let _ = plotters::style::register_font(FAMILY, plotters::style::FontStyle::Normal, FONT);
    });
}

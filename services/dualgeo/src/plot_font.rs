//! The font of every PNG plot: DejaVu Sans, read at run time from Debian's
//! `fonts-dejavu-core` (installed by scripts/setup.sh). Without it plots are drawn
//! without text.

use plotters::style::FontStyle;
use std::sync::OnceLock;

const FONT_PATHS: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Registers the font once; false when none is installed.
pub fn font_available() -> bool {
    static FONT: OnceLock<bool> = OnceLock::new();
    *FONT.get_or_init(|| {
        for path in FONT_PATHS {
            if let Ok(bytes) = std::fs::read(path) {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    return true;
                }
            }
        }
        tracing::warn!("no DejaVu Sans font found: plots are drawn without text (apt-get install fonts-dejavu-core)");
        false
    })
}

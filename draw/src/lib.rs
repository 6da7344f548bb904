//! Pictures, without libtorch: the simulator's scenes drawn as PNG, SVG or
//! an animated GIF (`crossroads render`), and curves plotted as PNG figures
//! (learning curves, TTC sweeps, the reports' figures).
//!
//! The simulator describes a picture as data (a [`crossroads_sim::Scene`]);
//! [`record_episode`] plays one trial of a policy and keeps a scene per
//! simulation step ([`EpisodeScenes`]), and [`write_png`], [`write_svg`]
//! and [`write_gif`] rasterise scenes with plotters, the same code for every
//! format and for the pixels of [`rgb`]. [`plot`] draws [`Panel`]s of [`Series`] into a grid. Text uses an
//! embedded DejaVu Sans font, so no system fonts are needed. Every failure
//! is a [`DrawError`] naming the file.

mod episode;
mod error;
pub mod plot;
mod scene;

pub use episode::{EpisodeScenes, EpisodeView, record_episode};
pub use error::DrawError;
pub use plot::{LOG_FLOOR, Panel, Series, chart, grid};
pub use scene::{rgb, write_gif, write_png, write_svg};

use std::sync::Once;

use plotters::style::FontStyle;

/// Font family name under which DejaVu Sans is registered.
const FONT: &str = "sans-serif";

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid; a failure would only drop text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

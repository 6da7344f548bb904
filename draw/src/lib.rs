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

use std::path::Path;
use std::sync::Once;

use plotters::style::FontStyle;

/// Font family name under which DejaVu Sans is registered.
const FONT: &str = "sans-serif";

/// Writes RGB `pixels` (`size` wide and high, row by row from the top)
/// to `path` as a PNG at the encoder's best compression with adaptive
/// filtering: about a quarter of the bytes of plotters' own PNG writer,
/// the same pixels.
fn encode_png(path: &Path, size: (u32, u32), pixels: &[u8]) -> Result<(), DrawError> {
    let file = std::fs::File::create(path).map_err(|e| DrawError::write(path, e))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), size.0, size.1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Best);
    encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
    let mut writer = encoder
        .write_header()
        .map_err(|e| DrawError::write(path, e))?;
    writer
        .write_image_data(pixels)
        .map_err(|e| DrawError::write(path, e))?;
    writer.finish().map_err(|e| DrawError::write(path, e))
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid; a failure would only drop text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

//! A [`Scene`] rasterised with plotters: background, shapes back to front,
//! the caption and a legend of the car colours, the same code for PNG, SVG,
//! each frame of a GIF and the pixels of [`rgb`].

use std::path::Path;

use crossroads_sim::{Color, Layer, Scene, Shape, palette};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::Color as _;

use crate::{DrawError, FONT, register_font};

/// Writes `scene` to `path` as a PNG: [`rgb`]'s pixels, encoded.
pub fn write_png(path: &Path, scene: &Scene) -> Result<(), DrawError> {
    let pixels = raster(scene, |e| DrawError::draw(path, e))?;
    crate::encode_png(path, scene.size, &pixels)
}

/// Writes `scene` to `path` as an SVG.
pub fn write_svg(path: &Path, scene: &Scene) -> Result<(), DrawError> {
    let root = SVGBackend::new(path, scene.size).into_drawing_area();
    draw(&root, scene).map_err(|e| DrawError::draw(path, e))?;
    root.present().map_err(|e| DrawError::write(path, e))
}

/// Rasterises `scene` into RGB bytes, row by row from the top, three a
/// pixel: the picture [`write_png`] writes (the Python face's `render`).
pub fn rgb(scene: &Scene) -> Result<Vec<u8>, DrawError> {
    raster(scene, DrawError::raster)
}

/// `scene`'s RGB pixels; a failure as `error` makes it.
fn raster(scene: &Scene, error: impl Fn(String) -> DrawError) -> Result<Vec<u8>, DrawError> {
    let (w, h) = scene.size;
    let mut pixels = vec![0u8; 3 * w as usize * h as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, scene.size).into_drawing_area();
        draw(&root, scene).map_err(|e| error(e.to_string()))?;
        root.present().map_err(|e| error(e.to_string()))?;
    }
    Ok(pixels)
}

/// Writes `scenes` to `path` as an animated GIF, one frame per 0.2 s
/// simulation step played at `speed` times real time; calls `on_frame`
/// after each frame (for a progress bar).
pub fn write_gif(
    path: &Path,
    scenes: &[Scene],
    speed: f64,
    mut on_frame: impl FnMut(),
) -> Result<(), DrawError> {
    let size = scenes.first().map_or((1, 1), |s| s.size);
    // 0.2 s per step at real time; GIF delays are whole milliseconds here.
    let delay_ms = (200.0 / speed).round().max(10.0) as u32;
    let root = BitMapBackend::gif(path, size, delay_ms)
        .map_err(|e| DrawError::create(path, e))?
        .into_drawing_area();
    for scene in scenes {
        draw(&root, scene).map_err(|e| DrawError::draw(path, e))?;
        root.present().map_err(|e| DrawError::write(path, e))?;
        on_frame();
    }
    Ok(())
}

fn rgba(c: Color) -> RGBAColor {
    RGBAColor(c.r, c.g, c.b, c.alpha)
}

fn pixels(points: &[(f64, f64)]) -> Vec<(i32, i32)> {
    points
        .iter()
        .map(|&(x, y)| (x.round() as i32, y.round() as i32))
        .collect()
}

/// Draws `scene` onto `area`: background, shapes back to front, the
/// caption, and a legend of the car colours. Errors are plotters' message.
fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, scene: &Scene) -> Result<(), String> {
    register_font();
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    area.fill(&rgba(scene.background)).map_err(fail)?;
    for shape in &scene.shapes {
        match shape {
            Shape::Polygon {
                points,
                fill,
                stroke,
                ..
            } => {
                let pts = pixels(points);
                if fill.alpha > 0.0 {
                    area.draw(&Polygon::new(pts.clone(), rgba(*fill).filled()))
                        .map_err(fail)?;
                }
                if let Some((color, width)) = stroke {
                    let mut closed = pts;
                    if let Some(&first) = closed.first() {
                        closed.push(first);
                    }
                    let style = rgba(*color).stroke_width(width.round().max(1.0) as u32);
                    area.draw(&PathElement::new(closed, style)).map_err(fail)?;
                }
            }
            Shape::Line {
                points,
                color,
                width,
                dashed,
                ..
            } => {
                let style = rgba(*color).stroke_width(width.round().max(1.0) as u32);
                let pts = pixels(points);
                if *dashed {
                    area.draw(&DashedPathElement::new(pts, 6, 4, style))
                        .map_err(fail)?;
                } else {
                    area.draw(&PathElement::new(pts, style)).map_err(fail)?;
                }
            }
        }
    }
    let text = (FONT, 15).into_font().color(&rgba(palette::TEXT));
    area.draw(&Text::new(scene.caption.clone(), (8, 6), text.clone()))
        .map_err(fail)?;
    let legend = [
        ("ego", palette::EGO),
        ("seen", palette::VISIBLE_CAR),
        ("hidden", palette::OCCLUDED_CAR),
        ("obstacle", palette::OBSTACLE),
        ("braking", palette::BRAKING),
    ];
    // The shield's colours only where it drew something.
    let shield = [
        ("phantom", palette::PHANTOM, Layer::Phantom),
        ("vetoed for", palette::THREAT, Layer::Threat),
    ];
    let legend: Vec<_> = legend
        .into_iter()
        .chain(
            shield
                .into_iter()
                .filter(|(_, _, layer)| scene.count(*layer) > 0)
                .map(|(label, color, _)| (label, color)),
        )
        .collect();
    // Right-aligned along the bottom edge: swatch, gap, label, gap.
    let width = |label: &str| {
        area.estimate_text_size(label, &text)
            .map_or(8 * label.len() as i32, |(w, _)| w as i32)
    };
    let total: i32 = legend.iter().map(|(l, _)| 18 + width(l) + 14).sum();
    let (w, h) = (scene.size.0 as i32, scene.size.1 as i32);
    let mut x = (w - total).max(8);
    let y = h - 22;
    for (label, color) in legend {
        area.draw(&Rectangle::new(
            [(x, y + 3), (x + 14, y + 13)],
            rgba(color).filled(),
        ))
        .map_err(fail)?;
        area.draw(&Text::new(label, (x + 18, y), text.clone()))
            .map_err(fail)?;
        x += 18 + width(label) + 14;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use crossroads_sim::{ActionSet, Env, EnvConfig, RenderView, Scenario, SceneOptions};

    use super::*;

    #[test]
    fn rgb_is_the_picture_row_by_row() {
        let scenario = Arc::new(Scenario::builtin("left").expect("left"));
        let mut env = Env::new(scenario, EnvConfig::for_actions(ActionSet::Ttg));
        env.reset(3);
        let scene = Scene::of(&env, &RenderView::default(), &SceneOptions::default());
        let pixels = rgb(&scene).expect("pixels");
        let (w, h) = scene.size;
        assert_eq!(pixels.len(), 3 * w as usize * h as usize);
        // Near the top right corner: background, left of the caption.
        let at = |x: usize, y: usize| {
            let i = 3 * (y * w as usize + x);
            (pixels[i], pixels[i + 1], pixels[i + 2])
        };
        let bg = scene.background;
        assert_eq!(at(w as usize - 2, 2), (bg.r, bg.g, bg.b));
        let colours: std::collections::HashSet<_> = pixels.chunks_exact(3).collect();
        assert!(colours.len() > 4, "{} colours", colours.len());
    }

    #[test]
    fn a_png_holds_exactly_the_pixels_at_best_compression() {
        let scenario = Arc::new(Scenario::builtin("occluded").expect("occluded"));
        let mut env = Env::new(scenario, EnvConfig::for_actions(ActionSet::Creep));
        env.reset(5);
        let scene = Scene::of(&env, &RenderView::default(), &SceneOptions::default());
        let dir = tempfile::tempdir().expect("temporary folder");
        let path = dir.path().join("scene.png");
        write_png(&path, &scene).expect("written");
        let file = std::fs::File::open(&path).expect("the PNG");
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .expect("a PNG");
        let mut decoded = vec![0u8; reader.output_buffer_size()];
        let info = reader.next_frame(&mut decoded).expect("one frame");
        assert_eq!((info.width, info.height), scene.size);
        assert_eq!(info.color_type, png::ColorType::Rgb);
        let pixels = rgb(&scene).expect("pixels");
        assert!(
            decoded[..info.buffer_size()] == pixels[..],
            "the same pixels"
        );
        // Best compression: a scene of flat colours packs far below the
        // 3 bytes a pixel it holds (plotters' own writer gave ~4x this).
        let bytes = std::fs::metadata(&path).expect("size").len() as usize;
        assert!(
            bytes * 20 < pixels.len(),
            "{bytes} bytes for {} values",
            pixels.len()
        );
    }
}

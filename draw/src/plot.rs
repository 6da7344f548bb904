//! Figures as PNG files: panels of labelled series in a grid.

use std::path::Path;

use plotters::coord::cartesian::Cartesian2d;
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::{DrawError, FONT, register_font};

/// One labelled series of (x, y) points.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points in drawing order.
    pub points: Vec<(f64, f64)>,
    /// Draw lines between points (else markers only).
    pub line: bool,
}

/// One chart of a figure: a title, axis labels and its series.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Caption above the chart.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// The series drawn.
    pub series: Vec<Series>,
    /// A logarithmic y axis from [`LOG_FLOOR`] up (values at or below the
    /// floor, zeros included, drawn on it), for rates that matter at
    /// 0.01 % and at 50 %.
    pub log_y: bool,
}

/// Bottom of a logarithmic y axis, where zeros are drawn.
pub const LOG_FLOOR: f64 = 0.001;

/// A scatter/line chart written to `path` as PNG (800 x 560).
pub fn chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<(), DrawError> {
    let panel = Panel {
        title: title.to_owned(),
        x_label: x_label.to_owned(),
        y_label: y_label.to_owned(),
        series: series.to_vec(),
        log_y: false,
    };
    grid(path, None, 1, std::slice::from_ref(&panel))
}

/// Panels in a grid of `cols` columns (each 800 x 560), under an optional
/// overall title, written to `path` as PNG. Panels with nothing to plot
/// are an error naming the panel.
pub fn grid(
    path: &Path,
    title: Option<&str>,
    cols: usize,
    panels: &[Panel],
) -> Result<(), DrawError> {
    register_font();
    let cols = cols.clamp(1, panels.len().max(1));
    let rows = panels.len().div_ceil(cols).max(1);
    let head = if title.is_some() { 40 } else { 0 };
    let size = (800 * cols as u32, 560 * rows as u32 + head);
    let mut pixels = vec![0u8; 3 * size.0 as usize * size.1 as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        let draw = |e: &dyn std::fmt::Display| DrawError::draw(path, e);
        root.fill(&WHITE).map_err(|e| draw(&e))?;
        let body = match title {
            Some(t) => root.titled(t, (FONT, 28)).map_err(|e| draw(&e))?,
            None => root.clone(),
        };
        for (area, panel) in body.split_evenly((rows, cols)).iter().zip(panels) {
            draw_panel(area, panel).map_err(|message| DrawError::Panel {
                panel: panel.title.clone(),
                path: path.to_owned(),
                message,
            })?;
        }
        root.present().map_err(|e| draw(&e))?;
    }
    crate::encode_png(path, size, &pixels)
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    panel: &Panel,
) -> Result<(), String> {
    let series = &panel.series;
    let all = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return Err("nothing to plot".to_owned());
    }
    let pad = |lo: f64, hi: f64| {
        if hi - lo < 1e-9 {
            // One value (a row of zero collision rates): a unit above it,
            // so the axis reads plainly.
            let w = hi.abs().max(1.0);
            return (lo - 0.05 * w, hi + w);
        }
        let span = hi - lo;
        (lo - 0.05 * span, hi + 0.05 * span)
    };
    let (x0, x1) = pad(x0, x1);
    let draw = |e: &dyn std::fmt::Display| e.to_string();
    let mut builder = ChartBuilder::on(area);
    builder
        .caption(&panel.title, (FONT, 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(64);
    if panel.log_y {
        let top = 10f64.powf(y1.max(LOG_FLOOR).log10().ceil().max(-2.0));
        let chart = builder
            .build_cartesian_2d(x0..x1, (LOG_FLOOR..top).log_scale())
            .map_err(|e| draw(&e))?;
        fill(chart, panel, Some(LOG_FLOOR))
    } else {
        let (y0, y1) = pad(y0.min(0.0), y1);
        let chart = builder
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| draw(&e))?;
        fill(chart, panel, None)
    }
}

/// Draws `panel`'s mesh, series and legend on a built chart; with `floor`
/// (a logarithmic axis) values below it are drawn on it.
fn fill<'a, Y>(
    mut chart: ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, Y>>,
    panel: &Panel,
    floor: Option<f64>,
) -> Result<(), String>
where
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let draw = |e: &dyn std::fmt::Display| e.to_string();
    let series = &panel.series;
    chart
        .configure_mesh()
        .x_desc(&panel.x_label)
        .y_desc(&panel.y_label)
        .label_style((FONT, 14))
        .draw()
        .map_err(|e| draw(&e))?;
    for (i, s) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let points: Vec<_> = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| (x, floor.map_or(y, |f| y.max(f))))
            .collect();
        if s.line {
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                .map_err(|e| draw(&e))?;
        }
        chart
            .draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))
            .map_err(|e| draw(&e))?
            .label(s.label.clone())
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, color.filled()));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| draw(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PNG's width and height, from its header.
    fn size(path: &Path) -> (u32, u32) {
        let b = std::fs::read(path).expect("the PNG");
        let word = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        (word(16), word(20))
    }

    #[test]
    fn a_log_panel_draws_rates_from_zero_to_half_beside_a_linear_one() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let rates = Series {
            label: "collision".to_owned(),
            points: vec![(0.0, 50.0), (1.0, 0.5), (2.0, 0.01), (3.0, 0.0)],
            line: true,
        };
        let panel = |log_y| Panel {
            title: "rates".to_owned(),
            x_label: "minutes".to_owned(),
            y_label: "%".to_owned(),
            series: vec![rates.clone()],
            log_y,
        };
        let path = dir.path().join("two.png");
        grid(&path, None, 2, &[panel(false), panel(true)]).expect("drawn");
        assert_eq!(size(&path), (1600, 560));
        // Nothing but zeros: drawn on the floor, not refused.
        let zeros = Panel {
            series: vec![Series {
                points: vec![(0.0, 0.0), (1.0, 0.0)],
                ..rates.clone()
            }],
            ..panel(true)
        };
        let path = dir.path().join("zeros.png");
        grid(&path, None, 1, &[zeros]).expect("drawn");
        assert_eq!(size(&path), (800, 560));
    }
}

//! `crossroads render`: one episode of a policy drawn as an animated GIF
//! (every 0.2 s step) or as a PNG/SVG of one moment. The simulator
//! describes each picture as a [`Scene`]; this module draws scenes with
//! plotters, the same code for every format.

use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context, anyhow, bail, ensure};
use crossroads_sim::{
    Color, Control, Env, EnvConfig, Layer, PolicyRng, RenderView, Scene, SceneOptions, Shape,
    check_go, episode_seed, palette, policy_seed, sense,
};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::Color as _;
use rand::SeedableRng;

use crate::cli::RenderArgs;
use crate::plot::{FONT, register_font};
use crate::progress;

/// Picture formats, by the output file's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Gif,
    Png,
    Svg,
}

impl Format {
    fn of(path: &Path) -> anyhow::Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("gif") => Ok(Self::Gif),
            Some("png") => Ok(Self::Png),
            Some("svg") => Ok(Self::Svg),
            Some(other) => bail!(
                "--out {}: unknown picture format {other:?}; use .gif, .png or .svg",
                path.display()
            ),
            None => bail!(
                "--out {}: no file extension; use .gif, .png or .svg",
                path.display()
            ),
        }
    }
}

/// The episode as scenes, one per simulation step (the first before any
/// step), and the index of the scene at which the policy chose *go*.
struct Episode {
    scenes: Vec<Scene>,
    go_at: Option<usize>,
    summary: String,
}

/// Runs the episode and writes the picture.
pub fn run(args: &RenderArgs) -> anyhow::Result<ExitCode> {
    let format = Format::of(&args.out)?;
    ensure!(
        args.speed.is_finite() && args.speed > 0.0,
        "--speed must be a positive number, got {}",
        args.speed
    );
    if let Some(scale) = args.scale {
        ensure!(
            scale.is_finite() && (0.5..=50.0).contains(&scale),
            "--scale must be between 0.5 and 50 pixels per metre, got {scale}"
        );
    }
    let episode = record(args)?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let frames = match format {
        Format::Gif => {
            write_gif(&args.out, &episode.scenes, args.speed)?;
            episode.scenes.len()
        }
        Format::Png | Format::Svg => {
            let index = match args.step {
                Some(step) => {
                    let last = episode.scenes.len() - 1;
                    ensure!(
                        step as usize <= last,
                        "--step {step}: the episode ended at step {last}"
                    );
                    step as usize
                }
                None => episode.go_at.unwrap_or(episode.scenes.len() - 1),
            };
            let scene = &episode.scenes[index];
            if format == Format::Png {
                let root = BitMapBackend::new(&args.out, scene.size).into_drawing_area();
                draw(&root, scene).with_context(|| format!("drawing {}", args.out.display()))?;
                root.present()
                    .map_err(|e| anyhow!("writing {}: {e}", args.out.display()))?;
            } else {
                let root = SVGBackend::new(&args.out, scene.size).into_drawing_area();
                draw(&root, scene).with_context(|| format!("drawing {}", args.out.display()))?;
                root.present()
                    .map_err(|e| anyhow!("writing {}: {e}", args.out.display()))?;
            }
            1
        }
    };
    println!(
        "{}: {}; wrote {} ({frames} frame{})",
        args.run.scenario,
        episode.summary,
        args.out.display(),
        if frames == 1 { "" } else { "s" }
    );
    Ok(ExitCode::SUCCESS)
}

/// Plays trial `args.trial` of seed `args.seed` (the same episode as
/// `crossroads eval` plays) and records a scene after every step.
fn record(args: &RenderArgs) -> anyhow::Result<Episode> {
    let super::eval::Loaded {
        scenario,
        policy,
        shield,
        actions,
    } = super::eval::load(&args.run)?;
    let config = EnvConfig::for_actions(actions);
    let options = SceneOptions {
        grid: args.grid.then_some(config.observation),
    };
    let mut env = Env::new(Arc::clone(&scenario), config);
    env.reset(episode_seed(args.seed, args.trial));
    let mut rng = [PolicyRng::seed_from_u64(policy_seed(args.seed, args.trial))];
    let mut view = if args.grid || !env.occluders().is_empty() {
        RenderView::wide()
    } else {
        RenderView::default()
    };
    if let Some(scale) = args.scale {
        view.scale = scale;
    }

    let mut scenes = vec![Scene::of(&env, &view, &options)];
    let mut go_at = None;
    let mut sensed = Vec::new();
    let mut vetoes = 0;
    while !env.is_done() {
        let mut action = [0];
        let before = shield.as_ref().map(|(_, c)| c.stats().vetoes);
        policy.act(std::slice::from_ref(&env), &mut rng, &mut action)?;
        // Before the ego commits, draw what the shield assumed, and the car
        // it feared when it vetoed this decision.
        if let (Some((params, counters)), Some(before)) = (&shield, before)
            && !env.ego().committed
        {
            sense(&env, params, &mut sensed);
            let vetoed = counters.stats().vetoes > before;
            let threat = if vetoed {
                vetoes += 1;
                check_go(&env, &sensed, params)
            } else {
                None
            };
            if let Some(scene) = scenes.last_mut() {
                scene.mark_shield(&env, &view, &sensed, threat.as_ref());
            }
        }
        if go_at.is_none() && actions.decode(action[0])? == Control::Go {
            go_at = Some(scenes.len() - 1);
        }
        env.step_with(action[0], |e| scenes.push(Scene::of(e, &view, &options)))?;
    }
    let m = env.metrics();
    let outcome = env
        .outcome()
        .map_or_else(|| "running".to_owned(), |o| format!("{o:?}").to_lowercase());
    let mut summary = format!(
        "{} {outcome} after {:.1} s (traffic braking {:.1} s)",
        policy.name(),
        m.time_s,
        m.brake_time_s
    );
    if shield.is_some() {
        summary += &format!(", the shield vetoed {vetoes} go decision(s)");
    }
    Ok(Episode {
        scenes,
        go_at,
        summary,
    })
}

fn write_gif(path: &Path, scenes: &[Scene], speed: f64) -> anyhow::Result<()> {
    let size = scenes.first().map_or((1, 1), |s| s.size);
    // 0.2 s per step at real time; GIF delays are whole milliseconds here.
    let delay_ms = (200.0 / speed).round().max(10.0) as u32;
    let root = BitMapBackend::gif(path, size, delay_ms)
        .map_err(|e| anyhow!("creating {}: {e}", path.display()))?
        .into_drawing_area();
    let bar = progress::bar(scenes.len() as u64, "frames");
    bar.set_message(format!("encoding {}", path.display()));
    for scene in scenes {
        draw(&root, scene).with_context(|| format!("drawing {}", path.display()))?;
        root.present()
            .map_err(|e| anyhow!("writing {}: {e}", path.display()))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
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
/// caption, and a legend of the car colours.
fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, scene: &Scene) -> anyhow::Result<()> {
    register_font();
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("{e}");
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

//! `crossroads render`: one episode of a policy drawn as an animated GIF
//! (every 0.2 s step) or as a PNG/SVG of one moment, by `crossroads_draw`.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context, bail, ensure};
use crossroads_draw::EpisodeView;
use crossroads_harness::progress;

use crate::cli::RenderArgs;

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
    let loaded = crossroads_harness::eval::load(&args.run)?;
    let view = EpisodeView {
        seed: args.seed,
        trial: args.trial,
        grid: args.grid,
        scale: args.scale,
    };
    let shield = loaded.shield.as_ref().map(|(p, c)| (p, c.as_ref()));
    let episode = crossroads_draw::record_episode(
        &loaded.scenario,
        loaded.policy.as_ref(),
        shield,
        loaded.actions,
        view,
    )?;
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let frames = match format {
        Format::Gif => {
            let bar = progress::bar(episode.scenes.len() as u64, "frames");
            bar.set_message(format!("encoding {}", args.out.display()));
            crossroads_draw::write_gif(&args.out, &episode.scenes, args.speed, || bar.inc(1))?;
            bar.finish_and_clear();
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
                crossroads_draw::write_png(&args.out, scene)?;
            } else {
                crossroads_draw::write_svg(&args.out, scene)?;
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

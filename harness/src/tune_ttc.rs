//! `crossroads tune-ttc`: the TTC threshold sweep and the paper's rule (the
//! lowest threshold with zero collisions).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::Context;
use clap::Args;
use crossroads_draw::plot::{self, Series};
use crossroads_sim::{ActionSet, Scenario, SweepPoint, TuneReport, default_thresholds, tune_ttc};

use crate::eval::parse_action_set;
use crate::progress;

/// `crossroads tune-ttc`.
#[derive(Debug, Args)]
pub struct TuneTtcArgs {
    /// Scenario name or scenario TOML file.
    #[arg(long, default_value = "left")]
    pub scenario: String,
    /// Who drives the traffic: sumo, human, mixed or a drivers TOML file
    /// [default: the scenario's own]; the paper's rule then tunes TTC for
    /// that population.
    #[arg(long, value_name = "PRESET|FILE")]
    pub drivers: Option<String>,
    /// Action set the TTC rule drives.
    #[arg(long, default_value = "ttg", value_parser = parse_action_set)]
    pub actions: ActionSet,
    /// Creep until the conflicting lanes are visible, then apply the rule
    /// (TTC with creep, for occlusion scenarios).
    #[arg(long)]
    pub creep: bool,
    /// Trials per threshold.
    #[arg(long, short = 'n', default_value_t = 2_000)]
    pub trials: u64,
    /// Base seed, the same for every threshold.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Thresholds in seconds: start:end:step or a comma-separated list
    /// [default: 0:10:0.25].
    #[arg(long)]
    pub thresholds: Option<String>,
    /// Folder for tune-ttc[-creep]-<scenario>.csv and .png.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs the sweep, prints it, and writes CSV and PNG under `--out`.
pub fn run(args: &TuneTtcArgs) -> anyhow::Result<ExitCode> {
    let scenario = Arc::new(
        Scenario::load_with_drivers(&args.scenario, args.drivers.as_deref())
            .with_context(|| format!("scenario {:?}", args.scenario))?,
    );
    let thresholds = match &args.thresholds {
        Some(spec) => parse_thresholds(spec).context("--thresholds")?,
        None => default_thresholds(),
    };
    anyhow::ensure!(args.trials > 0, "--trials must be at least 1");

    let bar = progress::bar(args.trials * thresholds.len() as u64, "trials");
    bar.set_message(format!("TTC sweep on {}", scenario.name()));
    let report = tune_ttc(
        &scenario,
        args.actions,
        args.creep,
        &thresholds,
        args.trials,
        args.seed,
        &|n| bar.inc(n),
    )?;
    bar.finish_and_clear();

    print!("{}", table(&report));
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let stem = format!(
            "tune-ttc{}-{}",
            if args.creep { "-creep" } else { "" },
            report.scenario
        );
        let csv_path = dir.join(format!("{stem}.csv"));
        std::fs::write(&csv_path, csv(&report.sweep))
            .with_context(|| format!("writing {}", csv_path.display()))?;
        let png_path = dir.join(format!("{stem}.png"));
        figure(&report, &png_path)?;
        println!("wrote {} and {}", csv_path.display(), png_path.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// `start:end:step` (inclusive) or a comma-separated list, in seconds.
pub fn parse_thresholds(spec: &str) -> anyhow::Result<Vec<f64>> {
    let parts: Vec<&str> = spec.split(':').collect();
    let values: Vec<f64> = if parts.len() == 3 {
        let [start, end, step] = [parts[0], parts[1], parts[2]].map(|p| p.trim().parse::<f64>());
        let (start, end, step) = (start?, end?, step?);
        anyhow::ensure!(
            step > 0.0 && end >= start && (end - start) / step <= 10_000.0,
            "start:end:step needs step > 0, end >= start and at most 10,000 values"
        );
        let n = ((end - start) / step + 1e-9).floor() as usize;
        (0..=n).map(|i| start + step * i as f64).collect()
    } else {
        spec.split(',')
            .map(|v| v.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{spec:?} is neither start:end:step nor a list of seconds"))?
    };
    anyhow::ensure!(
        !values.is_empty() && values.iter().all(|v| v.is_finite() && *v >= 0.0),
        "thresholds must be finite, non-negative seconds"
    );
    Ok(values)
}

fn table(r: &TuneReport) -> String {
    let mut out = format!(
        "TTC{} sweep on {} ({} actions), {} trials per threshold, seed {}\n\
         threshold s  success %  collision %  timeout %  mean time s  mean brake s  brake light s\n",
        if r.creep { " with creep" } else { "" },
        r.scenario,
        r.action_set,
        r.trials,
        r.seed
    );
    for p in &r.sweep {
        let _ = writeln!(
            out,
            "{:11.2}  {:9.2}  {:11.2}  {:9.2}  {:>11}  {:12.2}  {:13.2}",
            p.threshold,
            100.0 * p.success_rate,
            100.0 * p.collision_rate,
            100.0 * p.timeout_rate,
            p.mean_time_s.map_or("-".to_owned(), |t| format!("{t:.2}")),
            p.mean_brake_s,
            p.mean_brake_light_s
        );
    }
    match &r.best {
        Some(b) => {
            let _ = writeln!(
                out,
                "lowest threshold with zero collisions: {:.2} s (success {:.2} %, mean time {})",
                b.threshold,
                100.0 * b.success_rate,
                b.mean_time_s
                    .map_or("-".to_owned(), |t| format!("{t:.2} s"))
            );
        }
        None => out.push_str("no threshold in the sweep is free of collisions\n"),
    }
    out
}

fn csv(sweep: &[SweepPoint]) -> String {
    let mut out = String::from(
        "threshold_s,success_rate,collision_rate,timeout_rate,mean_time_s,mean_brake_s,mean_brake_light_s\n",
    );
    for p in sweep {
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{}",
            p.threshold,
            p.success_rate,
            p.collision_rate,
            p.timeout_rate,
            p.mean_time_s.map_or(String::new(), |t| t.to_string()),
            p.mean_brake_s,
            p.mean_brake_light_s
        );
    }
    out
}

/// The shape of the paper's Figure 3: collision rate against mean time to
/// cross, one point per threshold.
fn figure(r: &TuneReport, path: &Path) -> anyhow::Result<()> {
    let points = r
        .sweep
        .iter()
        .filter_map(|p| p.mean_time_s.map(|t| (t, 100.0 * p.collision_rate)))
        .collect();
    plot::chart(
        path,
        &format!(
            "TTC threshold sweep, {} ({} trials each)",
            r.scenario, r.trials
        ),
        "mean time to cross (s)",
        "collision rate (%)",
        &[Series {
            label: format!("TTC{}", if r.creep { " with creep" } else { "" }),
            points,
            line: true,
        }],
    )?;
    Ok(())
}

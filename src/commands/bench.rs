//! `crossroads bench`: throughput figures measured on this machine.

use std::process::ExitCode;
use std::time::Duration;

use crossroads_sim::bench_builtin;

use crate::cli::{BenchArgs, BenchTarget};

/// Runs the chosen benchmark and prints what it measured.
pub fn run(args: &BenchArgs) -> anyhow::Result<ExitCode> {
    match args.target {
        BenchTarget::Sim => sim(args),
    }
}

fn sim(args: &BenchArgs) -> anyhow::Result<ExitCode> {
    let min = Duration::from_secs_f64(args.seconds.max(0.1));
    let figures = bench_builtin(min)?;
    if args.json {
        println!("{}", serde_json::to_string(&figures)?);
    } else {
        println!(
            "simulator throughput on one thread ({:.1} s per measurement)",
            min.as_secs_f64()
        );
        println!("scenario    TTG decisions/s (with observation)  traffic steps/s  mean cars");
        for f in &figures {
            println!(
                "{:<10}  {:>34.0}  {:>15.0}  {:>9.1}",
                f.scenario, f.decisions_per_s, f.steps_per_s, f.mean_cars
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

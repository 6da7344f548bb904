//! `crossroads bench`: throughput and memory measurements.

use std::process::ExitCode;

use crate::cli::{BenchArgs, BenchTarget};

/// Runs the chosen measurement and prints its figures.
pub fn run(args: &BenchArgs) -> anyhow::Result<ExitCode> {
    match &args.target {
        BenchTarget::Replay {
            capacity,
            rounds,
            json,
        } => {
            let r = crossroads_replay::bench::run(*capacity, *rounds);
            if *json {
                println!(
                    "{{\"capacity\":{},\"bytes_per_transition\":{:.1},\"inserts_per_sec\":{:.0},\"samples_per_sec\":{:.0}}}",
                    r.capacity, r.bytes_per_transition, r.inserts_per_sec, r.samples_per_sec
                );
            } else {
                println!(
                    "replay table, {} synthetic TTG transitions (3-8 cars)",
                    r.capacity
                );
                println!(
                    "  bytes per stored transition  {:.1}",
                    r.bytes_per_transition
                );
                println!("  inserts/s (median, batch 64) {:.0}", r.inserts_per_sec);
                println!("  samples/s (median, batch 256) {:.0}", r.samples_per_sec);
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

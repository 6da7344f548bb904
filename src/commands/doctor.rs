//! `crossroads doctor`: what this machine offers the training service.

use std::process::ExitCode;
use std::time::Instant;

use crossroads_config::Config;
use crossroads_model::{DuelingMlp, MlpSpec};
use serde::Serialize;
use tch::{Device, Kind, Tensor, nn};

use crate::cli::DoctorArgs;

#[derive(Debug, Serialize)]
struct Report {
    version: &'static str,
    cores: usize,
    torch_threads: i32,
    cuda_available: bool,
    mkl: bool,
    openmp: bool,
    /// Median of timed forward passes of a 468-input dueling MLP at batch 64.
    forward_batch64_median_ms: f64,
}

/// Prints the report.
pub fn run(config: &Config, args: &DoctorArgs) -> anyhow::Result<ExitCode> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if config.runtime.compute_threads > 0 {
        tch::set_num_threads(config.runtime.compute_threads as i32);
    }
    let report = Report {
        version: env!("CARGO_PKG_VERSION"),
        cores,
        torch_threads: tch::get_num_threads(),
        cuda_available: tch::Cuda::is_available(),
        mkl: tch::utils::has_mkl(),
        openmp: tch::utils::has_openmp(),
        forward_batch64_median_ms: time_forward()?,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("crossroads {}", report.version);
        println!("  cores            {}", report.cores);
        println!("  torch threads    {}", report.torch_threads);
        println!("  CUDA available   {}", report.cuda_available);
        println!("  MKL / OpenMP     {} / {}", report.mkl, report.openmp);
        println!(
            "  forward pass     {:.3} ms median (dueling MLP 468-256-256, batch 64)",
            report.forward_batch64_median_ms
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn time_forward() -> anyhow::Result<f64> {
    let vs = nn::VarStore::new(Device::Cpu);
    let spec = MlpSpec {
        input: 18 * 26,
        hidden: vec![256, 256],
        num_actions: 5,
    };
    let net = DuelingMlp::new(&vs.root(), spec)?;
    let x = Tensor::rand([64, 18 * 26], (Kind::Float, Device::Cpu));
    let mut times = Vec::with_capacity(50);
    tch::no_grad(|| -> anyhow::Result<()> {
        for _ in 0..55 {
            let start = Instant::now();
            let _q = net.q_values(&x)?;
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
        Ok(())
    })?;
    let mut times = times.split_off(5);
    times.sort_by(f64::total_cmp);
    Ok(times[times.len() / 2])
}

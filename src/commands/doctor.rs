//! `crossroads doctor`: what this machine offers the training service, and
//! how fast it runs the network a run would train: the one the loaded
//! configuration's `[learner]` section describes, over the observation its
//! scenario and action set produce (as `crossroads train` derives it), at
//! the actor's batch (`actor.envs`) and the learner's (`learner.batch_size`).
//! Without `--config` or `--experiment` that is the built-in experiment
//! `crossroads train` trains by default.
//!
//! With `--busy` it times the forward passes again beside another process
//! spinning on a core (a shell loop), as on a loaded machine.
//!
//! It also says what CUDA it found (libtorch built with it, devices
//! visible, cuDNN) and the device `runtime.device` resolves to for the
//! learner; the learner's update is timed there, the forward passes on the
//! CPU (actors and `doctor` itself never leave it). When `cuda` is asked
//! for and cannot be met, the report names what is missing and `doctor`
//! exits with status 1.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_config::{Config, ConfigLoader, SimConfig};
use crossroads_harness::experiments::{self, DEFAULT_EXPERIMENT, Experiment};
use crossroads_harness::global::GlobalArgs;
use crossroads_learner::bench::{SplitMix, median, synthetic_observation, updates_per_second_on};
use crossroads_model::{
    CudaSupport, NativeMlp, NetworkSpec, Precision, QNetwork, Work, cpu_has_amx_bf16, device_name,
};
use serde::Serialize;
use tch::{Device, Tensor};

use crate::cli::DoctorArgs;

/// Timed calls per figure, after as many untimed ones.
const CALLS: usize = 50;

#[derive(Debug, Serialize)]
struct Report {
    version: &'static str,
    cores: usize,
    /// libtorch threads of an actor's network (`runtime.torch_threads`).
    torch_threads: i32,
    /// libtorch threads of the learner's updates
    /// (`runtime.learner_torch_threads`).
    learner_torch_threads: i32,
    cuda_available: bool,
    /// The libtorch linked was built with CUDA (and its CUDA library
    /// loaded).
    libtorch_cuda: bool,
    /// CUDA devices libtorch sees.
    cuda_devices: i64,
    /// cuDNN is available.
    cudnn: bool,
    /// `runtime.device` as configured: `auto`, `cpu` or `cuda`.
    device_setting: &'static str,
    /// The device the learner's networks go on (`cpu`, `cuda:0`), or
    /// `unavailable` when `runtime.device = "cuda"` cannot be met.
    learner_device: String,
    /// Why the learner's device cannot be had, naming what is missing;
    /// `doctor` then exits with status 1.
    #[serde(skip_serializing_if = "Option::is_none")]
    learner_device_error: Option<String>,
    mkl: bool,
    openmp: bool,
    /// `OMP_WAIT_POLICY` as this process runs (the binary makes it
    /// `passive` unless the user set it), or `unset`.
    openmp_wait_policy: String,
    /// `GLIBC_TUNABLES` as this process runs (the binary sets glibc's
    /// heap thresholds unless the user set it), or `unset`.
    glibc_tunables: String,
    /// The network timed, in one line (`dueling conv 2344-16-32-256 -> 5`).
    network: String,
    /// The number format the learner's updates compute the trunk in
    /// (`runtime.precision` resolved for this network, CPU and the
    /// learner's device).
    learner_precision: &'static str,
    /// The number format of the actors' forward passes.
    actor_precision: &'static str,
    /// Whether the CPU has AMX-BF16 matrix units (what `auto` asks for).
    amx_bf16: bool,
    /// Where its settings came from: the configuration file and the
    /// built-in experiment under it (`--set` and the environment aside).
    config: String,
    /// Observations per actor inference call (`actor.envs`).
    actor_batch: usize,
    /// Median of timed inference calls at `actor_batch`.
    actor_forward_median_ms: f64,
    /// The actors' forward pass runs in plain Rust (`NativeMlp`: an f32
    /// MLP), not in libtorch.
    actor_forward_native: bool,
    /// Transitions per learner update (`learner.batch_size`).
    learner_batch: u32,
    /// Median of timed forward passes (no gradient) at `learner_batch`.
    learner_forward_median_ms: f64,
    /// One update (forward, double DQN targets, backward, optimizer step)
    /// at `learner_batch`, on `learner_device` (the CPU when it is
    /// unavailable), from the median of three rounds' rates.
    learner_update_median_ms: f64,
    /// With `--busy`: the forward passes again beside a busy process.
    #[serde(skip_serializing_if = "Option::is_none")]
    busy: Option<Busy>,
}

/// The forward passes timed while another process spins on a core.
#[derive(Debug, Serialize)]
struct Busy {
    actor_forward_median_ms: f64,
    learner_forward_median_ms: f64,
    /// Busy over quiet median, actor inference.
    actor_forward_ratio: f64,
    /// Busy over quiet median, learner forward.
    learner_forward_ratio: f64,
}

/// Runs `f` while another process spins on a core (a shell loop, killed
/// after). A separate process, not a thread of this one: only then do
/// libgomp's spinning threads lose their core to it and collapse (a
/// spinning thread here showed nothing).
fn beside_a_busy_process<T>(f: impl FnOnce() -> anyhow::Result<T>) -> anyhow::Result<T> {
    struct Killed(std::process::Child);
    impl Drop for Killed {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let _busy = Killed(
        std::process::Command::new("sh")
            .args(["-c", "while :; do :; done"])
            .stdin(std::process::Stdio::null())
            .spawn()
            .context("starting a busy process (sh) for --busy")?,
    );
    // Let it get its core first.
    std::thread::sleep(Duration::from_millis(200));
    f()
}

/// The configuration layers of `crossroads doctor`: the global ones, over
/// the experiment `crossroads train` trains by default when no file or
/// experiment is named.
pub fn loader(global: &GlobalArgs) -> ConfigLoader {
    let loader = global.loader();
    match default_experiment(global) {
        Some(e) => loader.base(format!("built-in experiment {}", e.name), e.toml),
        None => loader,
    }
}

/// [`DEFAULT_EXPERIMENT`] when neither `--config` nor `--experiment` is
/// given.
fn default_experiment(global: &GlobalArgs) -> Option<Experiment> {
    if global.config.is_some() || global.experiment.is_some() {
        return None;
    }
    experiments::named(DEFAULT_EXPERIMENT)
}

/// Prints the report.
pub fn run(global: &GlobalArgs, config: &Config, args: &DoctorArgs) -> anyhow::Result<ExitCode> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // Each role's libtorch threads, set on this thread before its timings.
    let threads_of = |n: Option<usize>| {
        if let Some(n) = n {
            tch::set_num_threads(n as i32);
        }
        tch::get_num_threads()
    };
    let (sim, spec) = network(config)?;
    let learner = &config.learner;
    let experiment = default_experiment(global)
        .map(|e| e.name)
        .or(global.experiment.as_deref());
    let source = match (experiment, &global.config) {
        (Some(e), None) => format!("built-in experiment {e}"),
        (Some(e), Some(file)) => format!("{} over built-in experiment {e}", file.display()),
        (None, Some(file)) => file.display().to_string(),
        (None, None) => "built-in defaults".to_owned(),
    };
    let cuda = CudaSupport::probe();
    let learner_device = cuda.resolve(config.runtime.device);
    // Timings where the learner would train; on the CPU when it cannot.
    let device = learner_device.as_ref().map_or(Device::Cpu, |d| *d);
    let mut net = QNetwork::new(spec.clone(), learner.seed).context("building the network")?;
    let precision = config.runtime.precision;
    let training = Precision::choose_on(precision, &spec, Work::Training, device);
    let acting = Precision::choose(precision, &spec, Work::Acting);
    let actor_batch = config.actor.envs;
    let learner_batch = learner.batch_size;
    let learner_threads = threads_of(config.runtime.learner_torch_threads());
    let update = updates_per_second_on(
        &sim,
        learner,
        precision,
        device,
        3,
        Duration::from_millis(300),
    )
    .context("timing learner updates")?;
    // The actors' call and the learner's forward pass, each in the
    // format its role computes in.
    let (mut actor_native, mut actor_threads) = (false, 1);
    let mut forwards = || -> anyhow::Result<(f64, f64)> {
        actor_threads = threads_of(config.runtime.torch_threads());
        net.set_precision(acting);
        let (actor, native) = time_inference(&net, actor_batch)?;
        actor_native = native;
        threads_of(config.runtime.learner_torch_threads());
        net.set_precision(training);
        Ok((actor, time_forward(&net, learner_batch as usize)?))
    };
    let (actor_forward, learner_forward) = forwards()?;
    let busy = if args.busy {
        let (actor, learner) = beside_a_busy_process(&mut forwards)?;
        Some(Busy {
            actor_forward_median_ms: actor,
            learner_forward_median_ms: learner,
            actor_forward_ratio: actor / actor_forward,
            learner_forward_ratio: learner / learner_forward,
        })
    } else {
        None
    };
    let report = Report {
        version: env!("CARGO_PKG_VERSION"),
        cores,
        torch_threads: actor_threads,
        learner_torch_threads: learner_threads,
        cuda_available: tch::Cuda::is_available(),
        libtorch_cuda: cuda.built_with_cuda,
        cuda_devices: cuda.devices,
        cudnn: cuda.cudnn,
        device_setting: config.runtime.device.name(),
        learner_device: learner_device
            .as_ref()
            .map_or_else(|_| "unavailable".to_owned(), |d| device_name(*d)),
        learner_device_error: learner_device.as_ref().err().map(ToString::to_string),
        mkl: tch::utils::has_mkl(),
        openmp: tch::utils::has_openmp(),
        openmp_wait_policy: std::env::var("OMP_WAIT_POLICY").unwrap_or_else(|_| "unset".into()),
        glibc_tunables: std::env::var("GLIBC_TUNABLES").unwrap_or_else(|_| "unset".into()),
        network: crossroads_harness::bench::describe_network(&spec),
        learner_precision: training.name(),
        actor_precision: acting.name(),
        amx_bf16: cpu_has_amx_bf16(),
        config: source,
        actor_batch,
        actor_forward_median_ms: actor_forward,
        actor_forward_native: actor_native,
        learner_batch,
        learner_forward_median_ms: learner_forward,
        learner_update_median_ms: 1e3 / update.updates_per_sec,
        busy,
    };
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("crossroads {}", report.version);
        println!("  cores            {}", report.cores);
        println!(
            "  torch threads    actors {}, learner {} (runtime.torch_threads, runtime.learner_torch_threads)",
            report.torch_threads, report.learner_torch_threads
        );
        println!("  CUDA available   {}", report.cuda_available);
        let yes = |b: bool| if b { "yes" } else { "no" };
        println!(
            "  CUDA             libtorch built with CUDA {}, {} device(s) visible, cuDNN {}",
            yes(report.libtorch_cuda),
            report.cuda_devices,
            yes(report.cudnn)
        );
        match &report.learner_device_error {
            None => println!(
                "  learner device   {} (runtime.device {})",
                report.learner_device, report.device_setting
            ),
            Some(e) => println!(
                "  learner device   unavailable (runtime.device {}): {e}",
                report.device_setting
            ),
        }
        println!("  MKL / OpenMP     {} / {}", report.mkl, report.openmp);
        println!(
            "  OpenMP waits     {} (OMP_WAIT_POLICY)",
            report.openmp_wait_policy
        );
        println!(
            "  glibc malloc     {} (GLIBC_TUNABLES)",
            report.glibc_tunables
        );
        println!("  network          {} ({})", report.network, report.config);
        println!(
            "  number format    learner {}, actors {} (runtime.precision {}; AMX-BF16 {})",
            report.learner_precision,
            report.actor_precision,
            config.runtime.precision.name(),
            if report.amx_bf16 { "yes" } else { "no" }
        );
        println!(
            "  actor forward    {:.3} ms median (batch {}, actor.envs; {})",
            report.actor_forward_median_ms,
            report.actor_batch,
            if report.actor_forward_native {
                "plain Rust"
            } else {
                "libtorch"
            }
        );
        println!(
            "  learner forward  {:.3} ms median (batch {}, learner.batch_size)",
            report.learner_forward_median_ms, report.learner_batch
        );
        println!(
            "  learner update   {:.3} ms median (batch {}, {})",
            report.learner_update_median_ms,
            report.learner_batch,
            device_name(device)
        );
        if let Some(b) = &report.busy {
            println!(
                "  beside a busy core: actor forward {:.3} ms ({:.2}x quiet), learner forward \
                 {:.3} ms ({:.2}x)",
                b.actor_forward_median_ms,
                b.actor_forward_ratio,
                b.learner_forward_median_ms,
                b.learner_forward_ratio
            );
        }
    }
    if report.learner_device_error.is_some() {
        // A failed check: the learner of this configuration would not
        // start here.
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// The network a run of `config` trains, and its `[sim]` with the
/// observation resolved (what the run's actors produce).
fn network(config: &Config) -> anyhow::Result<(SimConfig, NetworkSpec)> {
    let mut sim = config.sim.clone();
    crossroads_actor::resolve_observation(&mut sim).context("[sim]")?;
    let spec =
        crossroads_model::network_spec(&sim, &config.learner).context("the [learner] network")?;
    Ok((sim, spec))
}

/// `batch` synthetic observations of `spec`, back to back.
fn observations(spec: &NetworkSpec, batch: usize) -> Vec<f32> {
    let mut rng = SplitMix::new(11);
    (0..batch)
        .flat_map(|_| synthetic_observation(spec, &mut rng))
        .collect()
}

/// Median milliseconds of `f` over [`CALLS`] calls, after as many untimed.
fn median_ms(mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<f64> {
    for _ in 0..CALLS {
        f()?;
    }
    let mut times = Vec::with_capacity(CALLS);
    for _ in 0..CALLS {
        let start = Instant::now();
        f()?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(&times))
}

/// The actors' call on `batch` observations: [`NativeMlp`] where the network has one
/// (as `LiveNetwork` uses it), else [`QNetwork::infer`]; whether it was native.
fn time_inference(net: &QNetwork, batch: usize) -> anyhow::Result<(f64, bool)> {
    let obs = observations(net.spec(), batch);
    if let Some(mut native) = NativeMlp::of(net)? {
        // As the actors call it: each observation's non-zero values.
        let pairs: Vec<Vec<(u32, f32)>> = obs
            .chunks_exact(native.obs_len())
            .map(crossroads_types::codec::nonzero_pairs)
            .collect();
        let mut q = vec![0.0; batch * native.num_actions()];
        let ms = median_ms(|| Ok(native.q_values_sparse(&pairs, &mut q)?))?;
        return Ok((ms, true));
    }
    let ms = median_ms(|| {
        net.infer(&obs, batch)?;
        Ok(())
    })?;
    Ok((ms, false))
}

/// The learner's forward pass without a gradient (its target network's).
fn time_forward(net: &QNetwork, batch: usize) -> anyhow::Result<f64> {
    let obs = observations(net.spec(), batch);
    let x = Tensor::from_slice(&obs).reshape([batch as i64, net.spec().input_len()]);
    tch::no_grad(|| {
        median_ms(|| {
            let _q = net.q_values(&x)?;
            Ok(())
        })
    })
}

//! Measurements of the learner: updates per second on in-memory batches,
//! and updates per second with the fraction of time spent waiting when fed
//! by a replay server over gRPC. Used by `cargo bench -p
//! crossroads-learner` and `crossroads bench learner`; nothing here prints.

use std::time::{Duration, Instant};

use crossroads_common::Shutdown;
use crossroads_config::{Config, LearnerConfig, PrecisionSetting, SimConfig};
use crossroads_model::{NetworkSpec, Precision, Work};
use crossroads_transport::grpc::ReplayClient;
use crossroads_types::{ObservationEncoding, Transition, TransitionBatch};
use tch::Device;

use crate::LearnerError;
use crate::batch::TrainingBatch;
use crate::trainer::{Trainer, TrainerConfig};

/// A small deterministic generator (SplitMix64); benchmarks need no more.
#[derive(Debug, Clone)]
pub struct SplitMix(u64);

impl SplitMix {
    /// Seeded.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in 0..n.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }
}

/// One synthetic observation of `spec`: 3 to 8 cars in random cells
/// (occupied 1, heading, speed, other channels small values), dense ego
/// features in [0, 1).
pub fn synthetic_observation(spec: &NetworkSpec, rng: &mut SplitMix) -> Vec<f32> {
    let o = &spec.observation;
    let (c, r, w) = (o.channels as usize, o.rows as usize, o.cols as usize);
    let mut v = vec![0f32; spec.input_len() as usize];
    for _ in 0..3 + rng.below(6) {
        let (row, col) = (rng.below(r as u64) as usize, rng.below(w as u64) as usize);
        for ch in 0..c {
            let value = match ch {
                0 => 1.0,
                1 => rng.unit() * 2.0 - 1.0,
                2 => rng.unit() * 1.3,
                _ => rng.unit(),
            };
            v[(ch * r + row) * w + col] = value;
        }
    }
    for x in &mut v[c * r * w..] {
        *x = rng.unit();
    }
    v
}

/// A batch of `n` chained transitions of `spec` (each next state is the
/// following transition's state; episodes end with probability 1/50),
/// k-step discounts 0.99^k for k in {1, 2, 4, 8}, sparse observations.
pub fn synthetic_batch(spec: &NetworkSpec, n: usize, rng: &mut SplitMix) -> TransitionBatch {
    let mut b = TransitionBatch::new(
        spec.observation.clone(),
        spec.num_actions as u32,
        ObservationEncoding::SparseF32,
    );
    let mut current = b.push_observation(&synthetic_observation(spec, rng));
    for _ in 0..n {
        let done = rng.below(50) == 0;
        let k = [1, 2, 4, 8][rng.below(4) as usize];
        let next = b.push_observation(&synthetic_observation(spec, rng));
        b.push(Transition {
            observation: current,
            action: rng.below(spec.num_actions as u64) as u32,
            reward: if done { 1.0 } else { -0.01 * k as f32 },
            discount: if done { 0.0 } else { 0.99f32.powi(k) },
            priority: 0.01 + rng.unit(),
            next_observation: next,
        });
        current = if done {
            b.push_observation(&synthetic_observation(spec, rng))
        } else {
            next
        };
    }
    b
}

/// Updates per second at one batch size.
#[derive(Debug, Clone, PartialEq)]
pub struct UpdateRate {
    /// Transitions per update.
    pub batch_size: u32,
    /// Median over rounds.
    pub updates_per_sec: f64,
    /// Each round's rate.
    pub rounds: Vec<f64>,
    /// The number format the trunk computed in.
    pub precision: Precision,
}

/// The middle value (mean of the two middle ones for an even count); 0 for
/// none.
pub fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => 0.0,
        n if n % 2 == 1 => s[n / 2],
        n => (s[n / 2 - 1] + s[n / 2]) / 2.0,
    }
}

/// Times `rounds` rounds of updates of at least `round_time` each on a
/// fixed pool of in-memory batches (data generation is not timed), after a
/// warm-up; the network is `sim`'s and `config`'s, the optimizer
/// `config`'s, computing in the format `precision` chooses for it, on the
/// CPU.
pub fn updates_per_second(
    sim: &SimConfig,
    config: &LearnerConfig,
    precision: PrecisionSetting,
    rounds: usize,
    round_time: Duration,
) -> Result<UpdateRate, LearnerError> {
    updates_per_second_on(sim, config, precision, Device::Cpu, rounds, round_time)
}

/// [`updates_per_second`] of a trainer on `device` (the learner's,
/// `runtime.device`); the batches start on the CPU, as sampled ones do,
/// so each update includes moving its batch there.
pub fn updates_per_second_on(
    sim: &SimConfig,
    config: &LearnerConfig,
    precision: PrecisionSetting,
    device: Device,
    rounds: usize,
    round_time: Duration,
) -> Result<UpdateRate, LearnerError> {
    let tc = TrainerConfig::from_config(sim, config)?;
    let precision = Precision::choose_on(precision, &tc.spec, Work::Training, device);
    let mut rng = SplitMix::new(7);
    let batches: Vec<TrainingBatch> = (0..8)
        .map(|i| {
            let b = synthetic_batch(&tc.spec, config.batch_size as usize, &mut rng);
            let keys: Vec<u64> = (0..b.len() as u64).map(|k| k + i * 1_000_000).collect();
            let weights = vec![1.0; b.len()];
            TrainingBatch::from_batch(&b, &weights, keys, &tc.spec)
        })
        .collect::<Result<_, _>>()?;
    let mut trainer = Trainer::new_on(tc, device)?;
    trainer.set_precision(precision);
    for b in batches.iter().take(4) {
        trainer.update(b)?;
    }
    let mut rates = Vec::with_capacity(rounds);
    let mut i = 0;
    for _ in 0..rounds.max(1) {
        let start = Instant::now();
        let mut n = 0u64;
        while start.elapsed() < round_time {
            trainer.update(&batches[i % batches.len()])?;
            i += 1;
            n += 1;
        }
        rates.push(n as f64 / start.elapsed().as_secs_f64());
    }
    Ok(UpdateRate {
        batch_size: config.batch_size,
        updates_per_sec: median(&rates),
        rounds: rates,
        precision,
    })
}

/// Inserts `transitions` synthetic transitions of `spec` into the replay
/// server `client` talks to, in batches of 256.
pub async fn fill_replay(
    client: &ReplayClient,
    spec: &NetworkSpec,
    transitions: usize,
) -> Result<(), LearnerError> {
    let mut rng = SplitMix::new(11);
    let mut stream = client.insert_stream(8).await?;
    let mut left = transitions;
    while left > 0 {
        let n = left.min(256);
        if stream.is_full() {
            stream.next_ack().await?;
        }
        stream.send(synthetic_batch(spec, n, &mut rng)).await?;
        left -= n;
    }
    stream.finish().await?;
    Ok(())
}

/// The learner fed by a replay server over gRPC.
#[derive(Debug, Clone, PartialEq)]
pub struct FedReport {
    /// Updates applied.
    pub updates: u64,
    /// Wall time of the training loop, seconds.
    pub seconds: f64,
    /// Updates per second.
    pub updates_per_sec: f64,
    /// Seconds the loop waited for samples.
    pub wait_seconds: f64,
    /// `wait_seconds / seconds`.
    pub wait_fraction: f64,
}

/// Runs a whole learner (prefetching sampler, priority updates, weight
/// publication; no checkpoints, no shared memory) against the replay server
/// of `config.transport.replay_endpoint`, which must already hold
/// transitions of the configured network, for `updates` updates.
pub async fn fed(config: &Config, updates: u64) -> Result<FedReport, LearnerError> {
    let mut config = config.clone();
    config.learner.max_updates = updates;
    config.learner.checkpoint_dir = None;
    config.learner.shm_publish = false;
    config.learner.resume = false;
    config.learner.listen = ([127, 0, 0, 1], 0).into();
    let running = crate::start(&config, None, Shutdown::new()).await?;
    let started = Instant::now();
    let metrics = running.metrics().clone();
    running.join().await?;
    let seconds = started.elapsed().as_secs_f64();
    let wait_seconds = metrics.sample_wait_total.get();
    let done = metrics.updates.get();
    Ok(FedReport {
        updates: done,
        seconds,
        updates_per_sec: done as f64 / seconds,
        wait_seconds,
        wait_fraction: wait_seconds / seconds,
    })
}

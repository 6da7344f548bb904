//! Measurements of a table: inserts/s, samples/s and bytes per stored
//! transition, on synthetic TTG episodes (18 x 26 x 3 grids with 3 to 8
//! cars, each covering 1 to 3 cells that carry its heading, speed and
//! occupancy, moving between frames). Used by `cargo bench -p
//! crossroads-replay` and by tests; [`run`] prints nothing, it returns a
//! [`Report`].

use std::time::{Duration, Instant};

use crossroads_common::Shutdown;

use crossroads_types::{ObservationEncoding, ObservationLayout, Transition, TransitionBatch};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::metrics::TableMetrics;
use crate::rate_limiter::RateLimiterConfig;
use crate::table::{PreparedBatch, Table, TableConfig};

const ROWS: usize = 18;
const COLS: usize = 26;
const CHANNELS: usize = 5;
/// Dense values after the grid (none written: they stay 0).
const EXTRA: usize = 4;

/// The layout the synthetic batches carry: the grid above and [`EXTRA`]
/// values, the size of the simulator's TTG view (the replay does not link
/// the simulator; these grids are its own).
fn layout() -> ObservationLayout {
    ObservationLayout::new(
        "ttg",
        CHANNELS as i64,
        ROWS as i64,
        COLS as i64,
        EXTRA as i64,
    )
}

#[derive(Debug, Clone)]
struct Car {
    row: usize,
    col: f32,
    cells: usize,
    heading: f32,
    speed: f32,
}

/// An episode of synthetic TTG grids: cars drive along rows and wrap
/// around, speeds drift a little every step.
#[derive(Debug, Clone)]
pub struct SyntheticEpisodes {
    rng: Xoshiro256PlusPlus,
    cars: Vec<Car>,
}

impl SyntheticEpisodes {
    /// A source of episodes from `seed`.
    pub fn new(seed: u64) -> Self {
        let mut s = Self {
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            cars: Vec::new(),
        };
        s.new_episode();
        s
    }

    /// Starts a new episode with 3 to 8 cars.
    pub fn new_episode(&mut self) {
        let n = self.rng.random_range(3..=8);
        let headings = [0.25f32, 0.75, -0.25, -0.75];
        self.cars = (0..n)
            .map(|_| Car {
                row: self.rng.random_range(0..ROWS),
                col: self.rng.random_range(0.0..COLS as f32),
                cells: self.rng.random_range(1..=3),
                heading: headings[self.rng.random_range(0..headings.len())],
                speed: self.rng.random_range(0.2..1.0),
            })
            .collect();
    }

    /// The current grid, row-major `[18][26][5]` (heading, speed,
    /// occupied, x offset; the y offset stays 0 on a straight lane).
    pub fn grid(&self) -> Vec<f32> {
        let mut g = vec![0.0; ROWS * COLS * CHANNELS];
        for car in &self.cars {
            for k in 0..car.cells {
                let col = (car.col as usize + k) % COLS;
                let cell = (car.row * COLS + col) * CHANNELS;
                g[cell] = car.heading;
                g[cell + 1] = car.speed;
                g[cell + 2] = 1.0;
                g[cell + 3] = car.col.fract() - 0.5;
            }
        }
        g
    }

    /// Moves every car one decision step (0.2 s).
    pub fn step(&mut self) {
        for car in &mut self.cars {
            car.speed = (car.speed + self.rng.random_range(-0.02..0.02)).clamp(0.05, 1.0);
            car.col = (car.col + car.speed * 1.5) % COLS as f32;
        }
    }

    /// A batch of `n` consecutive one-step transitions, observations sent
    /// sparse and each once (transition i's next state is i + 1's state).
    /// Episodes end (discount 0) with probability 1/100 per step.
    pub fn batch(&mut self, n: usize) -> TransitionBatch {
        let mut b = TransitionBatch::new(layout(), 5, ObservationEncoding::SparseF32);
        let mut current = b.push_observation(&self.grid());
        for _ in 0..n {
            let done = self.rng.random_range(0..100) == 0;
            self.step();
            let next = b.push_observation(&self.grid());
            b.push(Transition {
                observation: current,
                action: self.rng.random_range(0..5),
                reward: if done { 1.0 } else { -0.01 },
                discount: if done { 0.0 } else { 0.99 },
                priority: self.rng.random_range(0.01..2.0),
                next_observation: next,
            });
            current = next;
            if done {
                self.new_episode();
                current = b.push_observation(&self.grid());
            }
        }
        b
    }
}

/// A table for benchmarks: no rate limit, alpha 0.6.
pub fn bench_table(capacity: usize) -> Table {
    Table::new(
        TableConfig {
            name: "bench".to_owned(),
            capacity,
            alpha: 0.6,
            min_priority: 1e-6,
            normalization: Default::default(),
            seed: 7,
            limiter: RateLimiterConfig {
                min_size_to_sample: 1,
                samples_per_insert: 0.0,
                tolerance: 0.0,
                ramp: None,
            },
        },
        TableMetrics::unregistered("bench"),
    )
}

/// Fills `table` to capacity with batches of `batch` transitions.
pub fn fill(table: &Table, episodes: &mut SyntheticEpisodes, batch: usize) {
    let capacity = table.config().capacity as u64;
    while table.stats().info.size < capacity {
        if let Ok(p) = PreparedBatch::try_from(episodes.batch(batch)) {
            let _ = table.insert_now(&p);
        }
    }
}

/// What [`run`] measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Table capacity used.
    pub capacity: usize,
    /// Memory held by the full table divided by its size.
    pub bytes_per_transition: f64,
    /// Median over rounds, batches of 64 including validation and
    /// encoding.
    pub inserts_per_sec: f64,
    /// Median over rounds, batches of 256 including decoding.
    pub samples_per_sec: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// Measures a table of `capacity` items: bytes per transition when full,
/// then `rounds` timed rounds of inserts and samples; reports medians.
pub fn run(capacity: usize, rounds: usize) -> Report {
    let table = bench_table(capacity);
    let mut episodes = SyntheticEpisodes::new(1);
    fill(&table, &mut episodes, 64);
    let stats = table.stats();
    let bytes_per_transition = stats.info.bytes_stored as f64 / stats.info.size as f64;

    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build();
    let shutdown = Shutdown::new();
    let mut inserts = Vec::new();
    let mut samples = Vec::new();
    for _ in 0..rounds.max(1) {
        let batches: Vec<_> = (0..50).map(|_| episodes.batch(64)).collect();
        let start = Instant::now();
        for b in batches {
            if let Ok(p) = PreparedBatch::try_from(b) {
                let _ = table.insert_now(&p);
            }
        }
        inserts.push(50.0 * 64.0 / start.elapsed().as_secs_f64());

        if let Ok(rt) = &runtime {
            let start = Instant::now();
            for _ in 0..20 {
                let _ = rt.block_on(table.sample(256, 0.4, Duration::from_secs(1), &shutdown));
            }
            samples.push(20.0 * 256.0 / start.elapsed().as_secs_f64());
        }
    }
    Report {
        capacity,
        bytes_per_transition,
        inserts_per_sec: median(inserts),
        samples_per_sec: median(samples),
    }
}

//! The creep stall, small: a chain of creep positions ending at a line
//! where the crossing traffic comes into view, trained by the project's
//! dueling double DQN ([`Trainer`]) fed as `crossroads train` feeds it on
//! the occlusion family (an Ape-X epsilon ladder, n-step returns with the
//! acting network's priorities, a proportional replay, a samples-per-insert
//! ratio), at a thousandth of its cost.
//!
//! From position 0, *creep* moves one position on, *wait* stays, *go* ends
//! the episode; every step costs 0.01 and the crossing is clear with
//! probability `--clear`, shown only at the line. A *go* earns +1 when it
//! is clear and -10 otherwise, seen or not (going blind is worth
//! `11 * clear - 10`): the best policy creeps to the line and goes when it
//! sees it clear; the trap is waiting. Every `--every` updates it prints the
//! greedy policy's rates and values at the line. Flags: `parse` (`Options`
//! says what each sets). Findings: reports/time-to-target/NOTES.md.
//!
//! ```text
//! cargo run --release -p crossroads-learner --example creep_chain -- --cars 4 --ratio 0.5 --seeds 1,2,3
//! ```

use std::collections::VecDeque;

use crossroads_config::TargetUpdate;
use crossroads_learner::optimizer::OptimizerConfig;
use crossroads_learner::{Trainer, TrainerConfig, TrainingBatch};
use crossroads_model::{NetworkSpec, ObservationLayout, QNetwork, TrunkKind};
use crossroads_replay::sum_tree::SumTree;
use crossroads_types::{ObservationEncoding, Transition, TransitionBatch};
use tch::{Kind, Tensor};

const WAIT: usize = 0;
const CREEP: usize = 1;
const GO: usize = 2;
const STEP_REWARD: f32 = -0.01;
const SUCCESS: f32 = 1.0;
const COLLISION: f32 = -10.0;

/// Everything a run is told.
#[derive(Debug, Clone)]
struct Options {
    /// Position of the line: *creep* goes from 0 up to it.
    positions: usize,
    /// Probability that the crossing is clear in a step.
    clear: f64,
    /// Steps before an episode times out (terminal).
    steps: u32,
    envs: usize,
    n_step: usize,
    gamma: f32,
    ratio: f64,
    updates: u64,
    every: u64,
    batch: usize,
    capacity: usize,
    min_size: usize,
    alpha: f64,
    lr: f64,
    target_period: u64,
    sync_every: u64,
    hidden: Vec<i64>,
    seeds: Vec<u64>,
    /// Priorities of new items: the acting network's TD error (Ape-X) or
    /// the largest priority seen (the PER paper).
    max_priority: bool,
    /// Cars of the crossing whose distances the line shows (0: a plain
    /// clear bit), hiding the clear moment in a picture as the occlusion
    /// family's grid does: each at a distance drawn anew every step
    /// (uniform in 0..1), the crossing clear when every car is farther than
    /// a threshold set for `clear`; zeros before the line. The network must
    /// learn the conjunction from the rare exploring *go*s that succeed.
    cars: usize,
    /// The loss's Huber delta (the project's default: 20).
    huber: f64,
    /// Environments (the least exploring of the ladder) that follow the
    /// rule (creep to the line, go when it is seen clear) instead of the
    /// network, until `demo_updates` updates: demonstrations in the replay,
    /// as `actor.early_demo_envs` does in `crossroads train`.
    demo_envs: usize,
    /// Updates after which the demonstrating environments explore like
    /// the rest.
    demo_updates: u64,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            positions: 4,
            clear: 0.3,
            steps: 100,
            envs: 32,
            n_step: 3,
            gamma: 0.99,
            ratio: 4.0,
            updates: 20_000,
            every: 1_000,
            batch: 64,
            capacity: 1_000_000,
            min_size: 5_000,
            alpha: 0.6,
            lr: 0.00025,
            target_period: 1_000,
            sync_every: 50,
            hidden: vec![64, 64],
            seeds: vec![1],
            max_priority: false,
            cars: 0,
            huber: 20.0,
            demo_envs: 0,
            demo_updates: 0,
        }
    }
}

fn parse() -> Options {
    let mut o = Options::default();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let key = args[i].trim_start_matches("--").to_owned();
        if key == "max-priority" {
            o.max_priority = true;
            i += 1;
            continue;
        }
        let value = args.get(i + 1).unwrap_or_else(|| {
            eprintln!("--{key} needs a value");
            std::process::exit(2)
        });
        let bad = |e: &dyn std::fmt::Display| -> ! {
            eprintln!("--{key} {value}: {e}");
            std::process::exit(2)
        };
        macro_rules! num {
            ($field:expr) => {
                $field = value.parse().unwrap_or_else(|e| bad(&e))
            };
        }
        match key.as_str() {
            "positions" => num!(o.positions),
            "clear" => num!(o.clear),
            "steps" => num!(o.steps),
            "envs" => num!(o.envs),
            "n-step" => num!(o.n_step),
            "ratio" => num!(o.ratio),
            "updates" => num!(o.updates),
            "every" => num!(o.every),
            "batch" => num!(o.batch),
            "capacity" => num!(o.capacity),
            "min-size" => num!(o.min_size),
            "alpha" => num!(o.alpha),
            "lr" => num!(o.lr),
            "target-period" => num!(o.target_period),
            "sync-every" => num!(o.sync_every),
            "cars" => num!(o.cars),
            "huber" => num!(o.huber),
            "demo-envs" => num!(o.demo_envs),
            "demo-updates" => num!(o.demo_updates),
            "hidden" => {
                o.hidden = value
                    .split(',')
                    .map(|h| h.parse().unwrap_or_else(|e| bad(&e)))
                    .collect()
            }
            "seeds" => {
                o.seeds = value
                    .split(',')
                    .map(|h| h.parse().unwrap_or_else(|e| bad(&e)))
                    .collect()
            }
            other => {
                eprintln!("unknown option --{other}");
                std::process::exit(2)
            }
        }
        i += 2;
    }
    o
}

/// xorshift64*: enough randomness for a toy, with no dependency.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn below(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize % n
    }
}

/// One environment of the chain.
#[derive(Debug, Clone)]
struct Chain {
    position: usize,
    clear: bool,
    /// The cars' distances (with `--cars`), clear when all exceed
    /// [`Options::threshold`].
    cars: Vec<f32>,
    t: u32,
}

/// How an episode ended.
#[derive(Debug, Clone, Copy, PartialEq)]
enum End {
    Success,
    Collision,
    Timeout,
}

impl Options {
    /// The distance every car must exceed for the crossing to be clear
    /// with probability `clear`: `(1 - threshold)^cars = clear`.
    fn threshold(&self) -> f64 {
        1.0 - self.clear.powf(1.0 / self.cars as f64)
    }

    /// Width of an observation: the one-hot position, then the crossing.
    fn width(&self) -> usize {
        self.positions + 1 + self.cars.max(1)
    }
}

impl Chain {
    fn new(rng: &mut Rng, o: &Options) -> Self {
        let mut env = Self {
            position: 0,
            clear: false,
            cars: vec![0.0; o.cars],
            t: 0,
        };
        env.draw(rng, o);
        env
    }

    /// The crossing's traffic for this step.
    fn draw(&mut self, rng: &mut Rng, o: &Options) {
        if o.cars == 0 {
            self.clear = rng.uniform() < o.clear;
        } else {
            for d in &mut self.cars {
                *d = rng.uniform() as f32;
            }
            let threshold = o.threshold() as f32;
            self.clear = self.cars.iter().all(|&d| d > threshold);
        }
    }

    /// One-hot position, then the crossing's state where it is seen.
    fn observation(&self, o: &Options) -> Vec<f32> {
        let mut x = vec![0.0; o.width()];
        x[self.position] = 1.0;
        if self.position == o.positions {
            if o.cars == 0 {
                x[o.positions + 1] = f32::from(u8::from(self.clear));
            } else {
                x[o.positions + 1..].copy_from_slice(&self.cars);
            }
        }
        x
    }

    /// The rule the demonstrating environments follow: creep to the line,
    /// wait there until the crossing is seen clear, go.
    fn rule(&self, o: &Options) -> usize {
        if self.position < o.positions {
            CREEP
        } else if self.clear {
            GO
        } else {
            WAIT
        }
    }

    fn step(&mut self, action: usize, rng: &mut Rng, o: &Options) -> (f32, Option<End>) {
        if action == GO {
            return if self.clear {
                (SUCCESS, Some(End::Success))
            } else {
                (COLLISION, Some(End::Collision))
            };
        }
        if action == CREEP {
            self.position = (self.position + 1).min(o.positions);
        }
        self.t += 1;
        self.draw(rng, o);
        if self.t >= o.steps {
            (STEP_REWARD, Some(End::Timeout))
        } else {
            (STEP_REWARD, None)
        }
    }
}

fn spec(o: &Options) -> NetworkSpec {
    NetworkSpec {
        observation: ObservationLayout {
            kind: "toy".to_owned(),
            channels: 1,
            rows: 1,
            cols: o.width() as i64,
            extra: 0,
        },
        action_set: "toy".to_owned(),
        num_actions: 3,
        trunk: TrunkKind::Mlp,
        hidden: o.hidden.clone(),
    }
}

fn q_rows(net: &QNetwork, obs: &[Vec<f32>]) -> Vec<Vec<f32>> {
    let width = obs[0].len();
    let flat: Vec<f32> = obs.iter().flatten().copied().collect();
    let x = Tensor::from_slice(&flat).reshape([obs.len() as i64, width as i64]);
    let q = tch::no_grad(|| net.q_values(&x).expect("forward"));
    let v = Vec::<f32>::try_from(q.to_kind(Kind::Float).flatten(0, -1)).expect("values");
    v.chunks(3).map(<[f32]>::to_vec).collect()
}

fn argmax(q: &[f32]) -> usize {
    let mut best = 0;
    for (i, &v) in q.iter().enumerate() {
        if v > q[best] {
            best = i;
        }
    }
    best
}

/// One stored transition.
#[derive(Debug, Clone)]
struct Item {
    obs: Vec<f32>,
    action: usize,
    reward: f32,
    discount: f32,
    next: Vec<f32>,
}

/// A FIFO replay with proportional priorities.
struct Replay {
    items: Vec<Option<Item>>,
    tree: SumTree,
    next: usize,
    len: usize,
    max_priority: f64,
    alpha: f64,
}

impl Replay {
    fn new(capacity: usize, alpha: f64) -> Self {
        Self {
            items: vec![None; capacity],
            tree: SumTree::new(capacity),
            next: 0,
            len: 0,
            max_priority: 1.0,
            alpha,
        }
    }

    fn insert(&mut self, item: Item, priority: f64) {
        let slot = self.next;
        self.items[slot] = Some(item);
        self.tree.set(slot, priority.max(1e-6).powf(self.alpha));
        self.next = (self.next + 1) % self.items.len();
        self.len = (self.len + 1).min(self.items.len());
    }

    fn sample(&self, n: usize, beta: f64, rng: &mut Rng) -> (Vec<usize>, Vec<f32>) {
        let total = self.tree.total();
        let min = self.tree.min().unwrap_or(1.0);
        let max_weight = (self.len as f64 * min / total).powf(-beta);
        let mut slots = Vec::with_capacity(n);
        let mut weights = Vec::with_capacity(n);
        for _ in 0..n {
            let slot = self
                .tree
                .find(rng.uniform() * total)
                .expect("a non-empty tree");
            let p = self.tree.get(slot) / total;
            slots.push(slot);
            weights.push(((self.len as f64 * p).powf(-beta) / max_weight) as f32);
        }
        (slots, weights)
    }

    fn update(&mut self, slot: usize, priority: f64) {
        self.max_priority = self.max_priority.max(priority);
        self.tree.set(slot, priority.max(1e-6).powf(self.alpha));
    }
}

/// Greedy evaluation: success, collision and timeout rates over
/// `episodes` episodes, and the learned Q at the line (clear and not).
fn evaluate(net: &QNetwork, o: &Options, episodes: usize, seed: u64) -> ([f64; 3], [Vec<f32>; 2]) {
    let mut rng = Rng::new(seed ^ 0xE7A1);
    let mut ends = [0usize; 3];
    for _ in 0..episodes {
        let mut env = Chain::new(&mut rng, o);
        loop {
            let q = &q_rows(net, &[env.observation(o)])[0];
            let (_, end) = env.step(argmax(q), &mut rng, o);
            if let Some(end) = end {
                ends[end as usize] += 1;
                break;
            }
        }
    }
    // With cars: every car midway past the threshold (clear), or the
    // first one midway before it (blocked).
    let line = |clear: bool| {
        let threshold = if o.cars == 0 {
            0.0
        } else {
            o.threshold() as f32
        };
        let mut cars = vec![(1.0 + threshold) / 2.0; o.cars];
        if !clear && let Some(first) = cars.first_mut() {
            *first = threshold / 2.0;
        }
        Chain {
            position: o.positions,
            clear,
            cars,
            t: 0,
        }
        .observation(o)
    };
    let q = q_rows(net, &[line(true), line(false)]);
    let rates = ends.map(|e| e as f64 / episodes as f64);
    (rates, [q[0].clone(), q[1].clone()])
}

fn epsilon(i: usize, n: usize) -> f64 {
    if n <= 1 {
        return 0.4;
    }
    0.4f64.powf(1.0 + 7.0 * i as f64 / (n - 1) as f64)
}

/// Pending n-step window of one environment.
type Window = VecDeque<(Vec<f32>, usize, f32)>;

fn run(o: &Options, seed: u64) {
    let spec = spec(o);
    let mut trainer = Trainer::new(TrainerConfig {
        spec: spec.clone(),
        seed,
        optimizer: OptimizerConfig::Adam {
            lr: o.lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1.5e-4,
        },
        max_grad_norm: 40.0,
        huber_delta: o.huber,
        target_update: TargetUpdate::Period,
        target_period: o.target_period,
        target_tau: 0.005,
        priority_eps: 1e-6,
        go_labels: None,
    })
    .expect("trainer");
    let mut acting = QNetwork::new(spec.clone(), seed).expect("network");
    acting.copy_from(trainer.online()).expect("copy");
    let mut rng = Rng::new(seed);
    let mut envs: Vec<Chain> = (0..o.envs).map(|_| Chain::new(&mut rng, o)).collect();
    let mut windows: Vec<Window> = vec![VecDeque::new(); o.envs];
    let mut replay = Replay::new(o.capacity, o.alpha);
    let (mut inserts, mut updates) = (0u64, 0u64);
    let mut go_inserts = [0u64; 2];
    // Gos taken at the line, and those of them when clear.
    let mut line_gos = [0u64; 2];
    println!(
        "seed {seed}: ratio {}, {} positions, clear {}, {} steps, {} demonstrating envs until {} updates; updates success collision timeout  Q(line,clear)[wait creep go]  Q(line,blocked)  transitions",
        o.ratio, o.positions, o.clear, o.steps, o.demo_envs, o.demo_updates
    );
    while updates < o.updates {
        // Every environment takes one step with the acting network.
        let obs: Vec<Vec<f32>> = envs.iter().map(|e| e.observation(o)).collect();
        let q = q_rows(&acting, &obs);
        for (i, env) in envs.iter_mut().enumerate() {
            let demonstrating = i >= o.envs.saturating_sub(o.demo_envs) && updates < o.demo_updates;
            let action = if demonstrating {
                env.rule(o)
            } else if rng.uniform() < epsilon(i, o.envs) {
                rng.below(3)
            } else {
                argmax(&q[i])
            };
            let at_line = env.position == o.positions;
            let (reward, end) = env.step(action, &mut rng, o);
            if action == GO {
                go_inserts[usize::from(reward > 0.0)] += 1;
                if at_line {
                    line_gos[usize::from(reward > 0.0)] += 1;
                }
            }
            windows[i].push_back((obs[i].clone(), action, reward));
            let next = env.observation(o);
            let done = end.is_some();
            let emit = |w: &mut Window, bootstrap: bool| {
                let (s, a, _) = w.front().cloned().expect("non-empty");
                let mut ret = 0.0;
                for (k, (_, _, r)) in w.iter().enumerate() {
                    ret += o.gamma.powi(k as i32) * r;
                }
                let discount = if bootstrap {
                    o.gamma.powi(w.len() as i32)
                } else {
                    0.0
                };
                w.pop_front();
                (
                    Item {
                        obs: s,
                        action: a,
                        reward: ret,
                        discount,
                        next: next.clone(),
                    },
                    a,
                )
            };
            let mut ready = Vec::new();
            if done {
                while !windows[i].is_empty() {
                    ready.push(emit(&mut windows[i], false).0);
                }
                *env = Chain::new(&mut rng, o);
            } else if windows[i].len() == o.n_step {
                ready.push(emit(&mut windows[i], true).0);
            }
            for item in ready {
                let priority = if o.max_priority {
                    replay.max_priority
                } else {
                    let rows = q_rows(&acting, &[item.obs.clone(), item.next.clone()]);
                    let target = item.reward
                        + item.discount * rows[1].iter().cloned().fold(f32::MIN, f32::max);
                    f64::from((target - rows[0][item.action]).abs())
                };
                replay.insert(item, priority);
                inserts += 1;
            }
        }
        // Updates the ratio allows.
        if replay.len < o.min_size {
            continue;
        }
        while ((updates + 1) * o.batch as u64) as f64
            <= (inserts - o.min_size as u64) as f64 * o.ratio + o.batch as f64
            && updates < o.updates
        {
            let beta = 0.4 + 0.6 * updates as f64 / o.updates as f64;
            let (slots, weights) = replay.sample(o.batch, beta, &mut rng);
            let mut b =
                TransitionBatch::new(spec.observation.clone(), 3, ObservationEncoding::DenseF32);
            for &slot in &slots {
                let item = replay.items[slot].as_ref().expect("sampled item");
                let s = b.push_observation(&item.obs);
                let n = b.push_observation(&item.next);
                b.push(Transition {
                    observation: s,
                    action: item.action as u32,
                    reward: item.reward,
                    discount: item.discount,
                    priority: 1.0,
                    next_observation: n,
                });
            }
            let keys = slots.iter().map(|&s| s as u64).collect();
            let batch = TrainingBatch::from_batch(&b, &weights, keys, &spec).expect("batch");
            let stats = trainer.update(&batch).expect("update");
            for (&slot, &p) in slots.iter().zip(&stats.priorities) {
                replay.update(slot, f64::from(p));
            }
            updates += 1;
            if updates.is_multiple_of(o.sync_every) {
                acting.copy_from(trainer.online()).expect("copy");
            }
            if updates.is_multiple_of(o.every) {
                let (rates, [clear, blocked]) = evaluate(trainer.online(), o, 300, seed);
                println!(
                    "  {updates:>6}  {:>6.1} % {:>6.1} % {:>6.1} %  [{:+.2} {:+.2} {:+.2}]  [{:+.2} {:+.2} {:+.2}]  {inserts} (gos {} safe {}; at the line {} safe {})",
                    rates[0] * 100.0,
                    rates[1] * 100.0,
                    rates[2] * 100.0,
                    clear[WAIT],
                    clear[CREEP],
                    clear[GO],
                    blocked[WAIT],
                    blocked[CREEP],
                    blocked[GO],
                    go_inserts[0] + go_inserts[1],
                    go_inserts[1],
                    line_gos[0] + line_gos[1],
                    line_gos[1],
                );
            }
        }
    }
}

fn main() {
    let o = parse();
    tch::set_num_threads(1);
    for &seed in &o.seeds {
        run(&o, seed);
    }
}

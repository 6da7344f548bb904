//! Q(go) diagnosed before it is tuned: can the network tell a safe moment
//! to go from a doomed one? Creep networks undervalue *go* where it is safe
//! (`eval --risk 16 --missed`): too thin a learning signal (*data*), or too
//! poor an observation (*features*)? It drives `--episodes` greedy episodes
//! of `--scenario` with `--policy`'s network and labels every `--every`-th
//! decision before a *go* with the mean discounted return of going in
//! `--futures` forks (the present, hidden cars included, then other random
//! traffic): *safe* when every fork reached the goal, *doomed* when more
//! than half collided.
//! A network of the same shape (`--start` fresh or from the policy's
//! weights) regresses Q(go) on four fifths of the episodes (Adam,
//! `--updates` batches of `--batch`, labels averaging the first
//! `--train-futures` forks; comma lists run one regression per combination,
//! the fresh one on all forks giving the verdict); on the rest they and the
//! RL network are compared with the labels (medians at safe states in view
//! and at doomed ones, AUC of safe over doomed). The verdict, fixed before the
//! first run: *features* when the regression's AUC is below 0.9 or its
//! median at safe states in view is more than 1 below their median label,
//! else *data*. Results: reports/occlusion-ladder/README.md and NOTES.md.

use std::path::PathBuf;
use std::sync::Arc;

use crossroads_model::QNetwork;
use crossroads_sim::{ActionSet, Env, EnvConfig, IN_VIEW_S, Outcome, Scenario, episode_seed};
use rayon::prelude::*;
use tch::nn::OptimizerConfig;
use tch::{Kind, Tensor};

#[derive(Debug)]
struct Args {
    policy: PathBuf,
    scenario: String,
    episodes: u64,
    futures: u32,
    /// Forks averaged into each training label, one regression per entry
    /// (the held-out comparison always uses all `futures`).
    train_futures: Vec<u32>,
    seed: u64,
    /// Adam updates, one regression per entry.
    updates: Vec<usize>,
    /// Where each regression starts, one regression per entry.
    start: Vec<Start>,
    batch: usize,
    lr: f64,
    every: u32,
}

fn parse_args() -> Args {
    let mut a = Args {
        policy: PathBuf::from("reports/paper/runs/creep-occluded/best"),
        scenario: "occluded".to_owned(),
        episodes: 2000,
        futures: 16,
        train_futures: Vec::new(),
        seed: 1,
        updates: vec![20_000],
        start: vec![Start::Fresh],
        batch: 256,
        lr: 1e-3,
        every: 2,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        let bad = |what: &str| -> ! { panic!("{flag} {value:?}: {what}") };
        match flag.as_str() {
            "--policy" => a.policy = PathBuf::from(value),
            "--scenario" => a.scenario = value,
            "--episodes" => a.episodes = value.parse().unwrap_or_else(|_| bad("a count")),
            "--futures" => a.futures = value.parse().unwrap_or_else(|_| bad("a count")),
            "--seed" => a.seed = value.parse().unwrap_or_else(|_| bad("a number")),
            "--train-futures" => a.train_futures = list(&value).unwrap_or_else(|| bad("counts")),
            "--updates" => a.updates = list(&value).unwrap_or_else(|| bad("counts")),
            "--start" => a.start = list(&value).unwrap_or_else(|| bad("fresh or policy")),
            "--batch" => a.batch = value.parse().unwrap_or_else(|_| bad("a count")),
            "--lr" => a.lr = value.parse().unwrap_or_else(|_| bad("a number")),
            "--every" => a.every = value.parse().unwrap_or_else(|_| bad("a count")),
            _ => panic!(
                "unknown flag {flag}; known: --policy --scenario --episodes --futures \
                 --train-futures --seed --updates --start --batch --lr --every"
            ),
        }
    }
    if a.train_futures.is_empty() {
        a.train_futures = vec![a.futures];
    }
    if let Some(&n) = a.train_futures.iter().find(|&&n| n == 0 || n > a.futures) {
        panic!(
            "--train-futures {n}: between 1 and --futures ({})",
            a.futures
        );
    }
    a
}

/// Where a regression's weights start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Start {
    /// New weights from `--seed`.
    Fresh,
    /// The RL network's own weights.
    Policy,
}

impl std::str::FromStr for Start {
    type Err = ();
    fn from_str(s: &str) -> Result<Self, ()> {
        match s {
            "fresh" => Ok(Self::Fresh),
            "policy" => Ok(Self::Policy),
            _ => Err(()),
        }
    }
}

impl std::fmt::Display for Start {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Fresh => "fresh",
            Self::Policy => "policy",
        })
    }
}

/// A comma-separated list of counts (`1,16`), `None` if any is not one.
fn list<T: std::str::FromStr>(value: &str) -> Option<Vec<T>> {
    value.split(',').map(|v| v.trim().parse().ok()).collect()
}

/// One labelled decision.
struct Sample {
    episode: u64,
    obs: Vec<f32>,
    /// Mean discounted return of going now, over the forks.
    label: f32,
    /// Each fork's discounted return, in fork order.
    returns: Vec<f32>,
    safe: bool,
    doomed: bool,
    in_view: bool,
    /// The RL network's Q(go) here.
    q_go: f32,
}

/// Goes in `futures` forks of `env`: the mean return, whether every fork
/// reached the goal, whether more than half collided.
fn label(env: &Env, go: usize, futures: u32, base: u64) -> (f32, Vec<f32>, bool, bool) {
    let runs: Vec<(f64, Option<Outcome>)> = (0..futures)
        .into_par_iter()
        .map(|j| {
            let mut fork = env.fork(episode_seed(base, u64::from(j)));
            let r = fork.step(go).expect("a fork steps");
            (r.reward, fork.metrics().outcome)
        })
        .collect();
    let n = f64::from(futures);
    let mean = runs.iter().map(|r| r.0).sum::<f64>() / n;
    let successes = runs
        .iter()
        .filter(|r| r.1 == Some(Outcome::Success))
        .count();
    let collisions = runs
        .iter()
        .filter(|r| r.1 == Some(Outcome::Collision))
        .count();
    (
        mean as f32,
        runs.iter().map(|r| r.0 as f32).collect(),
        successes == futures as usize,
        2 * collisions > futures as usize,
    )
}

fn collect(a: &Args, net: &QNetwork, scenario: &Arc<Scenario>, go: usize) -> Vec<Sample> {
    let mut out = Vec::new();
    let mut env = Env::new(
        Arc::clone(scenario),
        EnvConfig::for_actions(ActionSet::Creep),
    );
    let len = env.obs_spec().len();
    let mut obs = vec![0.0f32; len];
    let view = IN_VIEW_S * scenario.spec().speed_limit;
    for e in 0..a.episodes {
        env.reset(episode_seed(a.seed, e));
        let mut decision = 0u32;
        while !env.is_done() {
            env.write_observation(&mut obs).expect("observation");
            let q = net.infer(&obs, 1).expect("forward pass");
            let q = q.row(0);
            if decision.is_multiple_of(a.every.max(1)) {
                let base = !episode_seed(a.seed ^ 0x9E0, e * 10_000 + u64::from(env.steps()));
                let (label, returns, safe, doomed) = label(&env, go, a.futures, base);
                out.push(Sample {
                    episode: e,
                    obs: obs.clone(),
                    label,
                    returns,
                    safe,
                    doomed,
                    in_view: env.sees_conflicts(view),
                    q_go: q[go],
                });
            }
            decision += 1;
            let action = q
                .iter()
                .enumerate()
                .max_by(|x, y| x.1.total_cmp(y.1))
                .map_or(0, |(i, _)| i);
            env.step(action).expect("step");
        }
        if (e + 1).is_multiple_of(200) {
            eprintln!("  {} episodes, {} decisions labelled", e + 1, out.len());
        }
    }
    out
}

/// A network of `net`'s shape (fresh, or `net`'s own weights read again
/// from `policy`) regressing Q(go) on the mean of each sample's first
/// `forks` returns, `updates` Adam steps.
fn train(
    a: &Args,
    net: &QNetwork,
    policy: Option<&[u8]>,
    train: &[&Sample],
    go: usize,
    (forks, updates): (u32, usize),
) -> QNetwork {
    let fresh = match policy {
        Some(bytes) => QNetwork::from_safetensors(bytes).expect("the policy").0,
        None => QNetwork::new(net.spec().clone(), a.seed).expect("network"),
    };
    let mut opt = tch::nn::Adam::default()
        .build(fresh.var_store(), a.lr)
        .expect("optimizer");
    let len = train[0].obs.len();
    let mut rng = a.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let mut flat = vec![0.0f32; a.batch * len];
    let mut targets = vec![0.0f32; a.batch];
    let labels: Vec<f32> = train
        .iter()
        .map(|s| s.returns[..forks as usize].iter().sum::<f32>() / forks as f32)
        .collect();
    for u in 0..updates {
        for k in 0..a.batch {
            let i = (next() % train.len() as u64) as usize;
            flat[k * len..(k + 1) * len].copy_from_slice(&train[i].obs);
            targets[k] = labels[i];
        }
        let x = Tensor::from_slice(&flat).view([a.batch as i64, len as i64]);
        let y = Tensor::from_slice(&targets);
        let q = fresh.q_values(&x).expect("forward").select(1, go as i64);
        let loss = (q - y).square().mean(Kind::Float);
        opt.backward_step(&loss);
        if (u + 1).is_multiple_of(5_000) {
            eprintln!("  update {}: mse {:.4}", u + 1, loss.double_value(&[]));
        }
    }
    fresh
}

/// Q(go) at held-out decision `i`, by one source.
type Reading<'a> = Box<dyn Fn(usize) -> f32 + 'a>;

fn median(mut v: Vec<f32>) -> f32 {
    if v.is_empty() {
        return f32::NAN;
    }
    v.sort_by(f32::total_cmp);
    v[v.len() / 2]
}

/// Probability that a random safe state scores above a random doomed one.
fn auc(safe: &[f32], doomed: &[f32]) -> f64 {
    if safe.is_empty() || doomed.is_empty() {
        return f64::NAN;
    }
    let mut d = doomed.to_vec();
    d.sort_by(f32::total_cmp);
    let mut wins = 0.0;
    for &s in safe {
        let below = d.partition_point(|&x| x < s);
        let equal = d[below..].partition_point(|&x| x <= s);
        wins += below as f64 + 0.5 * equal as f64;
    }
    wins / (safe.len() as f64 * d.len() as f64)
}

fn main() {
    let a = parse_args();
    let file = if a.policy.is_dir() {
        a.policy.join("weights.safetensors")
    } else {
        a.policy.clone()
    };
    let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let (net, version) = QNetwork::from_safetensors(&bytes).expect("a network");
    let scenario = Arc::new(Scenario::load(&a.scenario).expect("scenario"));
    let go = ActionSet::Creep.absorbing_go().expect("creep has a go");
    eprintln!(
        "qgo_probe: {} (v{version}) on {}, {} episodes, {} futures per decision",
        file.display(),
        a.scenario,
        a.episodes,
        a.futures
    );
    let samples = collect(&a, &net, &scenario, go);
    let (held, fit): (Vec<&Sample>, Vec<&Sample>) =
        samples.iter().partition(|s| s.episode % 5 == 0);
    eprintln!(
        "  {} decisions: {} to fit, {} held out",
        samples.len(),
        fit.len(),
        held.len()
    );
    let len = held[0].obs.len();
    let flat: Vec<f32> = held.iter().flat_map(|s| s.obs.iter().copied()).collect();
    // One regression per (forks a label, updates) pair, in the order given.
    let mut regressions: Vec<(String, Vec<f32>)> = Vec::new();
    // The regression the verdict was written for: fresh weights, labels of
    // every fork, the largest budget.
    let mut judged: Option<(usize, usize)> = None;
    for &start in &a.start {
        for &forks in &a.train_futures {
            for &updates in &a.updates {
                eprintln!(
                    "  regression from {start} weights on {forks}-fork labels, {updates} updates"
                );
                let policy = (start == Start::Policy).then_some(bytes.as_slice());
                if start == Start::Fresh
                    && forks == a.futures
                    && judged.is_none_or(|(_, u)| updates > u)
                {
                    judged = Some((regressions.len(), updates));
                }
                let regression = train(&a, &net, policy, &fit, go, (forks, updates));
                let predicted: Vec<f32> = tch::no_grad(|| {
                    let x = Tensor::from_slice(&flat).view([held.len() as i64, len as i64]);
                    let q = regression
                        .q_values(&x)
                        .expect("forward")
                        .select(1, go as i64);
                    Vec::<f32>::try_from(&q).expect("values")
                });
                regressions.push((
                    format!("regression from {start} ({forks}-fork labels, {updates} updates)"),
                    predicted,
                ));
            }
        }
    }
    let pick = |f: &dyn Fn(&Sample) -> bool, v: &dyn Fn(usize) -> f32| -> Vec<f32> {
        (0..held.len()).filter(|&i| f(held[i])).map(v).collect()
    };
    let safe_in_view = |s: &Sample| s.safe && s.in_view;
    let safe = |s: &Sample| s.safe;
    let doomed = |s: &Sample| s.doomed;
    let label_of = |i: usize| held[i].label;
    let rl = |i: usize| held[i].q_go;
    let mse = |v: &dyn Fn(usize) -> f32| -> f64 {
        (0..held.len())
            .map(|i| f64::from(v(i) - held[i].label).powi(2))
            .sum::<f64>()
            / held.len() as f64
    };
    let mean_label = held.iter().map(|s| f64::from(s.label)).sum::<f64>() / held.len() as f64;
    let variance = held
        .iter()
        .map(|s| (f64::from(s.label) - mean_label).powi(2))
        .sum::<f64>()
        / held.len() as f64;
    println!(
        "held out: {} decisions, {} safe ({} in view), {} doomed; label variance {variance:.3}",
        held.len(),
        pick(&safe, &label_of).len(),
        pick(&safe_in_view, &label_of).len(),
        pick(&doomed, &label_of).len()
    );
    println!(
        "| Q(go) | median at safe in view | at safe | at doomed | AUC safe > doomed | MSE vs label |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: |");
    let label_name = format!("label ({} futures)", a.futures);
    let mut rows: Vec<(&str, Reading<'_>)> = vec![(label_name.as_str(), Box::new(label_of))];
    for (name, predicted) in &regressions {
        rows.push((name.as_str(), Box::new(move |i: usize| predicted[i])));
    }
    rows.push(("RL network", Box::new(rl)));
    for (name, v) in &rows {
        let v: &dyn Fn(usize) -> f32 = v.as_ref();
        println!(
            "| {name} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            median(pick(&safe_in_view, v)),
            median(pick(&safe, v)),
            median(pick(&doomed, v)),
            auc(&pick(&safe, v), &pick(&doomed, v)),
            mse(v)
        );
    }
    let Some((judged, _)) = judged else {
        println!(
            "verdict: none (it reads a regression from fresh weights on labels of all {} forks; \
             add fresh to --start and {} to --train-futures)",
            a.futures, a.futures
        );
        return;
    };
    let reg = |i: usize| regressions[judged].1[i];
    let reg_auc = auc(&pick(&safe, &reg), &pick(&doomed, &reg));
    let gap = median(pick(&safe_in_view, &label_of)) - median(pick(&safe_in_view, &reg));
    let verdict = if reg_auc < 0.9 || gap > 1.0 {
        "features: the regression cannot separate what the labels know"
    } else {
        "data: the network's shape learns Q(go) from the labels; the replay did not teach it"
    };
    println!("verdict: {verdict} (regression AUC {reg_auc:.3}, safe-in-view median gap {gap:.3})");
}

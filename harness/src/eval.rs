//! `crossroads eval`: a policy on a scenario for N seeded trials.
//!
//! A thin wrapper over `crossroads_sim`: `run_trials` and `summarize` for
//! the report, `go_risk` for `--risk` and `--missed`, the failed trials
//! listed for `render` with `--failures`, and with `--shield` the policy
//! wrapped in `ShieldedPolicy` (as `render` does).

use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::Context;
use clap::Args;
use crossroads_sim::{
    ActionSet, Env, EnvConfig, EvalConfig, EvalReport, Interval, Outcome, Policy, RiskOptions,
    RiskReport, Scenario, ShieldCounters, ShieldParams, ShieldedPolicy, TrialResult, go_risk,
    parse_policy, run_trials, summarize,
};
use serde::Serialize;

use crate::network_policy::NetworkPolicy;
use crate::progress;

/// A policy driving an action set on a scenario (`eval`, `render`).
#[derive(Debug, Args)]
pub struct PolicyArgs {
    /// Policy: ttc:<seconds>, ttc-creep:<seconds>, random, never (the ego
    /// waits out the time limit: traffic alone), go (wants to go at every
    /// decision: with --shield, the shield alone), oracle:<futures> (sees
    /// hidden cars and goes when going reaches the goal in every one of
    /// that many futures: the upper bound under occlusion), or a trained
    /// network: a checkpoint folder (runs/NAME/best,
    /// runs/NAME/checkpoints/ckpt-...) or a weights .safetensors file;
    /// several networks of the same kind joined by commas act on the mean
    /// of their Q-values (an ensemble).
    #[arg(long, short = 'p')]
    pub policy: String,
    /// Scenario: right, left, left2, forward, challenge, occluded,
    /// occluded-<30|60|90>[-left|-right|-both], or a scenario TOML file.
    #[arg(long, default_value = "left")]
    pub scenario: String,
    /// Who drives the traffic: sumo (SUMO's drivers, the paper's), human
    /// (reaction 0.7-1.5 s and the rest as measured on roads;
    /// docs/drivers.md), mixed (half each), or a drivers TOML file
    /// [default: the scenario's own].
    #[arg(long, value_name = "PRESET|FILE")]
    pub drivers: Option<String>,
    /// Action set the policy drives: ttg, creep or sequential [default: a
    /// network's own; ttg for a rule].
    #[arg(long, value_parser = parse_action_set)]
    pub actions: Option<ActionSet>,
    /// Put the policy behind the safety shield: each *go* is checked
    /// against the cars the ego senses and phantom cars where its view
    /// ends, and vetoed when any could come too close (ttg and creep
    /// actions). Optionally override its assumptions, e.g.
    /// `--shield margin_s=0.3,phantom_factor=1.1` (keys: speed_factor,
    /// phantom_factor, slow_factor, margin_s, gap_m, follower_decel,
    /// reaction_s, yield_decel, fall_in_decel, clear_s, hard_decel,
    /// range_m, leader_decel, see_through; `yield_decel=4.5` counts on
    /// comfortable braking only; `range_m=150` senses each lane whole, as
    /// the TTC rule does; `see_through=1` lets walls hide nothing), or take
    /// a driver population's worst bounds with `assume=human` (a preset or
    /// a drivers file; the defaults assume SUMO's drivers).
    #[arg(long, value_name = "ASSUMPTIONS", num_args = 0..=1, default_missing_value = "default")]
    pub shield: Option<String>,
    /// Number format of a network policy's trunk: f32 (the same result on
    /// every machine), bf16, or auto (what a training run's actors use,
    /// which is f32: auto picks bf16 only for the learner's updates).
    #[arg(long, default_value = "f32", value_name = "auto|f32|bf16")]
    pub precision: crossroads_config::PrecisionSetting,
}

/// `crossroads eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    #[command(flatten)]
    pub run: PolicyArgs,
    /// Number of trials.
    #[arg(long, short = 'n', default_value_t = 10_000)]
    pub trials: u64,
    /// Base seed; the same seed gives the same result on any number of
    /// threads.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON object (rates as fractions) instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also replay every *go* decision in K other traffic futures (the same
    /// state, other random draws) and report how likely each was to
    /// collide: collisions the state already decided are the policy's
    /// mistakes, the rest its calculated risks (ttg and creep actions).
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub risk: Option<u32>,
    /// With --risk: also try *go* in the same K futures once a second
    /// while the policy waits or creeps, and report the chances it passed
    /// up (waits where going reached the goal in every future): timeouts
    /// that had one, and how late the policy went after its first. Tells a
    /// too cautious network from traffic that left no gap. For a network,
    /// also its Q(go) and best other value at safe and at doomed probes:
    /// whether it tells them apart
    #[arg(long, requires = "risk")]
    pub missed: bool,
    /// List the first N collided and the first N timed-out trials, each
    /// as the `--seed S --trial I` that `crossroads render` draws (any
    /// action set; with --json, as a `failures` object).
    #[arg(long, value_name = "N", default_value_t = 0, conflicts_with = "risk")]
    pub failures: usize,
}

/// An action set by name, for clap.
pub(crate) fn parse_action_set(s: &str) -> Result<ActionSet, String> {
    s.parse::<ActionSet>().map_err(|e| e.to_string())
}

/// What `--json` prints: the fields first, then the intervals.
#[derive(Debug, Serialize)]
struct JsonReport<'a> {
    scenario: &'a str,
    policy: &'a str,
    actions: &'a str,
    trials: u64,
    seed: u64,
    success_rate: f64,
    collision_rate: f64,
    timeout_rate: f64,
    mean_time_s: Option<f64>,
    mean_brake_s: f64,
    mean_brake_light_s: f64,
    mean_wait_s: Option<f64>,
    success_ci95: Interval,
    collision_ci95: Interval,
    timeout_ci95: Interval,
    mean_time_ci95: Option<Interval>,
    mean_brake_ci95: Interval,
    mean_brake_light_ci95: Interval,
    mean_wait_ci95: Option<Interval>,
    mean_go_offset_m: Option<f64>,
    mean_go_speed: Option<f64>,
    mean_return: f64,
    mean_return_ci95: Interval,
    wall_seconds: f64,
}

/// A policy as `crossroads eval` and `render` run it.
#[derive(Debug)]
pub struct LoadedPolicy {
    /// The scenario.
    pub scenario: Arc<Scenario>,
    /// The policy, behind the shield with `--shield`.
    pub policy: Box<dyn Policy>,
    /// With `--shield`: its assumptions and counters.
    pub shield: Option<(ShieldParams, Arc<ShieldCounters>)>,
    /// The action set it drives: `--actions`, else a network's own, else
    /// TTG.
    pub actions: ActionSet,
}

/// The scenario and the policy that `args` name, checked to fit the action
/// set; errors name the flag at fault.
pub fn load(args: &PolicyArgs) -> anyhow::Result<LoadedPolicy> {
    let scenario = Arc::new(
        Scenario::load_with_drivers(&args.scenario, args.drivers.as_deref())
            .with_context(|| format!("scenario {:?}", args.scenario))?,
    );
    let (mut policy, actions): (Box<dyn Policy>, ActionSet) =
        match NetworkPolicy::load(Path::new(&args.policy))
            .with_context(|| format!("--policy {}", args.policy))?
        {
            Some(mut net) => {
                let actions = match args.actions {
                    Some(set) => set,
                    None => net.spec().action_set.parse().with_context(|| {
                        format!("--policy {}: its action set", args.policy)
                    })?,
                };
                net.set_precision(args.precision);
                net.fits(&Env::new(
                    Arc::clone(&scenario),
                    EnvConfig::for_actions(actions),
                ))
                .with_context(|| format!("--policy {}", args.policy))?;
                (Box::new(net), actions)
            }
            None => (
                parse_policy(&args.policy).context(
                    "--policy (a checkpoint folder, a .safetensors file, ttc:<s>, ttc-creep:<s>, oracle:<futures>, random, never or go)",
                )?,
                args.actions.unwrap_or(ActionSet::Ttg),
            ),
        };
    let mut shield = None;
    if let Some(spec) = &args.shield {
        let params = ShieldParams::parse(spec).context("--shield")?;
        let shielded = ShieldedPolicy::new(policy, params);
        shield = Some((params, shielded.counters()));
        policy = Box::new(shielded);
    }
    policy
        .supports(actions)
        .with_context(|| format!("--policy {} with --actions {}", args.policy, actions.name()))?;
    Ok(LoadedPolicy {
        scenario,
        policy,
        shield,
        actions,
    })
}

/// Runs the evaluation and prints the report.
pub fn run(args: &EvalArgs) -> anyhow::Result<ExitCode> {
    let LoadedPolicy {
        scenario,
        policy,
        shield,
        actions,
    } = load(&args.run)?;
    anyhow::ensure!(args.trials > 0, "--trials must be at least 1");
    let config = EvalConfig::new(actions, args.trials, args.seed);

    let bar = progress::bar(args.trials, "trials");
    bar.set_message(format!("{} on {}", policy.name(), scenario.name()));
    let start = std::time::Instant::now();
    let mut failures = None;
    let (report, risk) = match args.risk {
        Some(futures) => {
            let options = RiskOptions {
                futures,
                missed: args.missed,
            };
            let risk = go_risk(&scenario, policy.as_ref(), &config, options, &|n| {
                bar.inc(n)
            })?;
            (risk.eval.clone(), Some(risk))
        }
        None => {
            let results = run_trials(&scenario, policy.as_ref(), &config, &|n| bar.inc(n))?;
            if args.failures > 0 {
                failures = Some(Failures::first(&results, args.failures));
            }
            (
                summarize(scenario.name(), &policy.name(), &config, &results),
                None,
            )
        }
    };
    let wall = start.elapsed().as_secs_f64();
    bar.finish_and_clear();

    if args.json {
        let mut value = serde_json::to_value(json(&report, wall))?;
        if let (Some(risk), Some(object)) = (&risk, value.as_object_mut()) {
            object.insert("risk".to_owned(), risk_json(risk)?);
        }
        if let (Some(f), Some(object)) = (&failures, value.as_object_mut()) {
            object.insert("failures".to_owned(), serde_json::to_value(f)?);
        }
        if let Some(object) = value.as_object_mut() {
            object.insert(
                "drivers".to_owned(),
                serde_json::to_value(&scenario.spec().drivers)?,
            );
        }
        if let (Some((params, counters)), Some(object)) = (&shield, value.as_object_mut()) {
            object.insert(
                "shield".to_owned(),
                serde_json::json!({ "assumptions": params, "counts": counters.stats() }),
            );
        }
        println!("{value}");
    } else {
        print!("{}", text(&report, wall));
        println!("  drivers      {}", scenario.spec().drivers);
        if let Some((_, counters)) = &shield {
            let c = counters.stats();
            println!(
                "  shield       {} of {} go decisions vetoed: {} crossing, {} ahead, {} behind; \
                 {} for a car it could not see",
                c.vetoes, c.go_decisions, c.crossing, c.ahead, c.behind, c.phantom_vetoes
            );
        }
        if let Some(risk) = &risk {
            print!("{}", risk_text(risk, args.seed));
        }
        if let Some(f) = &failures {
            print!("{}", f.text(args.seed));
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The first failed trials of an evaluation, by outcome, in trial order.
#[derive(Debug, PartialEq, Serialize)]
struct Failures {
    /// Collided trials: (trial, seconds into the episode).
    collisions: Vec<(u64, f64)>,
    /// Timed-out trials.
    timeouts: Vec<u64>,
}

impl Failures {
    /// At most `n` of each kind.
    fn first(results: &[TrialResult], n: usize) -> Self {
        let trials = |o: Outcome| {
            results
                .iter()
                .enumerate()
                .filter(move |(_, r)| r.outcome == o)
                .take(n)
                .map(|(i, r)| (i as u64, r.time_s))
        };
        Self {
            collisions: trials(Outcome::Collision).collect(),
            timeouts: trials(Outcome::Timeout).map(|(i, _)| i).collect(),
        }
    }

    fn text(&self, seed: u64) -> String {
        let mut out = String::new();
        if self.collisions.is_empty() && self.timeouts.is_empty() {
            return "  no collisions or timeouts to list\n".to_owned();
        }
        out += "  failed trials (draw one with crossroads render ... --seed S --trial I):\n";
        for (trial, t) in &self.collisions {
            out += &format!("    --seed {seed} --trial {trial:<6} collided at {t:.1} s\n");
        }
        for trial in &self.timeouts {
            out += &format!("    --seed {seed} --trial {trial:<6} timed out\n");
        }
        out
    }
}

/// The risk part of `--json`: the report without its evaluation (already
/// at the top level).
fn risk_json(r: &RiskReport) -> anyhow::Result<serde_json::Value> {
    let mut value = serde_json::to_value(r)?;
    if let Some(object) = value.as_object_mut() {
        object.remove("eval");
    }
    Ok(value)
}

/// The risk table under the evaluation's.
pub fn risk_text(r: &RiskReport, seed: u64) -> String {
    let mut out = format!(
        "  go decisions {}, each replayed in {} other traffic futures\n\
         \x20   P(collision | state, go)   decisions   collided\n",
        r.decisions, r.futures
    );
    for b in &r.bins {
        let range = if b.high == 0.0 {
            "0".to_owned()
        } else {
            format!("({:.0}, {:.0} %]", 100.0 * b.low, 100.0 * b.high)
        };
        out += &format!("    {range:<26} {:>9}   {:>8}\n", b.decisions, b.collisions);
    }
    let after_go: u64 = r.bins.iter().map(|b| b.collisions).sum();
    out += &format!(
        "  collisions after a go: {after_go}, of which {} foreseeable (P > 50 %: mistakes), {} chance; \
         other collisions: {}\n",
        r.foreseeable,
        after_go - r.foreseeable,
        r.other_collisions
    );
    if !r.riskiest.is_empty() {
        out += "  riskiest go decisions (render one with --seed S --trial I --step STEP):\n";
        for d in &r.riskiest {
            out += &format!(
                "    --seed {seed} --trial {:<6} --step {:<4} P = {:5.1} %{}\n",
                d.trial,
                d.step,
                100.0 * d.p_collision,
                if d.collided { "   collided" } else { "" }
            );
        }
    }
    if let Some(m) = &r.missed {
        out += &format!(
            "  waits probed {} (one every {:.0} s at most), going reached the goal in every future at {}\n\
             \x20 {} of them with the conflicting lanes in view ({:.0} m upstream)\n\
             \x20 timeouts {} of which {} passed up a safe chance, {} one in view; {} trials went after one, {} later (median)\n",
            m.probes,
            m.probe_every_s,
            m.safe,
            m.safe_in_view,
            m.in_view_m,
            m.timeouts,
            m.timeouts_with_chance,
            m.timeouts_with_chance_in_view,
            m.went_late,
            m.median_delay_s
                .map_or("-".to_owned(), |d| format!("{d:.1} s")),
        );
        if let Some(v) = &m.values {
            let f = |x: Option<f64>| x.map_or("-".to_owned(), |x| format!("{x:+.3}"));
            out += "  the network's values at probed waits in view (medians; margin = Q(go) - best other):\n\
                    \x20   probes                    count      Q(go)   best other   margin   margin > -0.05\n";
            for (name, s) in [
                ("safe (every future reached)", &v.safe),
                ("doomed (most collided)", &v.doomed),
            ] {
                out += &format!(
                    "    {name:<27} {:>7}   {:>8}   {:>10}   {:>6}   {}\n",
                    s.probes,
                    f(s.q_go),
                    f(s.q_other),
                    f(s.margin),
                    s.near
                        .map_or("-".to_owned(), |n| format!("{:.1} %", 100.0 * n)),
                );
            }
        }
        if !m.passed_up.is_empty() {
            out +=
                "  timeouts' first safe chance (render one with --seed S --trial I --step STEP):\n";
            for c in &m.passed_up {
                out += &format!(
                    "    --seed {seed} --trial {:<6} --step {}\n",
                    c.trial, c.step
                );
            }
        }
    }
    out
}

fn json(r: &EvalReport, wall_seconds: f64) -> JsonReport<'_> {
    JsonReport {
        scenario: &r.scenario,
        policy: &r.policy,
        actions: &r.action_set,
        trials: r.trials,
        seed: r.seed,
        success_rate: r.success_rate,
        collision_rate: r.collision_rate,
        timeout_rate: r.timeout_rate,
        mean_time_s: r.mean_time_s,
        mean_brake_s: r.mean_brake_s,
        mean_brake_light_s: r.mean_brake_light_s,
        mean_wait_s: r.mean_wait_s,
        success_ci95: r.success_ci,
        collision_ci95: r.collision_ci,
        timeout_ci95: r.timeout_ci,
        mean_time_ci95: r.mean_time_ci,
        mean_brake_ci95: r.mean_brake_ci,
        mean_brake_light_ci95: r.mean_brake_light_ci,
        mean_wait_ci95: r.mean_wait_ci,
        mean_go_offset_m: r.mean_go_offset_m,
        mean_go_speed: r.mean_go_speed,
        mean_return: r.mean_return,
        mean_return_ci95: r.mean_return_ci,
        wall_seconds,
    }
}

/// The human-readable report.
pub fn text(r: &EvalReport, wall_seconds: f64) -> String {
    let pct = |v: f64, ci: &Interval| {
        format!(
            "{:7.2} %   [{:.2}, {:.2}]",
            100.0 * v,
            100.0 * ci.low,
            100.0 * ci.high
        )
    };
    let secs = |v: f64, ci: &Interval| format!("{v:7.2} s   [{:.2}, {:.2}]", ci.low, ci.high);
    let time = match (r.mean_time_s, &r.mean_time_ci) {
        (Some(t), Some(ci)) => secs(t, ci),
        _ => "      -     (no successful run)".to_owned(),
    };
    let ret = format!(
        "{:7.3}     [{:.3}, {:.3}]",
        r.mean_return, r.mean_return_ci.low, r.mean_return_ci.high
    );
    let wait = match (r.mean_wait_s, &r.mean_wait_ci) {
        (Some(t), Some(ci)) => secs(t, ci),
        _ if r.action_set == ActionSet::Sequential.name() => {
            "      -     (no go action)".to_owned()
        }
        _ => "      -     (never went)".to_owned(),
    };
    let at_go = match (r.mean_go_offset_m, r.mean_go_speed) {
        (Some(m), Some(v)) => format!(
            "{m:7.2} m past the creep limit (negative: short of it), {v:.2} m/s (means, runs that went)"
        ),
        _ => "      -".to_owned(),
    };
    format!(
        "{policy} on {scenario} ({actions} actions), {trials} trials, seed {seed}, {wall:.2} s\n\
         \x20                  value      95 % interval\n\
         \x20 success      {s}\n\
         \x20 collision    {c}\n\
         \x20 timeout      {t}\n\
         \x20 mean time    {time}   (successful runs)\n\
         \x20 mean wait    {wait}   (before go, runs that went)\n\
         \x20 at go        {at_go}\n\
         \x20 mean brake   {b}   (traffic braking per run)\n\
         \x20 brake light  {l}   (per run, SUMO's rule)\n\
         \x20 mean return  {ret}   (per run, undiscounted, the scenario's rewards)\n",
        policy = r.policy,
        scenario = r.scenario,
        actions = r.action_set,
        trials = r.trials,
        seed = r.seed,
        wall = wall_seconds,
        s = pct(r.success_rate, &r.success_ci),
        c = pct(r.collision_rate, &r.collision_ci),
        t = pct(r.timeout_rate, &r.timeout_ci),
        b = secs(r.mean_brake_s, &r.mean_brake_ci),
        l = secs(r.mean_brake_light_s, &r.mean_brake_light_ci),
        ret = ret,
    )
}

//! `crossroads reproduce`: the paper's tables and Figure 3, measured here.
//!
//! Three phases. Training: every experiment a requested part needs
//! (configs/experiments/, built in) becomes one `crossroads train` run
//! under `<out>/runs/<experiment>`, started as a child process with its own
//! progress bar; a finished run is reused and an interrupted one resumed.
//! Evaluation: TTC threshold sweeps (the lowest threshold with zero
//! collisions is the TTC cell, as in the paper) and the best weights of
//! each run, all on the same seeded trials. Report: Markdown and CSV with
//! the paper's numbers beside ours, figures, and what each run cost
//! (`report.rs`).

mod drivers;
pub mod paper;
mod report;
mod table;

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::Context;
use clap::Args;
use crossroads_common::Shutdown;
use crossroads_sim::{
    ActionSet, Env, EnvConfig, EvalConfig, EvalReport, Policy, Scenario, ShieldCounters,
    ShieldParams, ShieldStats, ShieldedPolicy, SweepPoint, TuneReport, default_thresholds,
    evaluate, tune_ttc,
};
use serde::Serialize;

use crate::child::{self, TrainingChild, TrainingExit};
use crate::experiments;
use crate::global::GlobalArgs;
use crate::network_policy::NetworkPolicy;
use crate::progress;
use crate::train::{Evaluation, Summary, read_curve};

/// `crossroads reproduce`.
#[derive(Debug, Clone, Args)]
pub struct ReproduceArgs {
    /// Report folder.
    #[arg(long, default_value = "report", value_name = "DIR")]
    pub out: PathBuf,
    /// Only these parts (repeat or comma-separate): table1, table2,
    /// table3, fig3, drivers [default: all].
    #[arg(long, value_delimiter = ',', value_name = "PART")]
    pub only: Vec<Part>,
    /// Wall-clock budget of each training run in minutes (on top of the
    /// experiment's update budget; 0: the update budget alone).
    #[arg(long, value_name = "MIN", default_value_t = 0.0)]
    pub budget: f64,
    /// Update budget of each training run (replaces the experiment's).
    #[arg(long, value_name = "N")]
    pub updates: Option<u64>,
    /// Actor processes per training run (actor.count).
    #[arg(long, value_name = "N")]
    pub actors: Option<u32>,
    /// Trials per table cell and per TTC threshold.
    #[arg(long, short = 'n', default_value_t = 10_000)]
    pub trials: u64,
    /// Base seed of the evaluations (every method sees the same trials).
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Leave out DQN-Sequential (its runs are the longest).
    #[arg(long)]
    pub no_sequential: bool,
    /// Only the baselines: the TTC cells and sweeps, without training or
    /// evaluating any network (the DQN cells stay empty). For re-measuring
    /// them after a change of the simulator, where the networks need
    /// retraining anyway.
    #[arg(long, conflicts_with = "quick")]
    pub baselines_only: bool,
    /// A minutes-long smoke version: tiny networks and budgets, 300 trials,
    /// no DQN-Sequential. The numbers mean nothing; the pipeline is real.
    #[arg(long)]
    pub quick: bool,
}

/// A part of `crossroads reproduce`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    /// Table I: TTC, DQN-Sequential and DQN-TTG on the five scenarios.
    Table1,
    /// Table II: occlusion, TTC with creep and the DQNs per wall length.
    Table2,
    /// Table III: DQN-TTG trained on one scenario, tested on each.
    Table3,
    /// Figure 3: TTC threshold sweeps with the DQN points.
    Fig3,
    /// Safety across drivers: every Table I scenario against the drivers'
    /// reaction time and the share of inattentive drivers (drivers/).
    Drivers,
}

/// Settings `--quick` adds to every run: a small network, short warm-up
/// and frequent small evaluations.
const QUICK_SETS: [&str; 7] = [
    "learner.trunk=mlp",
    "learner.hidden=[64,64]",
    "replay.min_size_to_sample=500",
    "train.eval_every=100",
    "train.eval_trials=100",
    "train.confirm_trials=200",
    "actor.envs=8",
];

/// Update budget of a `--quick` run.
const QUICK_UPDATES: u64 = 200;

/// Trials per cell with `--quick`.
const QUICK_TRIALS: u64 = 300;

/// What a reproduction does, from the flags.
#[derive(Debug, Clone)]
struct Plan {
    out: PathBuf,
    parts: Vec<Part>,
    sequential: bool,
    trials: u64,
    seed: u64,
    quick: bool,
    /// Train and evaluate the networks (not `--baselines-only`).
    dqn: bool,
    budget_minutes: f64,
    updates: Option<u64>,
    actors: Option<u32>,
    sets: Vec<String>,
}

impl Plan {
    fn new(global: &GlobalArgs, args: &ReproduceArgs) -> anyhow::Result<Self> {
        anyhow::ensure!(args.trials > 0, "--trials must be at least 1");
        anyhow::ensure!(
            args.budget.is_finite() && args.budget >= 0.0,
            "--budget must be minutes >= 0, not {}",
            args.budget
        );
        anyhow::ensure!(
            global.config.is_none() && global.experiment.is_none(),
            "reproduce runs the built-in experiments (configs/experiments/); \
             --config and --experiment (CROSSROADS_EXPERIMENT) apply to `crossroads train`, \
             use --set to change a key in every run"
        );
        let parts = if args.only.is_empty() {
            vec![
                Part::Table1,
                Part::Table2,
                Part::Table3,
                Part::Fig3,
                Part::Drivers,
            ]
        } else {
            let mut p = args.only.clone();
            p.sort_by_key(|p| *p as u8);
            p.dedup();
            p
        };
        let mut sets = global.sets.clone();
        if args.quick {
            sets.splice(0..0, QUICK_SETS.iter().map(|s| (*s).to_owned()));
        }
        Ok(Self {
            out: args.out.clone(),
            parts,
            sequential: !(args.no_sequential || args.quick || args.baselines_only),
            dqn: !args.baselines_only,
            trials: if args.quick {
                args.trials.min(QUICK_TRIALS)
            } else {
                args.trials
            },
            seed: args.seed,
            quick: args.quick,
            budget_minutes: args.budget,
            updates: args.updates.or(if args.quick {
                Some(QUICK_UPDATES)
            } else {
                None
            }),
            actors: args.actors,
            sets,
        })
    }

    fn wants(&self, part: Part) -> bool {
        self.parts.contains(&part)
    }

    /// The experiments to train, cheapest and most used first.
    fn experiments(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        if !self.dqn {
            return names;
        }
        let mut add = |n: String| {
            if !names.contains(&n) {
                names.push(n);
            }
        };
        let table1 = self.wants(Part::Table1);
        let fig3 = self.wants(Part::Fig3);
        if table1 || self.wants(Part::Table3) {
            paper::SCENARIOS
                .iter()
                .for_each(|s| add(format!("ttg-{s}")));
            if table1 {
                paper::SCENARIOS
                    .iter()
                    .for_each(|s| add(format!("ttg-{s}+shield")));
            }
        } else if fig3 {
            paper::FIG3_SCENARIOS
                .iter()
                .for_each(|s| add(format!("ttg-{s}")));
        }
        if self.wants(Part::Drivers) {
            drivers::experiments().for_each(&mut add);
        }
        if self.wants(Part::Table2) {
            add("creep-occluded".into());
            add("creep-occluded+shield".into());
            add("ttg-occluded".into());
        }
        if self.sequential {
            if table1 {
                paper::SCENARIOS
                    .iter()
                    .for_each(|s| add(format!("sequential-{s}")));
            } else if fig3 {
                paper::FIG3_SCENARIOS
                    .iter()
                    .for_each(|s| add(format!("sequential-{s}")));
            }
            if self.wants(Part::Table2) {
                add("sequential-occluded".into());
            }
        }
        names
    }

    /// Networks trained for `experiment` ([`experiments::members`]; one
    /// with `--quick`, which checks the pipeline, not the results).
    fn members(&self, experiment: &str) -> u32 {
        if self.quick {
            1
        } else {
            experiments::members(experiment)
        }
    }

    fn run_dir(&self, experiment: &str) -> PathBuf {
        self.out.join("runs").join(experiment)
    }

    /// TTC thresholds swept: 0 to 10 s by 0.25 s (creep: 2 to 6 s, where
    /// the occlusion family's zero-collision thresholds lie); coarser with
    /// `--quick`.
    fn thresholds(&self, creep: bool) -> Vec<f64> {
        match (creep, self.quick) {
            (false, false) => default_thresholds(),
            (false, true) => (0..=8).map(|i| f64::from(i) * 0.5).collect(),
            (true, false) => (8..=24).map(|i| f64::from(i) * 0.25).collect(),
            (true, true) => (4..=10).map(|i| f64::from(i) * 0.5).collect(),
        }
    }
}

/// One evaluated cell.
#[derive(Debug, Clone, Serialize)]
pub struct ReportCell {
    /// The policy (`ttc:1.5`, `dqn:best@v812`).
    pub policy: String,
    /// Trials run.
    pub trials: u64,
    /// Percent of trials.
    pub success: f64,
    /// Percent of trials.
    pub collision: f64,
    /// Percent of trials.
    pub timeout: f64,
    /// Mean time to goal of successful trials, s.
    pub time: Option<f64>,
    /// Mean brake-light time of traffic per trial by SUMO's rule, s
    /// (`brake` in results.json).
    #[serde(rename = "brake")]
    pub brake_light_s: f64,
    /// What the safety shield did, for a policy behind it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shield: Option<ShieldStats>,
}

impl ReportCell {
    fn of_report(r: &EvalReport) -> Self {
        Self {
            policy: r.policy.clone(),
            trials: r.trials,
            success: 100.0 * r.success_rate,
            collision: 100.0 * r.collision_rate,
            timeout: 100.0 * r.timeout_rate,
            time: r.mean_time_s,
            brake_light_s: r.mean_brake_light_s,
            shield: None,
        }
    }

    fn of_sweep(p: &SweepPoint, trials: u64) -> Self {
        Self {
            policy: format!("ttc:{}", p.threshold),
            trials,
            success: 100.0 * p.success_rate,
            collision: 100.0 * p.collision_rate,
            timeout: 100.0 * p.timeout_rate,
            time: p.mean_time_s,
            brake_light_s: p.mean_brake_light_s,
            shield: None,
        }
    }
}

/// Table I, one scenario: TTC (with its threshold), DQN-Sequential,
/// DQN-TTG, and DQN-TTG behind the safety shield (not in the paper).
#[derive(Debug, Clone, Default, Serialize)]
pub struct Table1Row {
    pub scenario: String,
    pub ttc_threshold: Option<f64>,
    pub ttc: Option<ReportCell>,
    pub sequential: Option<ReportCell>,
    pub ttg: Option<ReportCell>,
    pub shielded: Option<ReportCell>,
    /// The shield alone: [`SHIELD_ALONE`] behind it (not in the paper).
    pub shield_alone: Option<ReportCell>,
}

/// The shield alone of both tables: a policy that wants to go at every
/// decision, behind the shield, so the ego goes at the first moment the
/// shield allows and the shield's fallback (wait on Table I, creep to the
/// creep limit on Table II) acts until then.
pub const SHIELD_ALONE: &str = "go";

/// Table II, one occluder length.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Table2Row {
    pub length_m: u32,
    pub ttc_threshold: Option<f64>,
    pub ttc_creep: Option<ReportCell>,
    pub ttg: Option<ReportCell>,
    pub creep: Option<ReportCell>,
    pub sequential: Option<ReportCell>,
    /// DQN-Creep trained behind the safety shield (`creep-occluded+shield`)
    /// and evaluated behind it (not in the paper).
    pub shielded: Option<ReportCell>,
    /// The shield alone: [`SHIELD_ALONE`] behind it (not in the paper).
    pub shield_alone: Option<ReportCell>,
    /// The shield alone with walls that hide nothing (`see_through=1`):
    /// what the walls cost a shielded policy.
    pub see_through: Option<ReportCell>,
    /// The oracle ([`ORACLE`]): sees hidden cars and goes when going
    /// reaches the goal in every one of its futures; the top of the ladder.
    pub oracle: Option<ReportCell>,
}

/// The oracle of Table II's ladder: 16 futures per decision.
pub const ORACLE: &str = "oracle:16";

/// One training run and what it cost.
#[derive(Debug, Clone, Serialize)]
pub struct RunRecord {
    pub experiment: String,
    pub summary: Summary,
    #[serde(skip)]
    pub curve: Vec<Evaluation>,
}

/// Everything measured.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Results {
    pub trials: u64,
    pub seed: u64,
    pub quick: bool,
    /// `--baselines-only`: no network was trained or evaluated.
    pub baselines_only: bool,
    pub machine: String,
    pub table1: Vec<Table1Row>,
    pub table2: Vec<Table2Row>,
    /// Row = tested on, column = trained on, in [`paper::SCENARIOS`] order.
    pub table3: Vec<Vec<Option<ReportCell>>>,
    /// TTC sweeps by scenario (`left`, `occluded-60`, ...).
    pub sweeps: Vec<TuneReport>,
    pub runs: Vec<RunRecord>,
    pub started: String,
    /// Wall time of the whole call, training included.
    pub minutes: f64,
    /// The runs this call trained or resumed; the others were reused
    /// finished (their own training time is in their summaries).
    pub trained: Vec<String>,
}

/// Runs the reproduction.
pub fn run(global: &GlobalArgs, args: &ReproduceArgs) -> anyhow::Result<ExitCode> {
    let plan = Plan::new(global, args)?;
    let (_signals, shutdown) = child::on_signals()?;
    let start = std::time::Instant::now();
    std::fs::create_dir_all(plan.out.join("runs"))
        .with_context(|| format!("creating {}", plan.out.display()))?;
    check_mode(&plan)?;

    let names = plan.experiments();
    let runs: Vec<(String, u32)> = names
        .iter()
        .flat_map(|name| (1..=plan.members(name)).map(move |k| (name.clone(), k)))
        .collect();
    let mut trained = Vec::new();
    for (i, (name, k)) in runs.iter().enumerate() {
        let run = experiments::member_run(name, *k);
        eprintln!("[{}/{}] {run}", i + 1, runs.len());
        if train(&plan, name, *k, &shutdown)? {
            trained.push(run);
        }
    }

    let mut results = Results {
        trials: plan.trials,
        seed: plan.seed,
        quick: plan.quick,
        baselines_only: !plan.dqn,
        machine: crate::train::machine(),
        started: now_utc(),
        trained,
        ..Results::default()
    };
    evaluate_all(&plan, &mut results, &shutdown)?;
    for (name, k) in &runs {
        let run = experiments::member_run(name, *k);
        let dir = plan.run_dir(&run);
        let summary = Summary::load(&dir)?
            .with_context(|| format!("{} has no summary.json", dir.display()))?;
        let curve = read_curve(&dir.join("curve.csv")).unwrap_or_default();
        results.runs.push(RunRecord {
            experiment: run,
            summary,
            curve,
        });
    }
    let drivers = if plan.wants(Part::Drivers) {
        Some(drivers::evaluate(
            &plan,
            &shutdown,
            results.started.clone(),
        )?)
    } else {
        None
    };
    results.minutes = start.elapsed().as_secs_f64() / 60.0;
    let mut written = Vec::new();
    // `--only drivers` leaves the paper's report as it was.
    if plan.parts.iter().any(|&p| p != Part::Drivers) {
        written.extend(report::write(&plan.out, &plan, &results)?);
    }
    if let Some(d) = &drivers {
        written.extend(drivers::write(&plan.out.join("drivers"), d)?);
    }
    for path in written {
        eprintln!("wrote {}", path.display());
    }
    if !results.runs.is_empty() {
        eprintln!("{}", report::training_time(&results));
    }
    Ok(ExitCode::SUCCESS)
}

/// A report folder holds either `--quick` runs or full ones, never both:
/// reusing one kind for the other would report the wrong networks.
fn check_mode(plan: &Plan) -> anyhow::Result<()> {
    let path = plan.out.join("mode");
    let mode = if plan.quick { "quick" } else { "full" };
    match std::fs::read_to_string(&path) {
        Ok(old) if old.trim() != mode => anyhow::bail!(
            "{} holds a {} reproduction; this one is {mode}: choose another --out",
            plan.out.display(),
            old.trim()
        ),
        Ok(_) => Ok(()),
        Err(_) => std::fs::write(&path, format!("{mode}\n"))
            .with_context(|| format!("writing {}", path.display())),
    }
}

/// Trains member `member` (from 1) of `experiment` unless its run
/// finished (then `false`: reused); resumes an interrupted one. Members
/// after the first train from seed `member` (actor and learner). The
/// child is a [`TrainingChild`]: Ctrl-C stops it cleanly, and a later
/// reproduce resumes it.
fn train(plan: &Plan, experiment: &str, member: u32, shutdown: &Shutdown) -> anyhow::Result<bool> {
    let dir = plan.run_dir(&experiments::member_run(experiment, member));
    if let Some(s) = Summary::load(&dir)?
        && s.status.is_complete()
    {
        eprintln!(
            "  reusing {} ({}, {} updates, {:.1} min)",
            dir.display(),
            s.status,
            s.updates,
            s.wall_seconds / 60.0
        );
        return Ok(false);
    }
    let resume = dir
        .join("checkpoints")
        .read_dir()
        .is_ok_and(|mut d| d.next().is_some());
    let e = experiments::EXPERIMENTS
        .iter()
        .find(|e| e.name == experiment)
        .with_context(|| format!("no built-in experiment {experiment}"))?;
    let configs = plan.out.join("configs");
    std::fs::create_dir_all(&configs).with_context(|| format!("creating {}", configs.display()))?;
    let config = configs.join(format!("{experiment}.toml"));
    std::fs::write(&config, e.toml).with_context(|| format!("writing {}", config.display()))?;

    let mut args: Vec<OsString> = Vec::new();
    for set in &plan.sets {
        args.extend(["--set".into(), set.into()]);
    }
    if member > 1 {
        for key in ["actor.seed", "learner.seed"] {
            args.extend(["--set".into(), format!("{key}={member}").into()]);
        }
    }
    args.extend([
        "--config".into(),
        config.into(),
        "train".into(),
        "--out".into(),
        dir.clone().into(),
    ]);
    if plan.budget_minutes > 0.0 {
        args.extend(["--minutes".into(), plan.budget_minutes.to_string().into()]);
    }
    if let Some(n) = plan.updates {
        args.extend(["--updates".into(), n.to_string().into()]);
    }
    if let Some(n) = plan.actors {
        args.extend(["--actors".into(), n.to_string().into()]);
    }
    if resume {
        args.push("--resume".into());
        eprintln!("  resuming {}", dir.display());
    } else {
        eprintln!("  training into {}", dir.display());
    }
    match TrainingChild::start(&args, None)?.wait(shutdown)? {
        TrainingExit::Stopped(status) => anyhow::bail!(
            "stopped while training {experiment} ({status}); run the same command again to resume"
        ),
        TrainingExit::Exited(status) => anyhow::ensure!(
            status.success(),
            "training {experiment} failed ({status}); its logs are in {}",
            dir.join("logs").display()
        ),
    }
    Ok(true)
}

/// The TTC sweeps and every DQN cell the parts need.
fn evaluate_all(plan: &Plan, r: &mut Results, shutdown: &Shutdown) -> anyhow::Result<()> {
    let stop = || -> anyhow::Result<()> {
        anyhow::ensure!(!shutdown.is_triggered(), "stopped during the evaluations");
        Ok(())
    };
    // TTC sweeps: Table I and Figure 3 on the open scenarios, Table II on
    // the occlusion family with creeping.
    for &s in open_scenarios(plan) {
        stop()?;
        r.sweeps.push(sweep(plan, s, ActionSet::Ttg, false)?);
    }
    if plan.wants(Part::Table2) {
        for len in paper::OCCLUSION_LENGTHS {
            stop()?;
            r.sweeps.push(sweep(
                plan,
                &format!("occluded-{len}"),
                ActionSet::Creep,
                true,
            )?);
        }
    }

    let eval_run = |experiment: &str,
                    scenario: &str,
                    actions: ActionSet,
                    shield: bool|
     -> anyhow::Result<Option<ReportCell>> {
        stop()?;
        let dirs: Vec<PathBuf> = (1..=plan.members(experiment))
            .map(|k| plan.run_dir(&experiments::member_run(experiment, k)))
            .collect();
        if !plan.dqn || !dirs.iter().all(|d| d.exists()) {
            return Ok(None);
        }
        let shield = shield.then(ShieldParams::default);
        evaluate_network(plan, &dirs, &load_scenario(scenario)?, actions, shield)
    };
    let dqn = |experiment: &str, scenario: &str, actions: ActionSet| {
        eval_run(experiment, scenario, actions, false)
    };
    let shielded = |experiment: &str, scenario: &str, actions: ActionSet| {
        eval_run(experiment, scenario, actions, true)
    };
    // A baseline behind the shield (with the networks' columns).
    let shield_alone_under = |scenario: &str,
                              policy: &str,
                              actions: ActionSet,
                              params: ShieldParams|
     -> anyhow::Result<Option<ReportCell>> {
        stop()?;
        if !plan.dqn {
            return Ok(None);
        }
        let (policy, counters) = behind_shield(crossroads_sim::parse_policy(policy)?, params);
        let name = policy.name();
        let sc = load_scenario(scenario)?;
        evaluate_policy(plan, &name, &sc, actions, policy.as_ref(), counters).map(Some)
    };
    let shield_alone = |scenario: &str, actions: ActionSet| {
        shield_alone_under(scenario, SHIELD_ALONE, actions, ShieldParams::default())
    };
    // The top of Table II's ladder, on the same trials.
    let oracle = |scenario: &str| -> anyhow::Result<Option<ReportCell>> {
        stop()?;
        if !plan.dqn {
            return Ok(None);
        }
        let policy = crossroads_sim::parse_policy(ORACLE)?;
        let sc = load_scenario(scenario)?;
        evaluate_policy(plan, ORACLE, &sc, ActionSet::Creep, policy.as_ref(), None).map(Some)
    };
    // Table I's rows; Figure 3 plots the same cells.
    for &s in open_scenarios(plan) {
        {
            let ttc = r.sweeps.iter().find(|w| w.scenario == s && !w.creep);
            r.table1.push(Table1Row {
                scenario: s.to_owned(),
                ttc_threshold: ttc.and_then(|w| w.best.as_ref()).map(|b| b.threshold),
                ttc: ttc.and_then(|w| w.best.as_ref().map(|b| ReportCell::of_sweep(b, w.trials))),
                sequential: if plan.sequential {
                    dqn(&format!("sequential-{s}"), s, ActionSet::Sequential)?
                } else {
                    None
                },
                ttg: dqn(&format!("ttg-{s}"), s, ActionSet::Ttg)?,
                shielded: shielded(&format!("ttg-{s}+shield"), s, ActionSet::Ttg)?,
                shield_alone: shield_alone(s, ActionSet::Ttg)?,
            });
        }
    }
    if plan.wants(Part::Table2) {
        for len in paper::OCCLUSION_LENGTHS {
            let s = format!("occluded-{len}");
            let ttc = r.sweeps.iter().find(|w| w.scenario == s && w.creep);
            r.table2.push(Table2Row {
                length_m: len,
                ttc_threshold: ttc.and_then(|w| w.best.as_ref()).map(|b| b.threshold),
                ttc_creep: ttc
                    .and_then(|w| w.best.as_ref().map(|b| ReportCell::of_sweep(b, w.trials))),
                ttg: dqn("ttg-occluded", &s, ActionSet::Ttg)?,
                creep: dqn("creep-occluded", &s, ActionSet::Creep)?,
                sequential: if plan.sequential {
                    dqn("sequential-occluded", &s, ActionSet::Sequential)?
                } else {
                    None
                },
                shielded: shielded("creep-occluded+shield", &s, ActionSet::Creep)?,
                shield_alone: shield_alone(&s, ActionSet::Creep)?,
                see_through: shield_alone_under(
                    &s,
                    SHIELD_ALONE,
                    ActionSet::Creep,
                    ShieldParams {
                        see_through: true,
                        ..ShieldParams::default()
                    },
                )?,
                oracle: oracle(&s)?,
            });
        }
    }
    if plan.wants(Part::Table3) {
        for tested in paper::SCENARIOS {
            let mut row = Vec::new();
            for trained in paper::SCENARIOS {
                // The diagonal is Table I's DQN-TTG cell (same trials).
                let same = r
                    .table1
                    .iter()
                    .find(|row| row.scenario == tested && tested == trained)
                    .and_then(|row| row.ttg.clone());
                row.push(match same {
                    Some(cell) => Some(cell),
                    None => dqn(&format!("ttg-{trained}"), tested, ActionSet::Ttg)?,
                });
            }
            r.table3.push(row);
        }
    }
    Ok(())
}

/// The scenarios without occlusion that Table I or Figure 3 need.
fn open_scenarios(plan: &Plan) -> &'static [&'static str] {
    if plan.wants(Part::Table1) || plan.wants(Part::Table3) {
        &paper::SCENARIOS
    } else if plan.wants(Part::Fig3) {
        &paper::FIG3_SCENARIOS
    } else {
        &[]
    }
}

/// A TTC threshold sweep on `scenario` with `plan.trials` trials per
/// threshold.
fn sweep(
    plan: &Plan,
    scenario: &str,
    actions: ActionSet,
    creep: bool,
) -> anyhow::Result<TuneReport> {
    let sc = Arc::new(Scenario::load(scenario).with_context(|| format!("scenario {scenario}"))?);
    let thresholds = plan.thresholds(creep);
    let bar = progress::bar(plan.trials * thresholds.len() as u64, "trials");
    bar.set_message(format!(
        "TTC{} sweep on {scenario}",
        if creep { " with creep" } else { "" }
    ));
    let report = tune_ttc(
        &sc,
        actions,
        creep,
        &thresholds,
        plan.trials,
        plan.seed,
        &|n| bar.inc(n),
    )?;
    bar.finish_and_clear();
    eprintln!(
        "  TTC{} on {scenario}: {}",
        if creep { " with creep" } else { "" },
        report
            .best
            .as_ref()
            .map_or("no threshold without collisions".to_owned(), |b| format!(
                "{:.2} s, {:.2} % success, {}",
                b.threshold,
                100.0 * b.success_rate,
                b.mean_time_s
                    .map_or("-".to_owned(), |t| format!("{t:.2} s"))
            ))
    );
    Ok(report)
}

/// The best weights of the runs in `dirs` (one, or an experiment's
/// ensemble) on `sc`, behind the safety shield with assumptions `shield`
/// when given; `None` when the network cannot read that scenario's
/// observations (transfer across different grids).
fn evaluate_network(
    plan: &Plan,
    dirs: &[PathBuf],
    sc: &Arc<Scenario>,
    actions: ActionSet,
    shield: Option<ShieldParams>,
) -> anyhow::Result<Option<ReportCell>> {
    let best: Vec<PathBuf> = dirs.iter().map(|d| d.join("best")).collect();
    let network = NetworkPolicy::load_members(&best)?;
    let dir = &dirs[0];
    if let Err(e) = network.fits(&Env::new(Arc::clone(sc), EnvConfig::for_actions(actions))) {
        eprintln!("  {} on {}: skipped, {e:#}", dir.display(), sc.name());
        return Ok(None);
    }
    let (policy, counters): (Box<dyn Policy>, _) = match shield {
        Some(params) => behind_shield(Box::new(network), params),
        None => (Box::new(network), None),
    };
    let name = dir
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned())
        + if shield.is_some() { " + shield" } else { "" };
    evaluate_policy(plan, &name, sc, actions, policy.as_ref(), counters).map(Some)
}

fn load_scenario(scenario: &str) -> anyhow::Result<Arc<Scenario>> {
    Ok(Arc::new(
        Scenario::load(scenario).with_context(|| format!("scenario {scenario}"))?,
    ))
}

/// `policy` behind the safety shield with assumptions `params`, and the
/// shield's counters.
fn behind_shield(
    policy: Box<dyn Policy>,
    params: ShieldParams,
) -> (Box<dyn Policy>, Option<Arc<ShieldCounters>>) {
    let shielded = ShieldedPolicy::new(policy, params);
    let counters = shielded.counters();
    (Box::new(shielded), Some(counters))
}

/// `policy` (called `name` in the log) on `plan.trials` trials of `sc`.
fn evaluate_policy(
    plan: &Plan,
    name: &str,
    sc: &Arc<Scenario>,
    actions: ActionSet,
    policy: &dyn Policy,
    counters: Option<Arc<ShieldCounters>>,
) -> anyhow::Result<ReportCell> {
    let scenario = sc.name();
    let bar = progress::bar(plan.trials, "trials");
    bar.set_message(format!("{name} on {scenario}"));
    let report = evaluate(
        sc,
        policy,
        &EvalConfig::new(actions, plan.trials, plan.seed),
        &|n| bar.inc(n),
    )?;
    bar.finish_and_clear();
    let cell = ReportCell {
        shield: counters.map(|c| c.stats()),
        ..ReportCell::of_report(&report)
    };
    eprintln!(
        "  {name} on {scenario}: {:.2} % success, {:.2} % collisions, {}",
        cell.success,
        cell.collision,
        cell.time.map_or("-".to_owned(), |t| format!("{t:.2} s"))
    );
    Ok(cell)
}

/// The current time, e.g. `Tue, 24 Nov 2026 04:30:00 GMT`.
fn now_utc() -> String {
    httpdate::fmt_http_date(std::time::SystemTime::now())
}

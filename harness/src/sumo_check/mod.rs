//! `crossroads sumo-check`: our simulator against SUMO on the same
//! scenarios with the same policies.
//!
//! For each scenario it exports the compiled scenario
//! ([`crossroads_sim::ScenarioExport`]) as JSON, runs
//! `scripts/sumo_check/check.py` on it (SUMO's network generated from the
//! export by netconvert, the ego driven over libsumo by the same TTC rule,
//! random and never-go policies), evaluates the same policies on our
//! simulator, and compares every metric cell by cell with intervals
//! ([`compare`]). The report ([`report`]) goes into `--out`.

mod compare;
mod report;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::sync::Arc;

use anyhow::{Context, bail, ensure};
use clap::Args;
use crossroads_sim::{
    ActionSet, DriverPopulation, EvalConfig, EvalReport, Outcome, PolicySpec, Scenario,
    TrialResult, evaluate, summarize,
};
use serde::Deserialize;

use crate::progress;

pub use compare::{SumoCell, Verdict};

/// `crossroads sumo-check`.
#[derive(Debug, Args)]
pub struct SumoCheckArgs {
    /// Comma-separated scenarios [default: right, left, left2, forward,
    /// challenge, occluded-30, occluded-60, occluded-90; with --quick left,
    /// challenge].
    #[arg(long)]
    pub scenarios: Option<String>,
    /// TTC thresholds in seconds, start:end:step or a list [default: 0.5,
    /// 1, 1.25, 1.5, 1.75, 2, 2.5, 3, 4 s; with creep 2.5, 3, 3.25, 3.5,
    /// 4 s; with --quick 1.5, 2, 3 s].
    #[arg(long)]
    pub thresholds: Option<String>,
    /// Trials per policy and scenario, in each simulator.
    #[arg(long, short = 'n', default_value_t = 1_000)]
    pub trials: u64,
    /// Base seed (ours: trial seeds; SUMO: its --seed, plus the policy's
    /// position in the list).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Comma-separated driver populations, each a preset (sumo, human, mixed) or
    /// a drivers TOML file; every scenario runs under each, SUMO drawing
    /// each car's vehicle type from the same bounds (docs/drivers.md gives
    /// the mapping) [default: sumo,human].
    #[arg(long)]
    pub drivers: Option<String>,
    /// A small check (what make test runs): left and challenge, three
    /// thresholds and never-go, 300 trials, under each population.
    #[arg(long)]
    pub quick: bool,
    /// Exit with status 1 when a gated cell drifts (success, collision or
    /// time of a TTC policy outside the 99 % interval of the difference).
    #[arg(long)]
    pub strict: bool,
    /// SUMO processes at a time (one scenario each).
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// Python with SUMO [default: $CROSSROADS_PYTHON, else .venv/bin/python3,
    /// else python3].
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// The SUMO driver [default: scripts/sumo_check/check.py].
    #[arg(long)]
    pub script: Option<PathBuf>,
    /// Folder for the report.
    #[arg(long, default_value = "reports/sumo")]
    pub out: PathBuf,
    /// Keep the working files here: each scenario's export (JSON), its SUMO
    /// network and routes, and SUMO's trials (JSON lines) [default: a
    /// temporary folder, removed at the end].
    #[arg(long)]
    pub work: Option<PathBuf>,
}

/// Scenarios of the full check: every scenario of Tables I and II.
pub const FULL_SCENARIOS: &[&str] = &[
    "right",
    "left",
    "left2",
    "forward",
    "challenge",
    "occluded-30",
    "occluded-60",
    "occluded-90",
];
/// Scenarios of `--quick`.
pub const QUICK_SCENARIOS: &[&str] = &["left", "challenge"];
/// TTC thresholds of the full check on the open scenarios, s.
pub const OPEN_THRESHOLDS: &[f64] = &[0.5, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0];
/// TTC-with-creep thresholds of the full check on the occlusion family, s.
pub const CREEP_THRESHOLDS: &[f64] = &[2.5, 3.0, 3.25, 3.5, 4.0];
/// Driver populations of a check unless `--drivers` says otherwise.
pub const DEFAULT_DRIVERS: &str = "sumo,human";
/// Thresholds of `--quick`, s.
pub const QUICK_THRESHOLDS: &[f64] = &[1.5, 2.0, 3.0];

/// One scenario of a check: what runs on it.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Scenario name (`<name>-empty` for the empty-road drive of an open
    /// scenario).
    pub scenario: String,
    /// The compiled scenario.
    pub compiled: Arc<Scenario>,
    /// Trials per policy.
    pub trials: u64,
    /// Action set of its policies (Creep-and-Go with occluders, else TTG).
    pub actions: ActionSet,
    /// Policies, TTC ones by ascending threshold first.
    pub policies: Vec<PolicySpec>,
    /// Whether `--strict` gates its TTC cells: SUMO drives these drivers as
    /// ours do (the scenario's own). A population SUMO can only approximate
    /// (a reaction time as its `actionStepLength`) is compared, not gated.
    pub gated: bool,
}

/// Trials of every policy of every plan (one simulator's share of a check).
fn total_trials(plans: &[Plan]) -> u64 {
    plans
        .iter()
        .map(|p| p.policies.len() as u64 * p.trials)
        .sum()
}

/// One SUMO trial as `check.py` writes it.
#[derive(Debug, Deserialize)]
struct SumoTrial {
    policy: String,
    outcome: Outcome,
    time_s: f64,
    brake_s: f64,
    wait_s: Option<f64>,
    overlap: bool,
}

/// Both simulators' reports for one policy on one scenario.
#[derive(Debug, Clone)]
pub struct Pair {
    /// Policy.
    pub policy: PolicySpec,
    /// Ours.
    pub ours: EvalReport,
    /// SUMO's.
    pub sumo: EvalReport,
    /// SUMO collisions that our overlap test of SUMO's positions did not
    /// see, and overlaps SUMO did not call a collision.
    pub collision_disagreements: u64,
}

/// Runs the check and writes the report; with `--strict`, exits 1 when a
/// gated cell drifts.
pub fn run(args: &SumoCheckArgs) -> anyhow::Result<ExitCode> {
    let trials = if args.quick { 300 } else { args.trials };
    ensure!(trials > 0, "--trials must be at least 1");
    let plans = plans(args, trials)?;
    let python = python(args.python.as_deref());
    let script = args.script.clone().unwrap_or_else(|| PathBuf::from(SCRIPT));
    ensure!(
        script.exists(),
        "{} not found: run from the repository root or pass --script",
        script.display()
    );
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let work = work_dir(args.work.as_deref())?;

    // Ours first: quick, and it catches a bad scenario before SUMO starts.
    let bar = progress::bar(total_trials(&plans), "trials");
    bar.set_message("ours");
    let mut ours: BTreeMap<String, Vec<EvalReport>> = BTreeMap::new();
    for plan in &plans {
        let config = EvalConfig::new(plan.actions, plan.trials, args.seed);
        let mut reports = Vec::new();
        for policy in &plan.policies {
            let r = evaluate(&plan.compiled, policy.build().as_ref(), &config, &|n| {
                bar.inc(n)
            })?;
            reports.push(r);
        }
        ours.insert(plan.scenario.clone(), reports);
    }
    bar.finish_and_clear();

    let (sumo_version, sumo) = run_sumo(args, &plans, &python, &script, work.path())?;
    let mut pairs: BTreeMap<String, Vec<Pair>> = BTreeMap::new();
    for plan in &plans {
        let rows = &sumo[&plan.scenario];
        let trials = plan.trials;
        let config = EvalConfig::new(plan.actions, trials, args.seed);
        let mut list = Vec::new();
        for (policy, ours) in plan.policies.iter().zip(&ours[&plan.scenario]) {
            let name = policy.to_string();
            let mine: Vec<&SumoTrial> = rows.iter().filter(|r| r.policy == name).collect();
            ensure!(
                mine.len() as u64 == trials,
                "SUMO returned {} trials of {name} on {}, expected {trials}",
                mine.len(),
                plan.scenario
            );
            let results: Vec<TrialResult> =
                mine.iter()
                    .map(|r| TrialResult {
                        outcome: r.outcome,
                        time_s: r.time_s,
                        // SUMO has no intended deceleration to read; its brake
                        // light is the one braking measure both have.
                        brake_s: r.brake_s,
                        brake_light_s: r.brake_s,
                        wait_s: r.wait_s,
                        go_state: None,
                        episode_return: plan.compiled.spec().rewards.episode_return(
                            r.outcome,
                            (r.time_s / plan.compiled.dt()).round() as u32,
                        ),
                    })
                    .collect();
            let disagreements = mine
                .iter()
                .filter(|r| (r.outcome == Outcome::Collision) != r.overlap)
                .count() as u64;
            list.push(Pair {
                policy: *policy,
                ours: ours.clone(),
                sumo: summarize(&plan.scenario, &name, &config, &results),
                collision_disagreements: disagreements,
            });
        }
        pairs.insert(plan.scenario.clone(), list);
    }

    let cells = compare::cells(&pairs, &plans);
    let meta = report::Meta {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        sumo_version,
        machine: crate::train::machine(),
        trials,
        seed: args.seed,
    };
    let written = report::write(&args.out, &meta, &plans, &pairs, &cells)?;
    let drifts: Vec<&SumoCell> = cells
        .iter()
        .filter(|c| c.gated && c.verdict == Verdict::Drifts)
        .collect();
    let differs = cells
        .iter()
        .filter(|c| c.verdict != Verdict::Agrees)
        .count();
    println!(
        "{} cells compared: {} agree, {differs} differ at 95 %, {} gated cells drift at 99 %",
        cells.len(),
        cells.len() - differs,
        drifts.len()
    );
    for c in &drifts {
        println!("  drift: {}", c.describe());
    }
    println!("wrote {}", written.display());
    if args.strict && !drifts.is_empty() {
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// Where the SUMO driver lives, relative to the repository root.
const SCRIPT: &str = "scripts/sumo_check/check.py";

/// Trials of an empty-road drive (deterministic in both simulators).
const EMPTY_TRIALS: u64 = 10;

/// The scenarios and policies of this check: for each scenario under each
/// driver population the TTC rule over the thresholds (with creep where
/// occluders hide traffic), random (not with `--quick`) and never-go, and
/// for each open scenario its empty-road drive (`ttc:0` without traffic:
/// the time the turn takes).
pub fn plans(args: &SumoCheckArgs, trials: u64) -> anyhow::Result<Vec<Plan>> {
    let names: Vec<String> = match &args.scenarios {
        Some(list) => list
            .split(',')
            .map(|s| s.trim().to_owned())
            .filter(|s| !s.is_empty())
            .collect(),
        None if args.quick => QUICK_SCENARIOS.iter().map(|s| (*s).to_owned()).collect(),
        None => FULL_SCENARIOS.iter().map(|s| (*s).to_owned()).collect(),
    };
    ensure!(!names.is_empty(), "--scenarios is empty");
    let populations = populations(args.drivers.as_deref())?;
    let mut plans = Vec::with_capacity(names.len() * populations.len());
    for (label, drivers) in &populations {
        for name in &names {
            let base = Scenario::load(name).with_context(|| format!("scenario {name:?}"))?;
            let scenario = match label {
                None => base,
                Some(label) => {
                    let mut spec = base.spec().clone();
                    spec.name = format!("{}+{label}", spec.name);
                    spec.drivers = drivers.clone();
                    Scenario::compile(spec)?
                }
            };
            plans.extend(plans_of(args, Arc::new(scenario), label.is_none(), trials)?);
        }
    }
    Ok(plans)
}

/// `--drivers` as (label, population): no label for `sumo` (the scenario's
/// own drivers, its plans named as the scenario), else the preset's name or
/// the file's stem.
fn populations(list: Option<&str>) -> anyhow::Result<Vec<(Option<String>, DriverPopulation)>> {
    let list = list.unwrap_or(DEFAULT_DRIVERS);
    let mut out: Vec<(Option<String>, DriverPopulation)> = Vec::new();
    for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let population = DriverPopulation::load(item).context("--drivers")?;
        let label = (item != "sumo").then(|| {
            Path::new(item)
                .file_stem()
                .map_or(item.to_owned(), |s| s.to_string_lossy().into_owned())
        });
        ensure!(
            out.iter().all(|(l, _)| *l != label),
            "--drivers names {item:?} twice"
        );
        out.push((label, population));
    }
    ensure!(!out.is_empty(), "--drivers is empty");
    Ok(out)
}

/// One scenario's plans under one population: its TTC thresholds, random
/// and never-go, and (for the scenario's own drivers) the empty-road drive.
fn plans_of(
    args: &SumoCheckArgs,
    scenario: Arc<Scenario>,
    own_drivers: bool,
    trials: u64,
) -> anyhow::Result<Vec<Plan>> {
    let mut plans = Vec::new();
    let spec = scenario.spec();
    let occluded = spec.occlusion.is_some() || !spec.obstacles.is_empty();
    let actions = if occluded {
        ActionSet::Creep
    } else {
        ActionSet::Ttg
    };
    let thresholds: Vec<f64> = match &args.thresholds {
        Some(t) => super::tune_ttc::parse_thresholds(t).context("--thresholds")?,
        None if args.quick => QUICK_THRESHOLDS.to_vec(),
        None if occluded => CREEP_THRESHOLDS.to_vec(),
        None => OPEN_THRESHOLDS.to_vec(),
    };
    let mut policies: Vec<PolicySpec> = thresholds
        .iter()
        .map(|&t| {
            if occluded {
                PolicySpec::TtcCreep(t)
            } else {
                PolicySpec::Ttc(t)
            }
        })
        .collect();
    if !args.quick {
        policies.push(PolicySpec::Random);
    }
    policies.push(PolicySpec::Never);
    if !occluded && own_drivers {
        let mut empty = spec.clone();
        empty.name = format!("{}-empty", spec.name);
        empty.emission_per_s = 0.0;
        empty
            .lanes
            .iter_mut()
            .for_each(|l| l.emission_per_s = Some(0.0));
        plans.push(Plan {
            scenario: empty.name.clone(),
            compiled: Arc::new(Scenario::compile(empty)?),
            trials: EMPTY_TRIALS.min(trials),
            actions,
            policies: vec![PolicySpec::Ttc(0.0)],
            gated: true,
        });
    }
    plans.push(Plan {
        scenario: scenario.name().to_owned(),
        compiled: scenario,
        trials,
        actions,
        policies,
        gated: own_drivers,
    });
    Ok(plans)
}

/// `--python`, else `CROSSROADS_PYTHON`, else the repository's `.venv`,
/// else `python3`.
fn python(arg: Option<&Path>) -> PathBuf {
    if let Some(p) = arg {
        return p.to_owned();
    }
    if let Some(p) = std::env::var_os("CROSSROADS_PYTHON") {
        return PathBuf::from(p);
    }
    let venv = PathBuf::from(".venv/bin/python3");
    if venv.exists() {
        return venv;
    }
    PathBuf::from("python3")
}

/// `--work`, kept, or a temporary folder removed on drop.
fn work_dir(keep: Option<&Path>) -> anyhow::Result<WorkDir> {
    let (path, remove) = match keep {
        Some(p) => (p.to_owned(), false),
        None => (
            std::env::temp_dir().join(format!("crossroads-sumo-check-{}", std::process::id())),
            true,
        ),
    };
    std::fs::create_dir_all(&path).with_context(|| format!("creating {}", path.display()))?;
    Ok(WorkDir { path, remove })
}

/// The working folder.
struct WorkDir {
    path: PathBuf,
    remove: bool,
}

impl WorkDir {
    fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for WorkDir {
    fn drop(&mut self) {
        if self.remove {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

/// Runs SUMO on every plan, `--jobs` processes at a time, with one
/// progress bar over all SUMO trials; returns each scenario's trials.
fn run_sumo(
    args: &SumoCheckArgs,
    plans: &[Plan],
    python: &Path,
    script: &Path,
    work: &Path,
) -> anyhow::Result<(String, BTreeMap<String, Vec<SumoTrial>>)> {
    let bar = progress::bar(total_trials(plans), "SUMO trials");
    bar.set_message("SUMO");
    let jobs = args.jobs.max(1);
    // Popped from the back: the longest runs (60 s occlusion episodes,
    // most policies) first, so the jobs end together.
    let mut order: Vec<&Plan> = plans.iter().collect();
    order.sort_by_key(|p| {
        p.trials * p.policies.len() as u64 * u64::from(p.compiled.spec().step_limit)
    });
    let queue = std::sync::Mutex::new(order);
    let results = std::sync::Mutex::new(BTreeMap::new());
    std::thread::scope(|s| -> anyhow::Result<()> {
        let handles: Vec<_> = (0..jobs)
            .map(|_| {
                s.spawn(|| -> anyhow::Result<()> {
                    loop {
                        let Some(plan) = queue.lock().map_err(|_| poisoned())?.pop() else {
                            return Ok(());
                        };
                        let run = run_one(args, plan, python, script, work, &bar)
                            .with_context(|| format!("SUMO on {}", plan.scenario))?;
                        results
                            .lock()
                            .map_err(|_| poisoned())?
                            .insert(plan.scenario.clone(), run);
                    }
                })
            })
            .collect();
        for h in handles {
            match h.join() {
                Ok(r) => r?,
                Err(_) => bail!("a SUMO worker thread panicked"),
            }
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    let runs: BTreeMap<String, SumoRun> = results.into_inner().map_err(|_| poisoned())?;
    let version = runs
        .values()
        .map(|r| r.version.clone())
        .next()
        .unwrap_or_default();
    Ok((
        version,
        runs.into_iter().map(|(k, r)| (k, r.rows)).collect(),
    ))
}

/// What one SUMO driver process returned.
struct SumoRun {
    version: String,
    rows: Vec<SumoTrial>,
}

fn poisoned() -> anyhow::Error {
    anyhow::anyhow!("a SUMO worker failed while holding the queue")
}

fn run_one(
    args: &SumoCheckArgs,
    plan: &Plan,
    python: &Path,
    script: &Path,
    work: &Path,
    bar: &indicatif::ProgressBar,
) -> anyhow::Result<SumoRun> {
    let export = plan.compiled.export()?;
    let export_path = work.join(format!("{}.json", plan.scenario));
    std::fs::write(&export_path, serde_json::to_vec_pretty(&export)?)
        .with_context(|| format!("writing {}", export_path.display()))?;
    let out = work.join(format!("{}.jsonl", plan.scenario));
    let net_dir = work.join(&plan.scenario);
    let policies: Vec<String> = plan.policies.iter().map(ToString::to_string).collect();
    let mut child = Command::new(python)
        .arg(script)
        .arg("--export")
        .arg(&export_path)
        .arg("--policies")
        .arg(policies.join(","))
        .arg("--actions")
        .arg(plan.actions.name())
        .arg("--trials")
        .arg(plan.trials.to_string())
        .arg("--seed")
        .arg(args.seed.to_string())
        .arg("--out")
        .arg(&out)
        .arg("--workdir")
        .arg(&net_dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| {
            format!(
                "starting {} (scripts/setup-python.sh --sumo installs SUMO into .venv)",
                python.display()
            )
        })?;
    let stderr = child.stderr.take();
    let err_reader = std::thread::spawn(move || {
        let mut text = String::new();
        if let Some(mut e) = stderr {
            let _ = std::io::Read::read_to_string(&mut e, &mut text);
        }
        text
    });
    let mut last = 0;
    let mut version = String::new();
    if let Some(stdout) = child.stdout.take() {
        for line in BufReader::new(stdout).lines() {
            let line = line.context("reading the SUMO driver's output")?;
            if let Some(v) = line.strip_prefix("version ") {
                v.clone_into(&mut version);
            }
            if let Some(done) = line
                .strip_prefix("progress ")
                .and_then(|r| r.split_whitespace().next())
                .and_then(|d| d.parse::<u64>().ok())
            {
                bar.inc(done.saturating_sub(last));
                last = done;
            }
        }
    }
    let status = child.wait().context("waiting for the SUMO driver")?;
    let stderr = err_reader.join().unwrap_or_default();
    ensure!(
        status.success(),
        "{} {} failed ({status}): {}",
        python.display(),
        script.display(),
        stderr.trim()
    );
    let text =
        std::fs::read_to_string(&out).with_context(|| format!("reading {}", out.display()))?;
    let rows = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{} line {}: not a SUMO trial", out.display(), i + 1))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(SumoRun { version, rows })
}

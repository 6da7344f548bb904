//! The command-line interface, as clap derives it.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use crossroads_config::ConfigLoader;
use crossroads_sim::ActionSet;

/// Learns to drive through unsignalized and occluded intersections with
/// distributed deep reinforcement learning (actors, prioritized replay, a
/// dueling double DQN learner).
#[derive(Debug, Parser)]
#[command(name = "crossroads", version, propagate_version = true)]
pub struct Cli {
    #[command(flatten)]
    pub global: GlobalArgs,
    #[command(subcommand)]
    pub command: Command,
}

/// Options every subcommand takes: where the configuration comes from.
#[derive(Debug, Clone, Args)]
pub struct GlobalArgs {
    /// TOML configuration file (one file describes a whole run; every role
    /// reads it). Environment variables CROSSROADS_<SECTION>__<KEY> override
    /// it, and --set overrides both.
    #[arg(
        long,
        short = 'c',
        global = true,
        env = "CROSSROADS_CONFIG",
        value_name = "FILE"
    )]
    pub config: Option<PathBuf>,

    /// Start from a built-in experiment of configs/experiments/ (ttg-left,
    /// sequential-right, ...): its settings lie under the file, the
    /// environment and --set. How a container of a scaled run picks the
    /// paper's tuned settings without a file.
    #[arg(
        long,
        global = true,
        env = "CROSSROADS_EXPERIMENT",
        value_name = "NAME",
        value_parser = experiment_name
    )]
    pub experiment: Option<String>,

    /// Override one configuration key, e.g. --set runtime.worker_threads=4.
    /// Repeatable; applied after the file and the environment.
    #[arg(long = "set", short = 's', global = true, value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

/// Every `--set KEY=VALUE` (also `--set=KEY=VALUE` and `-s KEY=VALUE`) of
/// a command line, in order, wherever it stands: clap keeps only the group
/// after the subcommand when a global flag appears on both sides of it.
/// Stops at `--`.
pub fn every_set(args: impl IntoIterator<Item = std::ffi::OsString>) -> Vec<String> {
    let mut sets = Vec::new();
    let mut args = args.into_iter().map(|a| a.to_string_lossy().into_owned());
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--" => break,
            "--set" | "-s" => sets.extend(args.next()),
            _ => {
                if let Some(v) = arg.strip_prefix("--set=") {
                    sets.push(v.to_owned());
                }
            }
        }
    }
    sets
}

impl GlobalArgs {
    /// The configuration layers these options describe.
    pub fn loader(&self) -> ConfigLoader {
        let mut loader = ConfigLoader::new();
        if let Some(e) = self
            .experiment
            .as_deref()
            .and_then(crate::experiments::named)
        {
            loader = loader.base(format!("built-in experiment {}", e.name), e.toml);
        }
        loader
            .file(self.config.as_ref())
            .sets(self.sets.iter().cloned())
    }
}

/// A built-in experiment's name, or an error listing them.
fn experiment_name(name: &str) -> Result<String, String> {
    match crate::experiments::named(name) {
        Some(e) => Ok(e.name.to_owned()),
        None => Err(format!(
            "no built-in experiment {name:?}; there are {}",
            crate::experiments::EXPERIMENTS
                .iter()
                .map(|e| e.name)
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Show the effective configuration, or check that it is valid.
    Config(ConfigArgs),
    /// Check this machine: libtorch, threads, and a timed forward pass.
    Doctor(DoctorArgs),
    /// Check that a role on this host is alive: GET /healthz on its
    /// metrics address (telemetry.metrics_addr, 0.0.0.0 read as
    /// 127.0.0.1); exit status 0 when it answers. For container health
    /// checks.
    Health(HealthArgs),
    /// Evaluate a policy on a scenario over seeded trials: success,
    /// collision and timeout rates, mean time and braking, with 95 %
    /// intervals.
    Eval(EvalArgs),
    /// Sweep TTC thresholds on a scenario and find the lowest one with zero
    /// collisions (the paper's tuning rule); CSV and PNG with --out.
    TuneTtc(TuneTtcArgs),
    /// Check our simulator against SUMO: the same scenarios (SUMO's network
    /// generated from ours), the same policies (TTC over thresholds, TTC
    /// with creep on the occlusion family, random, never-go), the same
    /// metrics, compared cell by cell with intervals.
    ///
    /// Needs SUMO in Python (scripts/setup-python.sh --sumo puts the
    /// eclipse-sumo and libsumo wheels into .venv) and runs from the
    /// repository root (scripts/sumo_check/). Writes into --out: README.md
    /// (ours beside SUMO per scenario, the tuned thresholds, the drifts),
    /// cells.csv, results.json, ttc-curves.png and success.png.
    SumoCheck(SumoCheckArgs),
    /// Draw one episode of a policy on a scenario: an animated GIF of the
    /// whole episode, or a PNG/SVG of one moment.
    ///
    /// Roads, obstacles (gray), cars the ego sees (green), cars hidden from
    /// it (yellow), braking cars (red outline), the ego (blue), and with
    /// --grid the observation grid (occupied cells blue, occluded cells
    /// dark).
    Render(RenderArgs),
    /// Run the prioritized replay server.
    ///
    /// Actors insert batches over gRPC (any host) or iceoryx2 shared memory
    /// (this host); the learner samples and updates priorities over gRPC.
    /// Configured by the [replay] and [transport] sections, the environment
    /// and the flags below; stops on SIGINT/SIGTERM after a last snapshot.
    Replay(ReplayArgs),
    /// Measure throughput and memory on this machine and print the figures.
    Bench(BenchArgs),
    /// Run the learner: dueling double DQN trained from the replay server.
    ///
    /// Samples batches over gRPC (prefetched in the background), trains,
    /// sends priority updates, publishes versioned weights (iceoryx2 on this
    /// host, a gRPC stream for any host) and keeps checkpoints. Configured
    /// by the [learner] and [transport] sections, the environment and the
    /// flags below; stops on SIGINT/SIGTERM after a last checkpoint.
    Learner(LearnerArgs),
    /// Manage the learner's checkpoints over its gRPC API: list, pull,
    /// save, restore, delete.
    Checkpoints(CheckpointsArgs),
    /// Run an actor: M simulators stepped in parallel, one batched forward
    /// pass per step, n-step transitions pushed to the replay server.
    ///
    /// Explores with the Ape-X epsilon ladder over every environment of
    /// every actor, from its index, the actor count and its environments
    /// (or acts greedily with --eval, pushing nothing and reporting
    /// episodes to the metrics and outcome rates to the log); pushes over gRPC (any host) or
    /// iceoryx2 (the replay's host); follows the learner's weights and acts
    /// on the last ones while the learner is unreachable. Configured by the
    /// [actor] and [transport] sections (the first network by [learner]),
    /// the environment and the flags below; stops on SIGINT/SIGTERM after
    /// delivering what it buffered.
    Actor(ActorArgs),
    /// Train on this machine: the replay, the learner and N actors as
    /// separate processes over the local transport, with a progress bar,
    /// greedy evaluations, checkpoints and a learning curve.
    ///
    /// Writes runs/<actions>-<scenario>/ (or --out): config.toml, logs/,
    /// checkpoints/, replay/ (snapshot), curve.csv and curve.png (greedy
    /// success, collisions and timeouts over time), best/ (the best
    /// evaluated weights, usable as `eval --policy`), summary.json. Serves
    /// crossroads_train_* on telemetry.metrics_addr. Ctrl-C stops cleanly
    /// with a last checkpoint; --resume continues. The [train] section sets
    /// actors, evaluations, budget and target.
    Train(TrainArgs),
    /// Reproduce the paper's tables and Figure 3: train what is missing
    /// (reusing finished runs), evaluate every cell on 10,000 trials, and
    /// write Markdown and CSV tables next to the paper's numbers, figures
    /// and learning curves.
    ///
    /// Writes into --out: README.md (the report), table1.csv, table2.csv,
    /// table3.csv, fig3.png (TTC threshold sweeps with the DQN points),
    /// curves.png (learning curves), training.csv (time and environment
    /// steps of each run), results.json (every number, the TTC sweeps
    /// included), mode (quick or full: a folder holds one kind), configs/
    /// and runs/ (one `crossroads train` run per experiment of
    /// configs/experiments/). A run that finished is reused; one that was
    /// interrupted resumes.
    Reproduce(ReproduceArgs),
    /// Regenerate the documents made from the code and the committed
    /// report: docs/reference/cli.md (this command line),
    /// docs/reference/config.md (the configuration schema and defaults)
    /// and the results block of README.md (from
    /// reports/paper/results.json).
    ///
    /// Run it from the repository root after changing a flag, a config key
    /// or the report; `--check` only compares, and exits 1 naming each
    /// document that differs.
    Docs(DocsArgs),
}

/// `crossroads docs`.
#[derive(Debug, Clone, Args)]
pub struct DocsArgs {
    /// Compare only: exit 1 when a generated document differs.
    #[arg(long)]
    pub check: bool,
    /// The repository's root folder.
    #[arg(long, default_value = ".", value_name = "DIR")]
    pub root: PathBuf,
}

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

/// `crossroads train`. Each flag overrides the configuration key it names.
#[derive(Debug, Clone, Args)]
pub struct TrainArgs {
    /// Scenario (sim.scenario).
    #[arg(long, value_name = "NAME|FILE")]
    pub scenario: Option<String>,
    /// Action set: ttg, sequential or creep (sim.action_set; the
    /// observation and the network follow).
    #[arg(long, value_name = "SET")]
    pub actions: Option<String>,
    /// Actor processes (actor.count).
    #[arg(long, value_name = "N")]
    pub actors: Option<u32>,
    /// Environments per actor (actor.envs).
    #[arg(long, value_name = "M")]
    pub envs: Option<usize>,
    /// Update budget (learner.max_updates; 0 trains until Ctrl-C).
    #[arg(long, value_name = "N")]
    pub updates: Option<u64>,
    /// Wall-clock budget in minutes (train.max_minutes).
    #[arg(long, value_name = "MIN")]
    pub minutes: Option<f64>,
    /// Run folder [default: runs/<actions>-<scenario>].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Continue the run in the folder: its config.toml (unless --config),
    /// newest checkpoint, replay snapshot, curve and clocks.
    #[arg(long)]
    pub resume: bool,
}

/// `crossroads actor`. Each flag overrides the `[actor]` (or `[sim]`,
/// `[transport]`) key it names.
#[derive(Debug, Clone, Args)]
pub struct ActorArgs {
    /// Scenario of the environments (sim.scenario).
    #[arg(long, value_name = "NAME|FILE")]
    pub scenario: Option<String>,
    /// Action set: ttg, sequential or creep (sim.action_set).
    #[arg(long, value_name = "SET")]
    pub actions: Option<String>,
    /// Environments stepped in parallel (actor.envs).
    #[arg(long, value_name = "M")]
    pub envs: Option<usize>,
    /// This actor's index i for the epsilon ladder (actor.index).
    #[arg(long, value_name = "I")]
    pub index: Option<u32>,
    /// Number of actors N in the run (actor.count).
    #[arg(long, value_name = "N")]
    pub count: Option<u32>,
    /// How batches reach the replay: grpc or shm (actor.transport).
    #[arg(long, value_name = "grpc|shm")]
    pub transport: Option<String>,
    /// How weights arrive: grpc or shm (actor.weights).
    #[arg(long, value_name = "grpc|shm")]
    pub weights: Option<String>,
    /// The replay server (transport.replay_endpoint).
    #[arg(long, value_name = "URL")]
    pub replay: Option<String>,
    /// The learner (transport.learner_endpoint).
    #[arg(long, value_name = "URL")]
    pub learner: Option<String>,
    /// Act greedily and push nothing (actor.eval).
    #[arg(long)]
    pub eval: bool,
    /// Stop after this many vectorized steps.
    #[arg(long, value_name = "N")]
    pub max_steps: Option<u64>,
}

impl ActorArgs {
    /// Layers these flags over `loader`.
    pub fn apply(&self, mut loader: ConfigLoader) -> ConfigLoader {
        let text = [
            ("sim.scenario", &self.scenario),
            ("sim.action_set", &self.actions),
            ("actor.transport", &self.transport),
            ("actor.weights", &self.weights),
            ("transport.replay_endpoint", &self.replay),
            ("transport.learner_endpoint", &self.learner),
        ];
        for (key, value) in text {
            if let Some(v) = value {
                loader = loader.flag(key, v);
            }
        }
        if let Some(v) = self.envs {
            loader = loader.flag("actor.envs", v);
        }
        if let Some(v) = self.index {
            loader = loader.flag("actor.index", v);
        }
        if let Some(v) = self.count {
            loader = loader.flag("actor.count", v);
        }
        if self.eval {
            loader = loader.flag("actor.eval", true);
        }
        loader
    }
}

/// `crossroads learner`. Each flag overrides the `[learner]` (or
/// `[transport]`) key it names.
#[derive(Debug, Clone, Args)]
pub struct LearnerArgs {
    /// gRPC address to serve on (learner.listen); port 0 picks a free port.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<std::net::SocketAddr>,
    /// The replay server to sample from (transport.replay_endpoint).
    #[arg(long, value_name = "URL")]
    pub replay: Option<String>,
    /// Directory for checkpoints, resumed from at start
    /// (learner.checkpoint_dir).
    #[arg(long, value_name = "DIR")]
    pub checkpoint_dir: Option<PathBuf>,
    /// Stop after this many updates (learner.max_updates).
    #[arg(long, value_name = "N")]
    pub max_updates: Option<u64>,
    /// Start fresh even if checkpoints exist (learner.resume = false).
    #[arg(long)]
    pub no_resume: bool,
    /// Do not publish weights over iceoryx2 shared memory
    /// (learner.shm_publish = false).
    #[arg(long)]
    pub no_shm: bool,
}

impl LearnerArgs {
    /// Layers these flags over `loader`.
    pub fn apply(&self, mut loader: ConfigLoader) -> ConfigLoader {
        if let Some(v) = self.listen {
            loader = loader.flag("learner.listen", v.to_string());
        }
        if let Some(v) = &self.replay {
            loader = loader.flag("transport.replay_endpoint", v);
        }
        if let Some(v) = &self.checkpoint_dir {
            loader = loader.flag("learner.checkpoint_dir", v);
        }
        if let Some(v) = self.max_updates {
            loader = loader.flag("learner.max_updates", v);
        }
        if self.no_resume {
            loader = loader.flag("learner.resume", false);
        }
        if self.no_shm {
            loader = loader.flag("learner.shm_publish", false);
        }
        loader
    }
}

/// `crossroads checkpoints`.
#[derive(Debug, Args)]
pub struct CheckpointsArgs {
    /// The learner's gRPC URL.
    #[arg(
        long,
        global = true,
        env = "CROSSROADS_LEARNER_URL",
        default_value = "http://127.0.0.1:50052",
        value_name = "URL"
    )]
    pub learner: String,
    /// Bearer token for save, restore and delete, instead of the
    /// configured one (transport.auth.token_file, or the CROSSROADS_TOKEN
    /// variable, which keeps it out of the process list). For an https://
    /// URL, the CA is transport.tls.ca_file.
    #[arg(long, global = true, value_name = "TOKEN")]
    pub token: Option<String>,
    /// Seconds to wait for each answer.
    #[arg(long, global = true, default_value_t = 60)]
    pub timeout: u64,
    /// Print JSON instead of text.
    #[arg(long, global = true)]
    pub json: bool,
    #[command(subcommand)]
    pub action: CheckpointsAction,
}

#[derive(Debug, Subcommand)]
pub enum CheckpointsAction {
    /// List stored checkpoints, newest first.
    List,
    /// Download a checkpoint's files into OUT/<id>/.
    Pull {
        /// Checkpoint id, e.g. ckpt-000000012000.
        id: String,
        /// Folder to write into.
        #[arg(long, short = 'o', default_value = ".")]
        out: PathBuf,
    },
    /// Write a checkpoint now.
    Save,
    /// Load a checkpoint into the running learner and continue from it.
    Restore {
        /// Checkpoint id.
        id: String,
    },
    /// Remove a checkpoint.
    Delete {
        /// Checkpoint id.
        id: String,
    },
}

/// A policy driving an action set on a scenario (`eval`, `render`).
#[derive(Debug, Args)]
pub struct PolicyArgs {
    /// Policy: ttc:<seconds>, ttc-creep:<seconds>, random, never (the ego
    /// waits out the time limit: traffic alone), oracle:<futures> (sees
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

/// `crossroads tune-ttc`.
#[derive(Debug, Args)]
pub struct TuneTtcArgs {
    /// Scenario name or scenario TOML file.
    #[arg(long, default_value = "left")]
    pub scenario: String,
    /// Who drives the traffic: sumo, human, mixed or a drivers TOML file
    /// [default: the scenario's own]; the paper's rule then tunes TTC for
    /// that population.
    #[arg(long, value_name = "PRESET|FILE")]
    pub drivers: Option<String>,
    /// Action set the TTC rule drives.
    #[arg(long, default_value = "ttg", value_parser = parse_action_set)]
    pub actions: ActionSet,
    /// Creep until the conflicting lanes are visible, then apply the rule
    /// (TTC with creep, for occlusion scenarios).
    #[arg(long)]
    pub creep: bool,
    /// Trials per threshold.
    #[arg(long, short = 'n', default_value_t = 2_000)]
    pub trials: u64,
    /// Base seed, the same for every threshold.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Thresholds in seconds: start:end:step or a comma-separated list
    /// [default: 0:10:0.25].
    #[arg(long)]
    pub thresholds: Option<String>,
    /// Folder for tune-ttc[-creep]-<scenario>.csv and .png.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

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

/// `crossroads render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub run: PolicyArgs,
    /// Base seed; with --trial, the episode is trial I of
    /// `crossroads eval --seed S`.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Which trial of the seed's sequence to draw.
    #[arg(long, default_value_t = 0)]
    pub trial: u64,
    /// Output file: .gif (the whole episode, one frame per 0.2 s step),
    /// .png or .svg (one moment, see --step).
    #[arg(long, short = 'o', value_name = "FILE")]
    pub out: PathBuf,
    /// Overlay the observation grid the action set's network sees.
    #[arg(long)]
    pub grid: bool,
    /// For .png/.svg: the simulation step to draw [default: the step at
    /// which the policy decides to go, else the last].
    #[arg(long)]
    pub step: Option<u32>,
    /// Pixels per metre [default: 8, or 5 for the wide view that grids and
    /// occlusion scenarios need].
    #[arg(long)]
    pub scale: Option<f64>,
    /// For .gif: playback speed relative to real time.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
}

fn parse_action_set(s: &str) -> Result<ActionSet, String> {
    s.parse::<ActionSet>().map_err(|e| e.to_string())
}

/// `crossroads config`.
#[derive(Debug, Args)]
pub struct ConfigArgs {
    #[command(subcommand)]
    pub action: ConfigAction,
}

#[derive(Debug, Subcommand)]
pub enum ConfigAction {
    /// Print the effective configuration (defaults, file, environment and
    /// --set merged) as TOML.
    Show,
    /// Validate the configuration and report every problem; exit status 0
    /// when it is valid.
    Check,
}

/// `crossroads health`.
#[derive(Debug, Args)]
pub struct HealthArgs {
    /// Metrics address of the role to check (default: telemetry.metrics_addr).
    #[arg(long, value_name = "ADDR")]
    pub addr: Option<std::net::SocketAddr>,
    /// Longest wait for the answer, milliseconds.
    #[arg(long, value_name = "MS", default_value_t = 2000)]
    pub timeout_ms: u64,
    /// Print nothing when healthy.
    #[arg(long, short)]
    pub quiet: bool,
}

/// `crossroads doctor`.
#[derive(Debug, Args)]
pub struct DoctorArgs {
    /// Print the report as one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Time the forward passes again while another process keeps one
    /// core busy, and print both medians and their ratio: how much a busy
    /// machine slows libtorch here.
    #[arg(long)]
    pub busy: bool,
}

/// `crossroads replay`. Each flag overrides the `[replay]` key of the same
/// name from the file, the environment and --set.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// gRPC address to serve on (replay.listen); port 0 picks a free port.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<std::net::SocketAddr>,
    /// Directory for snapshots, restored at start (replay.snapshot_dir).
    #[arg(long, value_name = "DIR")]
    pub snapshot_dir: Option<PathBuf>,
    /// Items the table holds before evicting the oldest (replay.capacity).
    #[arg(long, value_name = "N")]
    pub capacity: Option<u64>,
    /// Name of the table (replay.table).
    #[arg(long, value_name = "NAME")]
    pub table: Option<String>,
    /// Do not take batches over iceoryx2 shared memory (replay.shm_ingest).
    #[arg(long)]
    pub no_shm: bool,
    /// Start empty even if snapshots exist (replay.restore = false).
    #[arg(long)]
    pub no_restore: bool,
}

impl ReplayArgs {
    /// Layers these flags over `loader`.
    pub fn apply(&self, mut loader: ConfigLoader) -> ConfigLoader {
        if let Some(v) = self.listen {
            loader = loader.flag("replay.listen", v.to_string());
        }
        if let Some(v) = &self.snapshot_dir {
            loader = loader.flag("replay.snapshot_dir", v);
        }
        if let Some(v) = self.capacity {
            loader = loader.flag("replay.capacity", v);
        }
        if let Some(v) = &self.table {
            loader = loader.flag("replay.table", v);
        }
        if self.no_shm {
            loader = loader.flag("replay.shm_ingest", false);
        }
        if self.no_restore {
            loader = loader.flag("replay.restore", false);
        }
        loader
    }
}

/// `crossroads bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub target: BenchTarget,
}

#[derive(Debug, Subcommand)]
pub enum BenchTarget {
    /// Simulator: TTG decisions/s with observations and traffic steps/s per
    /// core, for each built-in scenario.
    Sim {
        /// Least time per measurement, in seconds.
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Actor: transitions/s of one actor process, inference included, for
    /// each environment count M and each way to the replay.
    ///
    /// `inproc` inserts batches into the table directly; `shm` and `grpc`
    /// push them to a real replay server in this process over iceoryx2 and
    /// loopback gRPC. Counts what the replay stored per second (medians of
    /// the rounds), with env steps/s, forward passes/s and the share of
    /// time in inference. Scenario, action set, batch size and network come
    /// from the [actor] and [learner] sections (--set to change them).
    Actor {
        /// Environment counts M, comma-separated.
        #[arg(long, default_value = "1,8,32,64", value_delimiter = ',')]
        envs: Vec<usize>,
        /// Ways to the replay, comma-separated: inproc, shm, grpc.
        #[arg(
            long = "transport",
            default_value = "inproc,shm,grpc",
            value_delimiter = ','
        )]
        transports: Vec<String>,
        /// Timed rounds per cell; the median is reported.
        #[arg(long, default_value_t = 5)]
        rounds: usize,
        /// Seconds per round.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        /// Seconds of acting before the first round.
        #[arg(long, default_value_t = 1.0)]
        warmup: f64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Load: one replay server under many actors' streams, and one learner
    /// under many weight subscribers with one stalled.
    ///
    /// Starts a replay server in this process and pushes synthetic TTG
    /// batches at it from --streams gRPC streams (each its own connection)
    /// and --shm iceoryx2 publishers for --seconds, with the write-ahead
    /// log off and on; prints transitions/s stored, ack latency p50/p99,
    /// the table's bytes and the resident memory (peak against the table's
    /// bytes). Then a learner (the run's network) trains on a filled replay
    /// while --subscribers subscribe to its weights, one of them never
    /// reading: prints the versions published and received by the slowest
    /// live subscriber, and the memory.
    Load {
        /// Concurrent gRPC insert streams.
        #[arg(long, default_value_t = 64)]
        streams: usize,
        /// Concurrent shared-memory publishers (at most transport.shm_max_publishers).
        #[arg(long, default_value_t = 8)]
        shm: usize,
        /// Seconds per measurement.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// Table capacity, items (the run exceeds it, so eviction is timed too).
        #[arg(long, default_value_t = 200_000)]
        capacity: u64,
        /// Transitions per batch.
        #[arg(long, default_value_t = 32)]
        batch: usize,
        /// Write-ahead log: off, on, or both (one run each).
        #[arg(long, default_value = "both", value_parser = ["off", "on", "both"])]
        wal: String,
        /// Weight subscribers on the learner (0 skips that part).
        #[arg(long, default_value_t = 64)]
        subscribers: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Replay table: bytes per transition, inserts/s, samples/s.
    ///
    /// Fills a table with synthetic TTG episodes (3-8 cars per grid), then
    /// times rounds of inserts (batches of 64) and samples (batches of 256)
    /// and prints the medians.
    Replay {
        /// Table capacity, filled before timing.
        #[arg(long, default_value_t = 262_144)]
        capacity: usize,
        /// Timed rounds; the median is reported.
        #[arg(long, default_value_t = 11)]
        rounds: usize,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Time to target: `crossroads train` of a built-in experiment from
    /// each seed (actor.seed and learner.seed), stopping at the
    /// experiment's target ([train] target_*); prints the wall time, env
    /// steps and updates to the confirmed target per seed and their
    /// medians, with the machine. --set applies to every training.
    TimeToTarget {
        /// Training seeds, comma-separated.
        #[arg(long, default_value = "1,2,3", value_delimiter = ',')]
        seeds: Vec<u64>,
        /// Give up on a seed after this many minutes (it counts as not
        /// reached).
        #[arg(long, default_value_t = 15.0)]
        minutes: f64,
        /// Keep the run folders here (default: a temporary folder, removed
        /// after).
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Learner: updates/s of the default network at each batch size on
    /// in-memory batches, then fed by a replay server over loopback gRPC
    /// (with the fraction of time spent waiting for samples), and the same
    /// network and optimizer in PyTorch for comparison.
    Learner {
        /// Batch sizes, comma-separated.
        #[arg(long, default_value = "64,256", value_delimiter = ',')]
        batch: Vec<u32>,
        /// libtorch (and PyTorch) intra-op threads [default:
        /// runtime.torch_threads, 1].
        #[arg(long)]
        threads: Option<usize>,
        /// Timed rounds per measurement; the median is reported.
        #[arg(long, default_value_t = 5)]
        rounds: usize,
        /// Seconds per round.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
        /// Updates of the gRPC-fed run per batch size.
        #[arg(long, default_value_t = 300)]
        fed_updates: u64,
        /// Python with torch for the comparison [default: $CROSSROADS_PYTHON,
        /// then .venv/bin/python3, then python3].
        #[arg(long)]
        python: Option<PathBuf>,
        /// Skip the PyTorch comparison.
        #[arg(long)]
        no_pytorch: bool,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

//! The command-line interface, as clap derives it: the subcommands, and
//! the flags of those the binary runs itself; the experiment harness's
//! commands take their `Args` from `crossroads_harness`.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use crossroads_config::ConfigLoader;
use crossroads_harness::bench::BenchArgs;
use crossroads_harness::eval::{EvalArgs, PolicyArgs};
use crossroads_harness::global::{GlobalArgs, KeyFlag, layer, with_keys};
use crossroads_harness::key_flag;
use crossroads_harness::reproduce::ReproduceArgs;
use crossroads_harness::sumo_check::SumoCheckArgs;
use crossroads_harness::train::TrainArgs;
use crossroads_harness::tune_ttc::TuneTtcArgs;

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

/// The command line as it is parsed and documented: [`Cli`], each flag
/// that sets a configuration key naming it in its help.
pub fn command() -> clap::Command {
    use clap::CommandFactory;
    let cli = Cli::command();
    let names: Vec<String> = cli
        .get_subcommands()
        .map(|c| c.get_name().to_owned())
        .collect();
    // `mut_subcommand` moves the one it edits to the end: every one is
    // edited in turn, so the order of `crossroads --help` stays declared.
    names.iter().fold(cli, |cli, name| {
        cli.mut_subcommand(name, |c| match c.get_name() {
            "replay" => with_keys(c, ReplayArgs::KEYS),
            "learner" => with_keys(c, LearnerArgs::KEYS),
            "actor" => with_keys(c, ActorArgs::KEYS),
            "train" => with_keys(c, TrainArgs::KEYS),
            _ => c,
        })
    })
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

/// `crossroads actor`. Each flag overrides the `[actor]` (or `[sim]`,
/// `[transport]`) key it names.
#[derive(Debug, Clone, Args)]
pub struct ActorArgs {
    /// Scenario of the environments.
    #[arg(long, value_name = "NAME|FILE")]
    pub scenario: Option<String>,
    /// Action set: ttg, sequential or creep.
    #[arg(long, value_name = "SET")]
    pub actions: Option<String>,
    /// Environments stepped in parallel.
    #[arg(long, value_name = "M")]
    pub envs: Option<usize>,
    /// This actor's index i for the epsilon ladder.
    #[arg(long, value_name = "I")]
    pub index: Option<u32>,
    /// Number of actors N in the run.
    #[arg(long, value_name = "N")]
    pub count: Option<u32>,
    /// How batches reach the replay: grpc or shm.
    #[arg(long, value_name = "grpc|shm")]
    pub transport: Option<String>,
    /// How weights arrive: grpc or shm.
    #[arg(long, value_name = "grpc|shm")]
    pub weights: Option<String>,
    /// The replay server.
    #[arg(long, value_name = "URL")]
    pub replay: Option<String>,
    /// The learner.
    #[arg(long, value_name = "URL")]
    pub learner: Option<String>,
    /// Act greedily and push nothing.
    #[arg(long)]
    pub eval: bool,
    /// Stop after this many vectorized steps.
    #[arg(long, value_name = "N")]
    pub max_steps: Option<u64>,
}

impl ActorArgs {
    /// The flags that set a configuration key.
    pub const KEYS: &'static [KeyFlag<Self>] = &[
        key_flag!(scenario => "sim.scenario"),
        key_flag!(actions => "sim.action_set"),
        key_flag!(envs => "actor.envs"),
        key_flag!(index => "actor.index"),
        key_flag!(count => "actor.count"),
        key_flag!(transport => "actor.transport"),
        key_flag!(weights => "actor.weights"),
        key_flag!(replay => "transport.replay_endpoint"),
        key_flag!(learner => "transport.learner_endpoint"),
        key_flag!(on eval => "actor.eval"),
    ];

    /// Layers these flags over `loader`.
    pub fn apply(&self, loader: ConfigLoader) -> ConfigLoader {
        layer(self, Self::KEYS, loader)
    }
}

/// `crossroads learner`. Each flag overrides the `[learner]` (or
/// `[transport]`) key it names.
#[derive(Debug, Clone, Args)]
pub struct LearnerArgs {
    /// gRPC address to serve on; port 0 picks a free port.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<std::net::SocketAddr>,
    /// The replay server to sample from.
    #[arg(long, value_name = "URL")]
    pub replay: Option<String>,
    /// Directory for checkpoints, resumed from at start.
    #[arg(long, value_name = "DIR")]
    pub checkpoint_dir: Option<PathBuf>,
    /// Stop after this many updates.
    #[arg(long, value_name = "N")]
    pub max_updates: Option<u64>,
    /// Start fresh even if checkpoints exist.
    #[arg(long)]
    pub no_resume: bool,
    /// Do not publish weights over iceoryx2 shared memory.
    #[arg(long)]
    pub no_shm: bool,
}

impl LearnerArgs {
    /// The flags that set a configuration key.
    pub const KEYS: &'static [KeyFlag<Self>] = &[
        key_flag!(listen => "learner.listen"),
        key_flag!(replay => "transport.replay_endpoint"),
        key_flag!(checkpoint_dir => "learner.checkpoint_dir"),
        key_flag!(max_updates => "learner.max_updates"),
        key_flag!(off no_resume => "learner.resume"),
        key_flag!(off no_shm => "learner.shm_publish"),
    ];

    /// Layers these flags over `loader`.
    pub fn apply(&self, loader: ConfigLoader) -> ConfigLoader {
        layer(self, Self::KEYS, loader)
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
    /// gRPC address to serve on; port 0 picks a free port.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<std::net::SocketAddr>,
    /// Directory for snapshots, restored at start.
    #[arg(long, value_name = "DIR")]
    pub snapshot_dir: Option<PathBuf>,
    /// Items the table holds before evicting the oldest.
    #[arg(long, value_name = "N")]
    pub capacity: Option<u64>,
    /// Name of the table.
    #[arg(long, value_name = "NAME")]
    pub table: Option<String>,
    /// Do not take batches over iceoryx2 shared memory.
    #[arg(long)]
    pub no_shm: bool,
    /// Start empty even if snapshots exist.
    #[arg(long)]
    pub no_restore: bool,
}

impl ReplayArgs {
    /// The flags that set a configuration key.
    pub const KEYS: &'static [KeyFlag<Self>] = &[
        key_flag!(listen => "replay.listen"),
        key_flag!(snapshot_dir => "replay.snapshot_dir"),
        key_flag!(capacity => "replay.capacity"),
        key_flag!(table => "replay.table"),
        key_flag!(off no_shm => "replay.shm_ingest"),
        key_flag!(off no_restore => "replay.restore"),
    ];

    /// Layers these flags over `loader`.
    pub fn apply(&self, loader: ConfigLoader) -> ConfigLoader {
        layer(self, Self::KEYS, loader)
    }
}

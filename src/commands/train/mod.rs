//! `crossroads train`: a whole training run on this machine, with the same
//! roles and transports as a distributed one.
//!
//! It writes the run's configuration to `<out>/config.toml`, starts
//! `crossroads replay`, `crossroads learner` and `train.actors` ×
//! `crossroads actor` from this binary (each in its own process group,
//! logging to `<out>/logs/`), and then watches: the learner's status and
//! the replay's info over gRPC, the actors' `/metrics`, a progress bar.
//! Every `train.eval_every` updates it fetches the latest weights and runs
//! `train.eval_trials` greedy trials in this process (the same seeded trials
//! each time, at most `train.eval_share` of the wall time), appends them to
//! `<out>/curve.csv`, keeps the weights in `<out>/last/` and reports them
//! to the learner (so its best checkpoint follows the same rule). Weights
//! whose mean undiscounted return beats the best so far, or that meet the
//! target, are re-measured on `train.confirm_trials` trials; the best by
//! that figure are kept in `<out>/best/`, and the target counts as reached
//! when such a figure meets it. It ends at the learner's update budget,
//! the time budget, the target (`train.stop_at_target`) or Ctrl-C, stopping
//! actors, then the learner (last checkpoint), then the replay (last
//! snapshot).

mod procs;
mod record;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_config::{ActorTransport, Config, ConfigLoader};
use crossroads_common::Shutdown;
use crossroads_sim::{ActionSet, Env, EnvConfig, EvalConfig, Scenario, evaluate};
use crossroads_transport::LearnerClient;
use crossroads_transport::grpc::ReplayClient;
use indicatif::{ProgressBar, ProgressStyle};

use self::procs::{Role, free_port};
pub use self::record::write_atomic;
use self::record::{Curve, Reached, TrainMetrics, plot_curve};
pub use self::record::{Evaluation, Summary, curve_panel, read_curve};
use super::role;
use crate::cli::{GlobalArgs, TrainArgs};
use crate::network_policy::NetworkPolicy;

/// Grace period for a role to stop after SIGTERM.
const GRACE: Duration = Duration::from_secs(60);

/// The run folder a run of `scenario` with `actions` gets by default:
/// `runs/<scenario>-<actions>` (a scenario file contributes its stem).
pub fn default_out(scenario: &str, actions: &str) -> PathBuf {
    let stem = Path::new(scenario)
        .file_stem()
        .map_or_else(|| scenario.to_owned(), |s| s.to_string_lossy().into_owned());
    PathBuf::from("runs").join(format!("{stem}-{actions}"))
}

impl TrainArgs {
    /// The run folder these flags name, before the config is read.
    fn out_dir(&self) -> PathBuf {
        self.out.clone().unwrap_or_else(|| {
            default_out(
                self.scenario.as_deref().unwrap_or("left"),
                self.actions.as_deref().unwrap_or("ttg"),
            )
        })
    }

    /// The built-in experiment these flags name (default: ttg on left).
    pub fn experiment(&self) -> Option<crate::experiments::Experiment> {
        crate::experiments::find(
            self.actions.as_deref().unwrap_or("ttg"),
            self.scenario.as_deref().unwrap_or("left"),
        )
    }

    /// The configuration layers of a run: with `--resume` and no
    /// `--config`, the run folder's `config.toml` is the file; then these
    /// flags. Without a file, the paper's experiment for the scenario and action
    /// set (configs/experiments/, built in) is the base, so that plain
    /// `crossroads train` trains DQN-TTG on left with tuned settings.
    pub fn loader(&self, global: &GlobalArgs) -> ConfigLoader {
        let mut loader = global.loader();
        let saved = self.out_dir().join("config.toml");
        if self.resume && global.config.is_none() && saved.exists() {
            loader = loader.file(Some(saved));
        } else if global.config.is_none()
            && global.experiment.is_none()
            && let Some(e) = self.experiment()
        {
            loader = loader.base(format!("built-in experiment {}", e.name), e.toml);
        }
        if let Some(s) = &self.scenario {
            loader = loader.flag("actor.scenario", s).flag("learner.scenario", s);
        }
        if let Some(a) = &self.actions {
            loader = loader
                .flag("actor.action_set", a)
                .flag("learner.action_set", a);
        }
        if let Some(n) = self.actors {
            loader = loader.flag("train.actors", n).flag("actor.count", n);
        }
        if let Some(n) = self.envs {
            loader = loader.flag("actor.envs", n);
        }
        if let Some(n) = self.updates {
            loader = loader.flag("learner.max_updates", n);
        }
        if let Some(m) = self.minutes {
            loader = loader.flag("train.max_minutes", m);
        }
        loader
    }
}

/// Runs the training job.
pub fn run(config: &Config, args: &TrainArgs) -> anyhow::Result<ExitCode> {
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| default_out(&config.actor.scenario, &config.actor.action_set));
    let run = prepare(config, &out, args.resume)?;
    role::block_on(config, async move { train(run).await })
}

/// A run ready to start: its folder and its configuration.
struct Run {
    out: PathBuf,
    config: Config,
    scenario: Arc<Scenario>,
    actions: ActionSet,
    previous: Summary,
}

/// Checks the folder, derives the learner's observation from the
/// scenario and action set, and writes `config.toml`.
fn prepare(config: &Config, out: &Path, resume: bool) -> anyhow::Result<Run> {
    let mut c = config.clone();
    let scenario = Arc::new(
        Scenario::load(&c.actor.scenario)
            .with_context(|| format!("actor.scenario {:?}", c.actor.scenario))?,
    );
    let actions: ActionSet = c
        .actor
        .action_set
        .parse()
        .with_context(|| format!("actor.action_set {:?}", c.actor.action_set))?;
    let env = Env::new(Arc::clone(&scenario), EnvConfig::for_actions(actions));
    let kind = crossroads_actor::batch_spec(env.obs_spec()).kind;
    c.learner.observation = kind;
    c.learner.action_set = c.actor.action_set.clone();
    c.learner.scenario = c.actor.scenario.clone();
    c.actor.count = c.train.actors;
    c.actor.index = None;
    c.actor.eval = false;
    c.actor.transport = c.train.transport;
    c.actor.weights = Some(c.train.transport);
    let shm = c.train.transport == ActorTransport::Shm;
    c.replay.shm_ingest = shm;
    c.learner.shm_publish = shm;

    let has_checkpoints = out
        .join("checkpoints")
        .read_dir()
        .is_ok_and(|mut d| d.next().is_some());
    anyhow::ensure!(
        resume || !has_checkpoints,
        "{} already holds a run; add --resume to continue it, or choose another --out",
        out.display()
    );
    std::fs::create_dir_all(out.join("logs"))
        .with_context(|| format!("creating {}", out.display()))?;
    let out = out
        .canonicalize()
        .with_context(|| format!("resolving {}", out.display()))?;
    c.learner.checkpoint_dir = Some(out.join("checkpoints"));
    c.learner.resume = resume;
    c.replay.snapshot_dir = Some(out.join("replay"));
    c.replay.restore = resume;
    let problems = c.validate();
    anyhow::ensure!(
        problems.is_empty(),
        "invalid run configuration: {}",
        problems
            .iter()
            .map(|(k, p)| format!("{k}: {p}"))
            .collect::<Vec<_>>()
            .join("; ")
    );
    write_atomic(&out.join("config.toml"), c.to_toml().as_bytes())?;
    let previous = if resume {
        Summary::load(&out)?.unwrap_or_default()
    } else {
        for stale in ["curve.csv", "summary.json"] {
            let _ = std::fs::remove_file(out.join(stale));
        }
        Summary::default()
    };
    Ok(Run {
        out,
        config: c,
        scenario,
        actions,
        previous,
    })
}

/// The addresses of one session's roles.
struct Addresses {
    replay: std::net::SocketAddr,
    learner: std::net::SocketAddr,
    shm_prefix: String,
}

impl Addresses {
    fn pick(out: &Path) -> anyhow::Result<Self> {
        let name = out
            .file_name()
            .map_or("run".into(), |n| n.to_string_lossy().into_owned());
        let name: String = name
            .chars()
            .map(|ch| if ch.is_ascii_alphanumeric() { ch } else { '-' })
            .collect();
        Ok(Self {
            replay: free_port()?,
            learner: free_port()?,
            shm_prefix: format!("crossroads/train-{name}-{}", std::process::id()),
        })
    }

    /// The variables every role gets (they override the file). The roles
    /// share this machine's cores, so libgomp's threads sleep instead of
    /// spinning while they wait (unless the user chose otherwise): spinning
    /// threads of one role starve the others.
    fn env(&self) -> Vec<(String, String)> {
        let mut env = Vec::new();
        if std::env::var_os("OMP_WAIT_POLICY").is_none() {
            env.push(("OMP_WAIT_POLICY".into(), "passive".into()));
        }
        env.extend([
            ("CROSSROADS_REPLAY__LISTEN".into(), self.replay.to_string()),
            (
                "CROSSROADS_TRANSPORT__REPLAY_ENDPOINT".into(),
                format!("http://{}", self.replay),
            ),
            (
                "CROSSROADS_LEARNER__LISTEN".into(),
                self.learner.to_string(),
            ),
            (
                "CROSSROADS_TRANSPORT__LEARNER_ENDPOINT".into(),
                format!("http://{}", self.learner),
            ),
            (
                "CROSSROADS_TRANSPORT__SHM_PREFIX".into(),
                self.shm_prefix.clone(),
            ),
        ]);
        env
    }
}

/// Why the run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    Budget,
    Minutes,
    Target,
    Signal,
}

impl End {
    fn status(self) -> &'static str {
        match self {
            End::Budget | End::Minutes => "finished",
            End::Target => "target",
            End::Signal => "stopped",
        }
    }
}

/// The running session: roles, clients, records.
struct Session {
    run: Run,
    replay: Role,
    learner: Role,
    actors: Vec<Role>,
    replay_client: ReplayClient,
    learner_client: LearnerClient,
    curve: Curve,
    metrics: TrainMetrics,
    summary: Summary,
    started: Instant,
    env_steps: u64,
    updates: u64,
    transitions: u64,
    loss: f64,
}

async fn train(run: Run) -> anyhow::Result<()> {
    let c = &run.config;
    tracing::info!(
        out = %run.out.display(),
        scenario = %c.actor.scenario,
        actions = %c.actor.action_set,
        observation = %c.learner.observation,
        actors = c.train.actors,
        envs = c.actor.envs,
        updates = c.learner.max_updates,
        transport = ?c.train.transport,
        "crossroads train starting"
    );
    let role = role::Role::start(c, "train").await?;
    let metrics = TrainMetrics::new(&role.registry)?;
    let result = session(run, metrics, role.shutdown.clone()).await;
    role.finish(result).await
}

async fn session(run: Run, metrics: TrainMetrics, shutdown: Shutdown) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("finding this program")?;
    let config_path = run.out.join("config.toml");
    let addr = Addresses::pick(&run.out)?;
    let env = addr.env();
    let logs = run.out.join("logs");
    let c = run.config.clone();
    let timeout = Duration::from_millis(c.transport.request_timeout_ms.min(10_000));

    let mut replay = Role::spawn(
        "replay",
        &exe,
        &config_path,
        &["replay"],
        &env,
        logs.join("replay.log"),
        free_port()?,
    )?;
    let mut transport = c.transport.clone();
    transport.replay_endpoint = format!("http://{}", addr.replay);
    let replay_client = ReplayClient::new(&transport, &c.replay.table)?;
    wait_ready(&mut replay, &shutdown, || async {
        replay_client
            .info()
            .await
            .map(|_| ())
            .map_err(|e| e.to_string())
    })
    .await?;

    let mut learner = Role::spawn(
        "learner",
        &exe,
        &config_path,
        &["learner"],
        &env,
        logs.join("learner.log"),
        free_port()?,
    )?;
    let learner_client = LearnerClient::new(
        &format!("http://{}", addr.learner),
        c.learner.api_token.clone(),
        timeout,
    )?;
    let ready = wait_ready(&mut learner, &shutdown, || async {
        learner_client
            .status()
            .await
            .map(|_| ())
            .map_err(|e| e.to_string())
    })
    .await;
    if let Err(e) = ready {
        replay.stop(GRACE).await;
        return Err(e);
    }

    let mut actors = Vec::new();
    for i in 0..c.train.actors {
        let mut env = env.clone();
        env.push(("CROSSROADS_ACTOR__INDEX".into(), i.to_string()));
        actors.push(Role::spawn(
            &format!("actor-{i}"),
            &exe,
            &config_path,
            &["actor"],
            &env,
            logs.join(format!("actor-{i}.log")),
            free_port()?,
        )?);
    }
    tracing::info!(
        replay = %addr.replay,
        learner = %addr.learner,
        replay_metrics = %replay.metrics,
        learner_metrics = %learner.metrics,
        actor_metrics = ?actors.iter().map(|a| a.metrics.to_string()).collect::<Vec<_>>(),
        logs = %logs.display(),
        "roles started"
    );

    let mut summary = run.previous.clone();
    summary.scenario = c.actor.scenario.clone();
    summary.action_set = c.actor.action_set.clone();
    summary.observation = c.learner.observation.clone();
    summary.actors = c.train.actors;
    summary.status = "running".into();
    summary.machine = machine();
    let mut s = Session {
        curve: Curve::open(&run.out)?,
        run,
        replay,
        learner,
        actors,
        replay_client,
        learner_client,
        metrics,
        started: Instant::now(),
        env_steps: 0,
        updates: 0,
        transitions: 0,
        loss: 0.0,
        summary,
    };
    let watched = s.watch(&shutdown).await;
    let stopped = s.stop_all(watched.as_ref().ok().copied()).await;
    match (watched, stopped) {
        (Err(e), _) | (Ok(_), Err(e)) => {
            s.summary.status = "failed".into();
            let _ = s.summary.save(&s.run.out);
            Err(e)
        }
        (Ok(_), Ok(())) => Ok(()),
    }
}

/// Waits until `probe` answers, failing early when the role exits (with
/// the end of its log) or after two minutes.
async fn wait_ready<F, Fut>(role: &mut Role, shutdown: &Shutdown, probe: F) -> anyhow::Result<()>
where
    F: Fn() -> Fut,
    Fut: Future<Output = Result<(), String>>,
{
    let start = Instant::now();
    loop {
        if let Some(status) = role.exited() {
            anyhow::bail!(
                "{} exited ({status}) before it was ready; the end of {}:\n{}",
                role.name,
                role.log.display(),
                role.log_tail(20)
            );
        }
        match probe().await {
            Ok(()) => return Ok(()),
            Err(e) if start.elapsed() > Duration::from_secs(120) => {
                anyhow::bail!("{} not ready after 2 minutes: {e}", role.name)
            }
            Err(_) => {}
        }
        if shutdown.is_triggered() {
            anyhow::bail!("stopped before {} was ready", role.name);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

impl Session {
    fn wall(&self) -> f64 {
        self.run.previous.wall_seconds + self.started.elapsed().as_secs_f64()
    }

    /// Watches until the run ends; evaluates on schedule.
    async fn watch(&mut self, shutdown: &Shutdown) -> anyhow::Result<End> {
        let c = self.run.config.clone();
        let budget = c.learner.max_updates;
        let bar = progress_bar(budget);
        // The first evaluation is of the weights the run starts from.
        let mut next_eval = 0;
        // Periodic evaluations take at most `eval_share` of the wall time:
        // the next one starts no earlier than this.
        let mut eval_gate = Instant::now();
        let mut rate = (Instant::now(), self.run.previous.env_steps);
        let mut steps_per_s = 0.0;
        let mut last_eval = "no evaluation yet".to_owned();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        // After a long evaluation, one tick, not a burst of missed ones.
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let end = loop {
            // Biased: a signal that came during an evaluation wins over the
            // tick that is due by then (unbiased, select! picked either, so
            // Ctrl-C could wait several evaluations of a minute each).
            tokio::select! {
                biased;
                () = shutdown.wait() => break End::Signal,
                _ = tick.tick() => {}
            }
            if self.check_roles()? {
                break End::Budget;
            }
            if let Ok(st) = self.learner_client.status().await {
                self.updates = st.update_step;
                self.loss = st.loss;
            }
            if let Ok(info) = self.replay_client.info().await {
                self.transitions = info.inserts_total;
            }
            let steps = self.run.previous.env_steps + self.actor_steps().await;
            if steps >= self.env_steps {
                self.env_steps = steps;
            }
            let dt = rate.0.elapsed().as_secs_f64();
            if dt >= 5.0 {
                steps_per_s = (self.env_steps.saturating_sub(rate.1)) as f64 / dt;
                rate = (Instant::now(), self.env_steps);
            }
            self.metrics
                .progress(self.updates, self.env_steps, steps_per_s);
            bar.set_position(self.updates);
            bar.set_message(format!("{:.0} env steps/s | {last_eval}", steps_per_s));
            if self.updates >= next_eval && Instant::now() >= eval_gate {
                next_eval = self.updates + c.train.eval_every;
                let began = Instant::now();
                let evaluated = self.evaluate_latest(c.train.eval_trials, &bar).await;
                match evaluated {
                    Ok((e, reached, took)) => {
                        // Gated on the periodic evaluation's own time: a
                        // 10,000-trial re-measure of a new best is rare and
                        // must not push the next evaluation minutes away.
                        eval_gate = began + took.div_f64(c.train.eval_share);
                        last_eval = e.brief();
                        bar.suspend(|| {
                            tracing::info!(
                                updates = e.updates,
                                minutes = format!("{:.1}", e.wall_seconds / 60.0),
                                env_steps = e.env_steps,
                                "evaluation: {}",
                                e.brief()
                            );
                        });
                        if reached && c.train.stop_at_target {
                            break End::Target;
                        }
                    }
                    Err(e) => {
                        eval_gate = began + began.elapsed().div_f64(c.train.eval_share);
                        tracing::warn!(error = %format!("{e:#}"), "evaluation failed");
                    }
                }
            }
            if budget > 0 && self.updates >= budget {
                break End::Budget;
            }
            if c.train.max_minutes > 0.0
                && self.started.elapsed().as_secs_f64() >= 60.0 * c.train.max_minutes
            {
                break End::Minutes;
            }
        };
        bar.finish_and_clear();
        Ok(end)
    }

    /// An error naming the role that ended on its own (with its log's
    /// end); `true` when the learner ended at its update budget.
    fn check_roles(&mut self) -> anyhow::Result<bool> {
        let budget = self.run.config.learner.max_updates;
        if let Some(status) = self.learner.exited() {
            if status.success() && budget > 0 {
                self.updates = self.updates.max(budget);
                return Ok(true);
            }
            return Err(died(&self.learner, status));
        }
        if let Some(status) = self.replay.exited() {
            return Err(died(&self.replay, status));
        }
        for a in &mut self.actors {
            if let Some(status) = a.exited() {
                return Err(died(a, status));
            }
        }
        Ok(false)
    }

    /// Simulation steps of all actors, from their `/metrics`.
    async fn actor_steps(&self) -> u64 {
        let mut total = 0.0;
        for a in &self.actors {
            if let Ok(text) =
                crossroads_common::metrics::scrape(a.metrics, Duration::from_secs(2)).await
            {
                total += sum_metric(&text, "crossroads_actor_env_steps_total");
            }
        }
        total as u64
    }

    /// Fetches the latest weights and evaluates them greedily on
    /// `trials` trials of the run's scenario; records (curve, `last/`) and
    /// reports the result. Weights that score above the best so far, or
    /// meet a target not yet reached, are re-measured on `confirm_trials`
    /// ([`Self::consider_best`]). Returns the evaluation, whether the
    /// target was reached by it, and how long the periodic evaluation took
    /// (fetching and `trials` trials, without a re-measure).
    async fn evaluate_latest(
        &mut self,
        trials: u64,
        bar: &ProgressBar,
    ) -> anyhow::Result<(Evaluation, bool, Duration)> {
        let began = Instant::now();
        let (version, safetensors) = if self.learner.exited().is_none() {
            let w = self
                .learner_client
                .latest_weights()
                .await
                .context("fetching the latest weights")?;
            (w.version, w.safetensors)
        } else {
            self.newest_checkpoint()?
        };
        let e = self.evaluate_bytes(&safetensors, version, trials).await?;
        let took = began.elapsed();
        self.record(&e, &safetensors)?;
        self.report(&e).await;
        let c = &self.run.config.train;
        let better = self
            .summary
            .best
            .as_ref()
            .is_none_or(|b| e.score() > b.score());
        let may_reach = self.summary.reached.is_none()
            && c.met(e.success_rate, e.collision_rate, e.mean_time_s);
        let reached = if better || may_reach {
            self.consider_best(&safetensors, &e, bar).await?
        } else {
            false
        };
        Ok((e, reached, took))
    }

    /// Tells the learner how `e`'s weights did, so its best checkpoint
    /// follows the same rule (`learner.best_metric`, `mean_return` by
    /// default).
    async fn report(&mut self, e: &Evaluation) {
        if self.learner.exited().is_some() {
            return;
        }
        let mut report = BTreeMap::new();
        report.insert("success_rate".to_owned(), e.success_rate);
        report.insert("collision_rate".to_owned(), e.collision_rate);
        report.insert("timeout_rate".to_owned(), e.timeout_rate);
        if let Some(r) = e.mean_return {
            report.insert("mean_return".to_owned(), r);
        }
        if let Some(t) = e.mean_time_s {
            report.insert("mean_time_s".to_owned(), t);
        }
        if let Err(err) = self
            .learner_client
            .report_evaluation(e.weights_version, report)
            .await
        {
            tracing::warn!(error = %err, "reporting the evaluation to the learner");
        }
    }

    /// The weights of the newest checkpoint on disk and their version (for
    /// the last evaluation when the learner has already stopped).
    fn newest_checkpoint(&self) -> anyhow::Result<(u64, Vec<u8>)> {
        let dir = self.run.out.join("checkpoints");
        let newest = std::fs::read_dir(&dir)
            .with_context(|| format!("reading {}", dir.display()))?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("ckpt-"))
            })
            .max()
            .with_context(|| format!("no checkpoint in {}", dir.display()))?;
        let file = newest.join("weights.safetensors");
        let bytes = std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?;
        let (_, version) = crossroads_model::QNetwork::from_safetensors(&bytes)
            .with_context(|| format!("{} holds no network", file.display()))?;
        Ok((version, bytes))
    }

    async fn evaluate_bytes(
        &self,
        safetensors: &[u8],
        version: u64,
        trials: u64,
    ) -> anyhow::Result<Evaluation> {
        let policy = NetworkPolicy::from_safetensors(safetensors, format!("dqn@v{version}"))
            .context("the learner's weights")?;
        let scenario = Arc::clone(&self.run.scenario);
        let eval = EvalConfig::new(self.run.actions, trials, self.run.config.train.eval_seed);
        let report = tokio::task::spawn_blocking(move || {
            evaluate(&scenario, &policy, &eval, &|_| {}).map_err(anyhow::Error::from)
        })
        .await
        .context("the evaluation thread")??;
        Ok(Evaluation {
            wall_seconds: self.wall(),
            updates: self.updates,
            env_steps: self.env_steps,
            transitions: self.transitions,
            weights_version: version,
            trials,
            success_rate: report.success_rate,
            collision_rate: report.collision_rate,
            timeout_rate: report.timeout_rate,
            mean_time_s: report.mean_time_s,
            mean_brake_s: report.mean_brake_s,
            loss: self.loss,
            mean_return: Some(report.mean_return),
        })
    }

    /// Appends to the curve, updates the summary and metrics, and keeps the
    /// weights in `last/`.
    fn record(&mut self, e: &Evaluation, safetensors: &[u8]) -> anyhow::Result<()> {
        self.curve.append(e)?;
        self.metrics.evaluated(e);
        keep(&self.run.out.join("last"), e, safetensors)?;
        self.summary.last = Some(e.clone());
        self.update_summary();
        self.summary.save(&self.run.out)
    }

    fn update_summary(&mut self) {
        self.summary.wall_seconds = self.wall();
        self.summary.updates = self.updates;
        self.summary.env_steps = self.env_steps;
        self.summary.transitions = self.transitions;
    }

    /// Re-measures the weights of periodic evaluation `e` on
    /// `confirm_trials` trials (10,000 by default: the periodic ones are
    /// small, and a best picked on them alone would be picked on noise);
    /// keeps them in `best/` when the re-measured score is the best so far,
    /// and records the target as reached when it meets it for the first
    /// time. Returns whether it did.
    async fn consider_best(
        &mut self,
        safetensors: &[u8],
        e: &Evaluation,
        bar: &ProgressBar,
    ) -> anyhow::Result<bool> {
        let c = self.run.config.train.clone();
        let confirmed = if c.confirm_trials > e.trials {
            let mut m = self
                .evaluate_bytes(safetensors, e.weights_version, c.confirm_trials)
                .await?;
            m.updates = e.updates;
            self.report(&m).await;
            m
        } else {
            e.clone()
        };
        let best = self
            .summary
            .best
            .as_ref()
            .is_none_or(|b| confirmed.score() > b.score());
        if best {
            keep(&self.run.out.join("best"), &confirmed, safetensors)?;
            self.summary.best = Some(confirmed.clone());
        }
        let reached = self.summary.reached.is_none()
            && c.met(
                confirmed.success_rate,
                confirmed.collision_rate,
                confirmed.mean_time_s,
            );
        bar.suspend(|| {
            tracing::info!(
                trials = confirmed.trials,
                mean_return = confirmed.mean_return,
                "re-measured: {}{}{}",
                confirmed.brief(),
                if best { " -> best" } else { "" },
                if reached { " -> target reached" } else { "" }
            );
        });
        if reached {
            self.metrics.reached();
            self.summary.reached = Some(Reached {
                evaluation: confirmed,
            });
        }
        self.summary.save(&self.run.out)?;
        Ok(reached)
    }

    /// Stops actors, evaluates the final weights, stops the learner (last
    /// checkpoint) and the replay (last snapshot); writes the summary and
    /// the curve's picture and prints where everything is.
    async fn stop_all(&mut self, end: Option<End>) -> anyhow::Result<()> {
        for a in &mut self.actors {
            a.stop(GRACE).await;
        }
        if end.is_some() {
            // The count of the weights about to be evaluated, not the last
            // tick's (updates go on between ticks).
            if let Ok(st) = self.learner_client.status().await {
                self.updates = st.update_step;
                self.loss = st.loss;
            }
            // A run that ends (budget, minutes, Ctrl-C) on weights that
            // score best or meet the target still gets them re-measured.
            match self
                .evaluate_latest(self.run.config.train.eval_trials, &ProgressBar::hidden())
                .await
            {
                Ok((e, _, _)) => eprintln!("final evaluation: {}", e.brief()),
                Err(e) => tracing::warn!(error = %format!("{e:#}"), "final evaluation"),
            }
        }
        let learner = self.learner.stop(GRACE).await;
        let replay = self.replay.stop(GRACE).await;
        self.update_summary();
        if let Some(end) = end {
            self.summary.status = end.status().into();
        }
        self.summary.save(&self.run.out)?;
        let rows = self.curve.read()?;
        if !rows.is_empty() {
            let title = format!(
                "{} on {} ({} actors)",
                self.summary.action_set, self.summary.scenario, self.summary.actors
            );
            plot_curve(&self.run.out.join("curve.png"), &title, &rows)?;
        }
        let s = &self.summary;
        eprintln!(
            "run {} {}: {} updates, {} env steps, {:.1} min{}",
            self.run.out.display(),
            s.status,
            s.updates,
            s.env_steps,
            s.wall_seconds / 60.0,
            s.reached.as_ref().map_or(String::new(), |r| format!(
                "; target reached at {:.1} min, {} env steps ({} trials: {})",
                r.evaluation.wall_seconds / 60.0,
                r.evaluation.env_steps,
                r.evaluation.trials,
                r.evaluation.brief()
            ))
        );
        if let Some(b) = &s.best {
            eprintln!(
                "best weights: {} ({})",
                self.run.out.join("best").display(),
                b.brief()
            );
        }
        for (name, status) in [("learner", learner), ("replay", replay)] {
            if let Some(st) = status
                && !st.success()
            {
                tracing::warn!(role = name, status = %st, "did not stop cleanly; see its log");
            }
        }
        Ok(())
    }
}

/// Writes `safetensors` and `e` (as `evaluation.json`) into `dir`.
fn keep(dir: &Path, e: &Evaluation, safetensors: &[u8]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write_atomic(&dir.join("weights.safetensors"), safetensors)?;
    write_atomic(
        &dir.join("evaluation.json"),
        serde_json::to_string_pretty(e)?.as_bytes(),
    )
}

fn died(role: &Role, status: std::process::ExitStatus) -> anyhow::Error {
    anyhow::anyhow!(
        "{} exited ({status}); the end of {}:\n{}",
        role.name,
        role.log.display(),
        role.log_tail(20)
    )
}

/// Sums every sample of `name` in Prometheus text (0 when there is none).
pub fn sum_metric(text: &str, name: &str) -> f64 {
    let Ok(scrape) = prometheus_parse::Scrape::parse(text.lines().map(|l| Ok(l.to_owned()))) else {
        return 0.0;
    };
    scrape
        .samples
        .iter()
        .filter(|s| s.metric == name)
        .map(|s| match s.value {
            prometheus_parse::Value::Counter(v)
            | prometheus_parse::Value::Gauge(v)
            | prometheus_parse::Value::Untyped(v) => v,
            _ => 0.0,
        })
        .sum()
}

fn progress_bar(budget: u64) -> ProgressBar {
    let bar = if budget > 0 {
        ProgressBar::new(budget)
    } else {
        ProgressBar::new_spinner()
    };
    let template = if budget > 0 {
        "{spinner} [{elapsed_precise}] {wide_bar} {human_pos}/{human_len} updates ({per_sec}, ETA {eta}) {msg}"
    } else {
        "{spinner} [{elapsed_precise}] {human_pos} updates ({per_sec}) {msg}"
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style);
    }
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

/// A one-line description of this machine.
pub fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(0, std::num::NonZero::get);
    let model = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_owned())
        })
        .unwrap_or_default();
    format!("{cores} cores, {model}")
}

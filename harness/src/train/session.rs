//! A session of a run: the roles started in order (replay, learner,
//! actors), watched until the run ends, then stopped in order (actors, a
//! final evaluation, the learner's last checkpoint, the replay's last
//! snapshot), with the summary and the curve's picture written.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_common::Shutdown;
use crossroads_transport::grpc::ReplayClient;
use crossroads_transport::{ClientSecurity, LearnerClient};
use indicatif::ProgressBar;

use super::prepare::Run;
use super::procs::{Addresses, Launch, RoleChild, died, wait_ready};
use super::record::{Curve, RunStatus, Summary, TrainMetrics, plot_curve};
use crate::role;

/// Grace period for a role to stop after SIGTERM.
pub const GRACE: Duration = Duration::from_secs(60);

/// Why the run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum End {
    Budget,
    Minutes,
    Target,
    Signal,
}

impl End {
    fn status(self) -> RunStatus {
        match self {
            End::Budget | End::Minutes => RunStatus::Finished,
            End::Target => RunStatus::Target,
            End::Signal => RunStatus::Stopped,
        }
    }
}

/// The running session: roles, clients, records.
pub struct Session {
    pub run: Run,
    pub replay: RoleChild,
    pub learner: RoleChild,
    pub actors: Vec<RoleChild>,
    pub replay_client: ReplayClient,
    pub learner_client: LearnerClient,
    pub curve: Curve,
    pub metrics: TrainMetrics,
    pub summary: Summary,
    pub started: Instant,
    pub env_steps: u64,
    pub updates: u64,
    pub transitions: u64,
    pub loss: f64,
}

pub async fn train(run: Run) -> anyhow::Result<()> {
    let c = &run.config;
    tracing::info!(
        out = %run.out.display(),
        scenario = %c.sim.scenario,
        actions = %c.sim.action_set,
        observation = c.sim.observation().unwrap_or_default(),
        actors = c.actor.count,
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
    let mut addr = Addresses::new(&run.out, run.config.transport.tls.scheme());
    let logs = run.out.join("logs");
    let c = run.config.clone();
    let timeout = Duration::from_millis(c.transport.request_timeout_ms.min(10_000));
    let launch = Launch {
        exe: &exe,
        config: &config_path,
        logs: &logs,
        metrics: c.telemetry.metrics,
    };
    let mut replay = RoleChild::spawn(&launch, "replay", &["replay"], &addr.env())?;
    replay.await_metrics(&shutdown).await?;
    addr.replay = Some(replay.announced("listen", &shutdown).await?);
    let mut transport = c.transport.clone();
    transport.replay_endpoint = addr.replay_url();
    let security = ClientSecurity::load(&transport)?;
    let replay_client = ReplayClient::with_security(&transport, &security, &c.replay.table)?;
    wait_ready(&mut replay, &shutdown, false, || async {
        replay_client
            .info()
            .await
            .map(|_| ())
            .map_err(|e| e.to_string())
    })
    .await?;

    let learner = async {
        let mut learner = RoleChild::spawn(&launch, "learner", &["learner"], &addr.env())?;
        learner.await_metrics(&shutdown).await?;
        let listen = learner.announced("listen", &shutdown).await?;
        Ok::<_, anyhow::Error>((learner, listen))
    }
    .await;
    let (mut learner, listen) = match learner {
        Ok(started) => started,
        Err(e) => {
            replay.stop(GRACE).await;
            return Err(e);
        }
    };
    addr.learner = Some(listen);
    let learner_client = LearnerClient::new(&addr.learner_url(), &security, timeout)?;
    let ready = wait_ready(&mut learner, &shutdown, true, || async {
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
    for i in 0..c.actor.count {
        let mut env = addr.env();
        env.push(("CROSSROADS_ACTOR__INDEX".into(), i.to_string()));
        let name = format!("actor-{i}");
        actors.push(RoleChild::spawn(&launch, &name, &["actor"], &env)?);
    }
    // The actors' metrics ports are read as they announce them
    // (`Session::actor_steps`), not awaited: the watch's first evaluation,
    // of the weights the run starts from, comes before their first
    // transitions.
    let shown = |m: Option<SocketAddr>| m.map_or_else(|| "off".to_owned(), |a| a.to_string());
    tracing::info!(
        replay = %addr.replay_url(),
        learner = %addr.learner_url(),
        replay_metrics = %shown(replay.metrics),
        learner_metrics = %shown(learner.metrics),
        logs = %logs.display(),
        "roles started"
    );

    let mut summary = run.previous.clone();
    summary.scenario = c.sim.scenario.clone();
    summary.action_set = c.sim.action_set.clone();
    summary.observation = c.sim.observation().unwrap_or_default().to_owned();
    summary.actors = c.actor.count;
    summary.status = RunStatus::Running;
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
            s.summary.status = RunStatus::Failed;
            let _ = s.summary.save(&s.run.out);
            Err(e)
        }
        (Ok(_), Ok(())) => Ok(()),
    }
}

impl Session {
    /// Wall-clock seconds over all sessions of the run.
    pub fn wall(&self) -> f64 {
        self.run.previous.wall_seconds + self.started.elapsed().as_secs_f64()
    }

    /// An error naming the role that ended on its own (with its log's
    /// end); `true` when the learner ended at its update budget.
    pub fn check_roles(&mut self) -> anyhow::Result<bool> {
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

    /// Simulation steps of all actors, from their `/metrics`; logs their
    /// addresses once every actor has announced its own.
    pub async fn actor_steps(&mut self) -> u64 {
        let known = self.actors.iter().all(|a| a.metrics.is_some());
        let addrs: Vec<Option<SocketAddr>> =
            self.actors.iter_mut().map(RoleChild::metrics_now).collect();
        if !known && addrs.iter().all(Option::is_some) {
            tracing::info!(actor_metrics = ?addrs.iter().flatten().collect::<Vec<_>>(), "actors' metrics");
        }
        let mut total = 0.0;
        for a in addrs.into_iter().flatten() {
            if let Ok(text) = crossroads_common::metrics::scrape(a, Duration::from_secs(2)).await {
                total += sum_metric(&text, "crossroads_actor_env_steps_total");
            }
        }
        total as u64
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
            self.summary.status = end.status();
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

//! The training loop: one thread that owns the networks and the optimizer,
//! takes prefetched batches, updates, sends priorities, publishes weights
//! and writes checkpoints, and serves the commands of the gRPC service
//! (save, restore, evaluation reports) between updates.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_model::{Precision, Work, device_name, resolve_device};
use crossroads_transport::WeightsSlot;
use crossroads_transport::weights_shm::ShmWeightsPublisher;
use crossroads_types::Weights;
use parking_lot::Mutex;
use tokio::runtime::Handle;
use tokio::sync::{mpsc, oneshot};

use crate::LearnerError;
use crate::batch::TrainingBatch;
use crate::checkpoint::{CheckpointEntry, CheckpointStore, NewCheckpoint};
use crate::metrics::LearnerMetrics;
use crate::sampler::{NewPriorities, Prefetched};
use crate::trainer::{EarlyPhase, Trainer, TrainerConfig};

/// How often idle loops look for late shared-memory subscribers.
const CONNECT_EVERY: Duration = Duration::from_millis(200);

/// Requests from the gRPC service, answered between updates.
#[derive(Debug)]
pub enum LearnerCommand {
    /// Write a checkpoint now.
    Save(oneshot::Sender<Result<CheckpointEntry, LearnerError>>),
    /// Load a checkpoint and continue from it; answers with the checkpoint
    /// and the version its weights were published under.
    Restore(
        String,
        oneshot::Sender<Result<(CheckpointEntry, u64), LearnerError>>,
    ),
    /// Record an evaluation of a weights version.
    ReportEvaluation {
        /// Version evaluated.
        version: u64,
        /// Metric name -> value.
        metrics: BTreeMap<String, f64>,
        /// Answered once recorded.
        reply: oneshot::Sender<()>,
    },
}

/// Where training stands, for `Status`.
#[derive(Debug, Clone, Default)]
pub struct StatusView {
    /// Updates applied.
    pub update_step: u64,
    /// Latest published version.
    pub weights_version: u64,
    /// Latest loss.
    pub loss: f64,
    /// Latest mean Q.
    pub mean_q: f64,
    /// Updates per second over the last few seconds.
    pub updates_per_second: f64,
    /// Latest checkpoint id.
    pub latest_checkpoint: String,
}

/// State shared by the training thread and the gRPC service.
#[derive(Debug)]
pub struct Shared {
    /// The latest published weights, for the gRPC stream and
    /// `GetLatestWeights`.
    pub weights: WeightsSlot,
    /// Checkpoints, when enabled.
    pub store: Option<Arc<CheckpointStore>>,
    /// Training progress.
    pub status: Mutex<StatusView>,
    /// Commands to the training thread.
    pub commands: mpsc::Sender<LearnerCommand>,
    /// The run's configuration.
    pub config: Config,
    /// Metrics.
    pub metrics: LearnerMetrics,
    /// When the learner started.
    pub started: Instant,
    /// Updates applied, for the prefetcher's importance-sampling anneal.
    pub steps: Arc<AtomicU64>,
}

/// What the training thread needs besides the shared state.
#[derive(Debug)]
pub struct LoopInputs {
    /// Prefetched batches.
    pub batches: mpsc::Receiver<Prefetched>,
    /// Commands from the service.
    pub commands: mpsc::Receiver<LearnerCommand>,
    /// Priority updates to the replay.
    pub priorities: mpsc::Sender<NewPriorities>,
    /// Runtime for waiting on channels from this thread.
    pub handle: Handle,
    /// Stops the loop.
    pub shutdown: Shutdown,
}

fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// The training thread's state.
pub struct Learner {
    trainer: Trainer,
    shared: Arc<Shared>,
    shm: Option<ShmWeightsPublisher>,
    version: u64,
    /// Versions up to this are leased in the checkpoint folder.
    leased: u64,
    eval: (u64, BTreeMap<String, f64>),
    rate: (Instant, u64),
}

/// Versions leased at a time: one fsync per this many publications.
pub const VERSION_LEASE: u64 = 1024;

impl std::fmt::Debug for Learner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Learner")
            .field("step", &self.trainer.step())
            .field("version", &self.version)
            .finish_non_exhaustive()
    }
}

enum Event {
    Stop,
    Command(LearnerCommand),
    Batch(Option<Prefetched>),
    Tick,
}

impl Learner {
    /// Builds the networks on the device `runtime.device` resolves to
    /// (failing, naming what is missing, when `cuda` cannot be met),
    /// resumes from the newest checkpoint when asked (an unreadable one is
    /// skipped for the one before, with a warning), opens the
    /// shared-memory publisher and publishes the first weights. Runs on
    /// the training thread.
    pub fn new(shared: Arc<Shared>) -> Result<Self, LearnerError> {
        let config = &shared.config;
        let device = resolve_device(config.runtime.device)?;
        let mut trainer = Trainer::new_on(
            TrainerConfig::from_config(&config.sim, &config.learner)?,
            device,
        )?;
        let precision = Precision::choose_on(
            config.runtime.precision,
            &trainer.config().spec,
            Work::Training,
            device,
        );
        trainer.set_precision(precision);
        trainer.set_early_phase(EarlyPhase::from_config(&config.learner));
        tracing::info!(
            %precision,
            device = %device_name(device),
            runtime_device = config.runtime.device.name(),
            "learner network number format and device"
        );
        let shm = if config.learner.shm_publish {
            let bytes = trainer.online().to_safetensors(0)?.len();
            Some(
                ShmWeightsPublisher::new(&config.transport, bytes).map_err(|e| {
                    LearnerError::Shm(format!(
                        "{e} (set learner.shm_publish = false to publish over gRPC only)"
                    ))
                })?,
            )
        } else {
            None
        };
        let mut learner = Self {
            trainer,
            shared,
            shm,
            version: 0,
            leased: 0,
            eval: (0, BTreeMap::new()),
            rate: (Instant::now(), 0),
        };
        // Above every version a learner of this folder may have published,
        // whether or not it resumes (a kill -9 may have come after
        // publications its last checkpoint does not know of).
        if let Some(store) = &learner.shared.store {
            learner.leased = store.version_lease()?;
            learner.version = learner.leased;
        }
        if learner.shared.config.learner.resume {
            learner.resume()?;
        }
        learner.shared.status.lock().update_step = learner.trainer.step();
        learner
            .shared
            .steps
            .store(learner.trainer.step(), Ordering::Relaxed);
        learner.rate = (Instant::now(), learner.trainer.step());
        learner.publish()?;
        Ok(learner)
    }

    fn resume(&mut self) -> Result<(), LearnerError> {
        let Some(store) = self.shared.store.clone() else {
            return Ok(());
        };
        let entries = store.list()?;
        for entry in &entries {
            match store.load(entry.id()) {
                Ok(loaded) => {
                    if &loaded.manifest.network != self.trainer.online().spec() {
                        return Err(LearnerError::Config(format!(
                            "checkpoint {} in {} is of another network ({:?}) than learner.* asks for ({:?}); \
                             use another checkpoint_dir or set learner.resume = false",
                            entry.id(),
                            store.dir().display(),
                            loaded.manifest.network,
                            self.trainer.online().spec()
                        )));
                    }
                    self.trainer.restore(loaded.state)?;
                    self.version = self.version.max(loaded.manifest.weights_version);
                    self.eval = (
                        loaded.manifest.eval_weights_version,
                        loaded.manifest.eval_metrics.clone(),
                    );
                    self.shared.status.lock().latest_checkpoint = entry.id().to_owned();
                    self.mark_checkpoint_time(loaded.manifest.created_unix_ms);
                    tracing::info!(
                        checkpoint = entry.id(),
                        update_step = self.trainer.step(),
                        weights_version = self.version,
                        "resumed from checkpoint"
                    );
                    return Ok(());
                }
                Err(e) => {
                    tracing::warn!(checkpoint = entry.id(), error = %e, "cannot resume from checkpoint; trying the one before");
                }
            }
        }
        if !entries.is_empty() {
            return Err(LearnerError::Config(format!(
                "no checkpoint in {} can be loaded; move them away or set learner.resume = false",
                store.dir().display()
            )));
        }
        Ok(())
    }

    /// Updates applied.
    pub fn step(&self) -> u64 {
        self.trainer.step()
    }

    /// Latest published version.
    pub fn version(&self) -> u64 {
        self.version
    }

    /// Runs until shutdown, `max_updates` or an error; writes a last
    /// checkpoint (when enabled) however it ends.
    pub fn run(mut self, mut inputs: LoopInputs) -> Result<(), LearnerError> {
        let max_updates = self.shared.config.learner.max_updates;
        let mut waiting_since = Instant::now();
        let mut connected = Instant::now();
        let result = loop {
            if max_updates > 0 && self.trainer.step() >= max_updates {
                tracing::info!(max_updates, "reached learner.max_updates");
                break Ok(());
            }
            let event = inputs.handle.block_on(async {
                tokio::select! {
                    biased;
                    _ = inputs.shutdown.wait() => Event::Stop,
                    Some(c) = inputs.commands.recv() => Event::Command(c),
                    b = inputs.batches.recv() => Event::Batch(b),
                    _ = tokio::time::sleep(CONNECT_EVERY) => Event::Tick,
                }
            });
            match event {
                Event::Stop => break Ok(()),
                Event::Tick => {}
                Event::Command(c) => self.handle(c),
                Event::Batch(None) => break Err(LearnerError::Stopped),
                Event::Batch(Some(Err(e))) => break Err(e),
                Event::Batch(Some(Ok(batch))) => {
                    let waited = waiting_since.elapsed();
                    if let Err(e) = self.step_on(batch, waited, &inputs.priorities) {
                        break Err(e);
                    }
                    waiting_since = Instant::now();
                }
            }
            if let Some(shm) = &self.shm
                && connected.elapsed() >= CONNECT_EVERY
            {
                shm.update_connections();
                connected = Instant::now();
            }
        };
        if let Err(e) = &result {
            tracing::error!(error = %e, "training stopped");
        }
        if self.shared.store.is_some() {
            match self.save() {
                Ok(entry) => tracing::info!(checkpoint = entry.id(), "wrote the last checkpoint"),
                Err(e) => tracing::error!(error = %e, "writing the last checkpoint"),
            }
        }
        result
    }

    /// One training step on a prefetched batch: the update (targets under
    /// no_grad, loss, optimizer step, target update; see
    /// [`Trainer::update`]), then the priority update, then publication and
    /// checkpoint on their schedules.
    pub fn step_on(
        &mut self,
        batch: TrainingBatch,
        waited: Duration,
        priorities: &mpsc::Sender<NewPriorities>,
    ) -> Result<(), LearnerError> {
        let m = &self.shared.metrics;
        m.sample_wait.observe(waited.as_secs_f64());
        m.sample_wait_total.inc_by(waited.as_secs_f64());

        let started = Instant::now();
        let stats = self.trainer.update(&batch)?;
        m.update_seconds_total
            .inc_by(started.elapsed().as_secs_f64());

        let update = NewPriorities {
            keys: batch.keys,
            priorities: stats.priorities,
        };
        if priorities.try_send(update).is_err() {
            m.priority_updates_dropped.inc();
        }

        self.shared.steps.store(stats.step, Ordering::Relaxed);
        m.updates.inc();
        m.loss.set(stats.loss);
        m.q_mean.set(stats.q_mean);
        m.q_max.set(stats.q_max);
        m.td_error.set(stats.td_abs_mean);
        m.grad_norm.set(stats.grad_norm);
        {
            let mut status = self.shared.status.lock();
            status.update_step = stats.step;
            status.loss = stats.loss;
            status.mean_q = stats.q_mean;
            let (since, at) = self.rate;
            let elapsed = since.elapsed().as_secs_f64();
            if elapsed >= 2.0 {
                status.updates_per_second = (stats.step - at) as f64 / elapsed;
                self.rate = (Instant::now(), stats.step);
            }
        }

        let (publish_every, checkpoint_every) = {
            let c = &self.shared.config.learner;
            (c.publish_every, c.checkpoint_every)
        };
        if stats.step.is_multiple_of(publish_every) {
            self.publish()?;
        }
        if checkpoint_every > 0
            && stats.step.is_multiple_of(checkpoint_every)
            && self.shared.store.is_some()
        {
            // A failed periodic checkpoint (disk full, say) must not stop
            // training; the next one may succeed.
            if let Err(e) = self.save() {
                tracing::error!(error = %e, "writing a checkpoint");
            }
        }
        Ok(())
    }

    /// Publishes the online network under the next version. With a
    /// checkpoint folder, versions are leased there first, a block at a
    /// time ([`VERSION_LEASE`]), so a learner killed at any moment restarts
    /// above every version it published; when the lease cannot be written
    /// (a full disk), nothing is published and the error is returned.
    pub fn publish(&mut self) -> Result<(), LearnerError> {
        let version = self.version + 1;
        if let Some(store) = &self.shared.store
            && version > self.leased
        {
            let upto = version + VERSION_LEASE;
            store.lease_versions(upto)?;
            self.leased = upto;
        }
        let weights = Weights {
            version,
            update_step: self.trainer.step(),
            published_unix_ms: now_ms(),
            spec: self.trainer.online().spec().clone(),
            safetensors: self.trainer.online().to_safetensors(version)?,
        };
        if let Some(shm) = &mut self.shm
            && let Err(e) = shm.publish(&weights)
        {
            tracing::warn!(error = %e, "publishing weights over shared memory");
        }
        self.shared.weights.offer(weights);
        self.version = version;
        self.shared.metrics.weights_version.set(version as i64);
        self.shared.metrics.weights_published.inc();
        self.shared.status.lock().weights_version = version;
        Ok(())
    }

    fn mark_checkpoint_time(&self, unix_ms: i64) {
        let t = unix_ms as f64 / 1000.0;
        self.shared.metrics.checkpoint_time.set(t);
        self.shared
            .metrics
            .refresh_checkpoint_age(now_ms() as f64 / 1000.0);
    }

    /// Writes a checkpoint of the current state.
    pub fn save(&mut self) -> Result<CheckpointEntry, LearnerError> {
        let store = self
            .shared
            .store
            .clone()
            .ok_or(LearnerError::NoCheckpoints)?;
        let state = self.trainer.state(self.version)?;
        let config = &self.shared.config;
        let entry = store.write(&NewCheckpoint {
            state: &state,
            weights_version: self.version,
            scenario: &config.sim.scenario,
            network: self.trainer.online().spec(),
            optimizer: self.trainer.config().optimizer.name(),
            eval_metrics: &self.eval.1,
            eval_weights_version: self.eval.0,
            config: &config.to_toml(),
        })?;
        self.shared.metrics.checkpoints.inc();
        self.mark_checkpoint_time(entry.manifest.created_unix_ms);
        self.shared.status.lock().latest_checkpoint = entry.id().to_owned();
        tracing::info!(
            checkpoint = entry.id(),
            update_step = state.step,
            weights_version = self.version,
            "checkpoint written"
        );
        Ok(entry)
    }

    /// Loads checkpoint `id` and continues from it; its weights are
    /// published under a version above every earlier one.
    pub fn restore(&mut self, id: &str) -> Result<(CheckpointEntry, u64), LearnerError> {
        let store = self
            .shared
            .store
            .clone()
            .ok_or(LearnerError::NoCheckpoints)?;
        let entry = store.entry(id)?;
        let loaded = store.load(id)?;
        if &loaded.manifest.network != self.trainer.online().spec() {
            return Err(LearnerError::Model(
                crossroads_model::ModelError::SpecMismatch {
                    expected: Box::new(self.trainer.online().spec().clone()),
                    got: Box::new(loaded.manifest.network.clone()),
                },
            ));
        }
        self.trainer.restore(loaded.state)?;
        self.shared
            .steps
            .store(self.trainer.step(), Ordering::Relaxed);
        self.version = self.version.max(loaded.manifest.weights_version);
        self.eval = (
            loaded.manifest.eval_weights_version,
            loaded.manifest.eval_metrics.clone(),
        );
        self.publish()?;
        {
            let mut status = self.shared.status.lock();
            status.update_step = self.trainer.step();
            status.latest_checkpoint = id.to_owned();
        }
        self.rate = (Instant::now(), self.trainer.step());
        tracing::info!(
            checkpoint = id,
            update_step = self.trainer.step(),
            weights_version = self.version,
            "restored checkpoint"
        );
        Ok((entry, self.version))
    }

    fn handle(&mut self, command: LearnerCommand) {
        match command {
            LearnerCommand::Save(reply) => {
                let _ = reply.send(self.save());
            }
            LearnerCommand::Restore(id, reply) => {
                let _ = reply.send(self.restore(&id));
            }
            LearnerCommand::ReportEvaluation {
                version,
                metrics,
                reply,
            } => {
                tracing::info!(version, ?metrics, "evaluation reported");
                self.eval = (version, metrics);
                let _ = reply.send(());
            }
        }
    }
}

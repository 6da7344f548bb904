//! Starting and stopping the learner: the training thread, the replay
//! conversations, the gRPC service, all under one [`Shutdown`].
//!
//! [`start`] builds the networks (resuming from the newest checkpoint when
//! asked), publishes the first weights, binds the gRPC address (port 0
//! picks a free one) and returns a [`RunningLearner`];
//! [`RunningLearner::join`] waits for the stop: on shutdown (or
//! `learner.max_updates`) the training thread finishes its update and
//! writes the last checkpoint, and the gRPC server drains.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::AtomicU64;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crossroads_common::{Backoff, Shutdown};
use crossroads_config::{Config, LearnerConfig};
use crossroads_model::NetworkSpec;
use crossroads_proto::v1::learner_server::LearnerServer;
use crossroads_transport::auth::LEARNER_OPEN_CALLS;
use crossroads_transport::grpc::ReplayClient;
use crossroads_transport::security::SecuredServer;
use crossroads_transport::{ClientSecurity, ServerSecurity, WeightsSlot};
use parking_lot::Mutex;
use prometheus::Registry;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;
use tokio_stream::wrappers::TcpListenerStream;

use crate::LearnerError;
use crate::checkpoint::CheckpointStore;
use crate::metrics::LearnerMetrics;
use crate::sampler::{
    BetaSchedule, NewPriorities, PrefetchConfig, Prefetched, spawn_prefetch, spawn_priority_sender,
};
use crate::service::LearnerService;
use crate::trainer::TrainerConfig;
use crate::training::{Learner, LoopInputs, Shared, StatusView};

/// Priority updates queued for the sender before new ones are dropped.
const PRIORITY_QUEUE: usize = 64;

/// Longest the gRPC server may take to drain after shutdown before its
/// connections are dropped (a weights subscriber that stopped reading
/// would otherwise hold it open for good).
const DRAIN: Duration = Duration::from_secs(10);

/// A started learner.
#[derive(Debug)]
pub struct RunningLearner {
    addr: SocketAddr,
    shared: Arc<Shared>,
    stop: Shutdown,
    task: JoinHandle<Result<(), LearnerError>>,
}

impl RunningLearner {
    /// The gRPC address actually bound.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Where training stands now.
    pub fn status(&self) -> StatusView {
        self.shared.status.lock().clone()
    }

    /// The learner's metrics.
    pub fn metrics(&self) -> &LearnerMetrics {
        &self.shared.metrics
    }

    /// Stops this learner alone (the shutdown given to [`start`] also
    /// stops it).
    pub fn stop(&self) {
        self.stop.trigger();
    }

    /// Waits until the learner has stopped and written its last
    /// checkpoint; returns the error that stopped training, if any.
    pub async fn join(self) -> Result<(), LearnerError> {
        let joined = self.task.await;
        joined.unwrap_or_else(|e| Err(LearnerError::Serve(format!("learner task failed: {e}"))))
    }
}

/// Starts the learner `config.learner` describes, sampling from
/// `config.transport.replay_endpoint`, with its metrics in `registry` when
/// given. Must be called inside a multi-threaded tokio runtime.
///
/// In order: the checkpoint store, the state the training thread and the
/// service share, the gRPC listener, the replay conversations (prefetcher
/// and priority sender), the training thread (which builds the networks
/// and publishes the first weights before this returns), the
/// checkpoint-age refresher and the gRPC server.
pub async fn start(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<RunningLearner, LearnerError> {
    let lc = &config.learner;
    // TLS files and token first: a missing file stops the start at once.
    let security = ServerSecurity::load(&config.transport)?;
    let server = security.builder(LEARNER_OPEN_CALLS)?;
    let client_security = ClientSecurity::load(&config.transport)?;
    let spec = TrainerConfig::from_config(&config.sim, lc)?.spec;
    // The device before anything is bound: `runtime.device = "cuda"`
    // without CUDA stops the start here, naming what is missing (the
    // training thread resolves it again when it builds the networks).
    crossroads_model::resolve_device(config.runtime.device)?;
    if let Some(n) = config.runtime.torch_threads() {
        tch::set_num_threads(n as i32);
    }
    let metrics = LearnerMetrics::new(registry)?;
    let store = open_store(lc)?;
    // The learner stops on the caller's shutdown, or alone (max_updates,
    // a fatal error, RunningLearner::stop).
    let stop = shutdown.child();
    let (commands_tx, commands) = mpsc::channel(16);
    let shared = Arc::new(Shared {
        weights: WeightsSlot::new(),
        store,
        status: Mutex::new(StatusView::default()),
        commands: commands_tx,
        config: config.clone(),
        metrics: metrics.clone(),
        started: Instant::now(),
        steps: Arc::new(AtomicU64::new(0)),
    });
    let (listener, addr) = bind(lc.listen).await?;
    let replay = start_replay_conversations(config, &client_security, spec, &shared, &stop)?;
    let inputs = LoopInputs {
        batches: replay.batches,
        commands,
        priorities: replay.priorities,
        handle: tokio::runtime::Handle::current(),
        shutdown: stop.clone(),
    };
    let trained = start_training(Arc::clone(&shared), inputs, config, &stop).await?;
    let age_task = spawn_checkpoint_age(metrics, stop.clone());
    let served = serve(server, listener, Arc::clone(&shared), stop.clone());
    tracing::info!(
        %addr,
        tls = security.tls(),
        client_certificates = security.client_certificates(),
        token = security.token(),
        replay = %config.transport.replay_endpoint,
        observation = config.sim.observation().unwrap_or("unresolved"),
        action_set = %config.sim.action_set,
        "learner listening"
    );

    let (prefetch_task, priority_task) = replay.tasks;
    let drained = stop.clone();
    let task = tokio::spawn(async move {
        let served = tokio::select! {
            r = served => r.map_err(|e| LearnerError::Serve(e.to_string())),
            _ = async { drained.wait().await; tokio::time::sleep(DRAIN).await } => {
                tracing::warn!("gRPC connections did not drain in {DRAIN:?}; dropping them");
                Ok(())
            }
        };
        let trained = trained.await.unwrap_or(Err(LearnerError::Stopped));
        let _ = tokio::join!(prefetch_task, priority_task, age_task);
        trained.and(served)
    });
    Ok(RunningLearner {
        addr,
        shared,
        stop,
        task,
    })
}

/// The checkpoint store `learner.checkpoint_dir` names, if any.
fn open_store(lc: &LearnerConfig) -> Result<Option<Arc<CheckpointStore>>, LearnerError> {
    let Some(dir) = &lc.checkpoint_dir else {
        tracing::warn!("learner.checkpoint_dir is not set: no checkpoints will be written");
        return Ok(None);
    };
    let store = CheckpointStore::open(dir.clone(), lc.checkpoint_keep as usize, &lc.best_metric)?;
    Ok(Some(Arc::new(store)))
}

/// The gRPC listener on `listen` (port 0 picks a free one) and the address
/// it got.
async fn bind(listen: SocketAddr) -> Result<(TcpListener, SocketAddr), LearnerError> {
    let failed = |e: std::io::Error| LearnerError::Serve(format!("cannot listen on {listen}: {e}"));
    let listener = TcpListener::bind(listen).await.map_err(failed)?;
    let addr = listener.local_addr().map_err(failed)?;
    Ok((listener, addr))
}

/// The learner's side of the replay: prefetched batches in, priority
/// updates out, and the two tasks behind them.
struct ReplayConversations {
    batches: mpsc::Receiver<Prefetched>,
    priorities: mpsc::Sender<NewPriorities>,
    tasks: (JoinHandle<()>, JoinHandle<()>),
}

/// Starts the prefetcher (sampled batches of `spec`'s network, beta
/// following the training thread's step) and the priority sender.
fn start_replay_conversations(
    config: &Config,
    security: &ClientSecurity,
    spec: NetworkSpec,
    shared: &Shared,
    stop: &Shutdown,
) -> Result<ReplayConversations, LearnerError> {
    let lc = &config.learner;
    let client = ReplayClient::with_security(&config.transport, security, &config.replay.table)?;
    let (batches, prefetch_task) = spawn_prefetch(
        client.clone(),
        PrefetchConfig {
            batch_size: lc.batch_size,
            beta: BetaSchedule::from_config(lc),
            steps: Arc::clone(&shared.steps),
            depth: lc.prefetch as usize,
            spec,
        },
        Backoff::from_config(&config.transport),
        shared.metrics.clone(),
        stop.clone(),
    );
    let (priorities, priority_task) =
        spawn_priority_sender(client, PRIORITY_QUEUE, shared.metrics.clone(), stop.clone());
    Ok(ReplayConversations {
        batches,
        priorities,
        tasks: (prefetch_task, priority_task),
    })
}

/// Starts the training thread and waits until it has built the networks
/// (the shared-memory publisher must live on the thread that uses it) and
/// published the first weights; the receiver answers with how training
/// ended. The thread fires `stop` when it ends.
async fn start_training(
    shared: Arc<Shared>,
    inputs: LoopInputs,
    config: &Config,
    stop: &Shutdown,
) -> Result<oneshot::Receiver<Result<(), LearnerError>>, LearnerError> {
    let (ready_tx, ready_rx) = oneshot::channel();
    let (done_tx, done_rx) = oneshot::channel();
    let thread_stop = stop.clone();
    let threads = config.runtime.learner_torch_threads();
    std::thread::Builder::new()
        .name("learner".to_owned())
        .spawn(move || {
            // libtorch's OpenMP thread count is per calling thread; set it
            // on the thread that trains.
            if let Some(n) = threads {
                tch::set_num_threads(n as i32);
            }
            tracing::debug!(
                torch_threads = tch::get_num_threads(),
                "training thread started"
            );
            let learner = match Learner::new(shared) {
                Ok(l) => {
                    let _ = ready_tx.send(Ok(()));
                    l
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(e));
                    return;
                }
            };
            let result = learner.run(inputs);
            thread_stop.trigger();
            let _ = done_tx.send(result);
        })
        .map_err(|e| LearnerError::Serve(format!("cannot start the training thread: {e}")))?;
    match ready_rx.await {
        Ok(Ok(())) => Ok(done_rx),
        Ok(Err(e)) => {
            stop.trigger();
            Err(e)
        }
        Err(_) => {
            stop.trigger();
            Err(LearnerError::Stopped)
        }
    }
}

/// Refreshes `crossroads_learner_checkpoint_age_seconds` every second
/// until `stop`.
fn spawn_checkpoint_age(metrics: LearnerMetrics, stop: Shutdown) -> JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            let now = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs_f64())
                .unwrap_or(0.0);
            metrics.refresh_checkpoint_age(now);
            tokio::select! {
                _ = stop.wait() => break,
                _ = tokio::time::sleep(Duration::from_secs(1)) => {}
            }
        }
    })
}

/// The gRPC server on `listener` until `stop` (then it drains).
fn serve(
    mut server: SecuredServer,
    listener: TcpListener,
    shared: Arc<Shared>,
    stop: Shutdown,
) -> impl Future<Output = Result<(), tonic::transport::Error>> {
    let service = LearnerServer::new(LearnerService::new(shared, stop.clone()))
        .max_decoding_message_size(16 << 20)
        .max_encoding_message_size(usize::MAX);
    server
        .add_service(service)
        .serve_with_incoming_shutdown(TcpListenerStream::new(listener), async move {
            stop.wait().await
        })
}

/// Runs the learner until `shutdown` fires (or `learner.max_updates`).
pub async fn run(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<(), LearnerError> {
    start(config, registry, shutdown).await?.join().await
}

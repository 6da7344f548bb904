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

use crossroads_config::Config;
use crossroads_common::{Backoff, Shutdown};
use crossroads_proto::v1::learner_server::LearnerServer;
use crossroads_transport::WeightsSlot;
use crossroads_transport::grpc::ReplayClient;
use parking_lot::Mutex;
use prometheus::Registry;
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;
use tokio_stream::wrappers::TcpListenerStream;

use crate::LearnerError;
use crate::checkpoint::CheckpointStore;
use crate::metrics::LearnerMetrics;
use crate::sampler::{BetaSchedule, PrefetchConfig, spawn_prefetch, spawn_priority_sender};
use crate::service::LearnerService;
use crate::trainer::TrainerConfig;
use crate::training::{Learner, LoopInputs, Shared, StatusView};

/// Priority updates queued for the sender before new ones are dropped.
const PRIORITY_QUEUE: usize = 64;

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
        match self.task.await {
            Ok(r) => r,
            Err(e) => Err(LearnerError::Serve(format!("learner task failed: {e}"))),
        }
    }
}

/// Starts the learner `config.learner` describes, sampling from
/// `config.transport.replay_endpoint`, with its metrics in `registry` when
/// given. Must be called inside a multi-threaded tokio runtime.
pub async fn start(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<RunningLearner, LearnerError> {
    let lc = &config.learner;
    let spec = TrainerConfig::from_config(lc)?.spec;
    if config.runtime.compute_threads > 0 {
        tch::set_num_threads(config.runtime.compute_threads as i32);
    }
    let metrics = LearnerMetrics::new(registry)?;
    let store = match &lc.checkpoint_dir {
        Some(dir) => Some(Arc::new(CheckpointStore::open(
            dir.clone(),
            lc.checkpoint_keep as usize,
            &lc.best_metric,
        )?)),
        None => {
            tracing::warn!("learner.checkpoint_dir is not set: no checkpoints will be written");
            None
        }
    };
    // The learner stops on the caller's shutdown, or alone (max_updates,
    // a fatal error, RunningLearner::stop).
    let stop = shutdown.child();
    let (commands_tx, commands_rx) = mpsc::channel(16);
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

    let listener = TcpListener::bind(lc.listen)
        .await
        .map_err(|e| LearnerError::Serve(format!("cannot listen on {}: {e}", lc.listen)))?;
    let addr = listener
        .local_addr()
        .map_err(|e| LearnerError::Serve(format!("cannot listen on {}: {e}", lc.listen)))?;

    let client = ReplayClient::new(&config.transport, &config.replay.table)?;
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
        metrics.clone(),
        stop.clone(),
    );
    let (priorities, priority_task) =
        spawn_priority_sender(client, PRIORITY_QUEUE, metrics.clone(), stop.clone());

    // The training thread builds the networks itself (the shared-memory
    // publisher must live on the thread that uses it) and reports back.
    let (ready_tx, ready_rx) = oneshot::channel();
    let (done_tx, done_rx) = oneshot::channel();
    let inputs = LoopInputs {
        batches,
        commands: commands_rx,
        priorities,
        handle: tokio::runtime::Handle::current(),
        shutdown: stop.clone(),
    };
    let thread_shared = shared.clone();
    let thread_stop = stop.clone();
    let threads = config.runtime.compute_threads;
    std::thread::Builder::new()
        .name("learner".to_owned())
        .spawn(move || {
            // libtorch's OpenMP thread count is per calling thread; set it
            // on the thread that trains.
            if threads > 0 {
                tch::set_num_threads(threads as i32);
            }
            tracing::debug!(
                torch_threads = tch::get_num_threads(),
                "training thread started"
            );
            let learner = match Learner::new(thread_shared) {
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
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            stop.trigger();
            return Err(e);
        }
        Err(_) => {
            stop.trigger();
            return Err(LearnerError::Stopped);
        }
    }

    let age_metrics = metrics.clone();
    let age_stop = stop.clone();
    let age_task = tokio::spawn(async move {
        loop {
            let now = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs_f64())
                .unwrap_or(0.0);
            age_metrics.refresh_checkpoint_age(now);
            tokio::select! {
                _ = age_stop.wait() => break,
                _ = tokio::time::sleep(Duration::from_secs(1)) => {}
            }
        }
    });

    let service = LearnerServer::new(LearnerService::new(shared.clone(), stop.clone()))
        .max_decoding_message_size(16 << 20)
        .max_encoding_message_size(usize::MAX);
    let serve = tonic::transport::Server::builder()
        .tcp_nodelay(true)
        .add_service(service)
        .serve_with_incoming_shutdown(TcpListenerStream::new(listener), {
            let stop = stop.clone();
            async move { stop.wait().await }
        });
    let l = &config.learner;
    tracing::info!(
        %addr,
        replay = %config.transport.replay_endpoint,
        observation = %l.observation,
        action_set = %l.action_set,
        "learner listening"
    );

    let task = tokio::spawn(async move {
        let served = serve.await.map_err(|e| LearnerError::Serve(e.to_string()));
        let trained = done_rx.await.unwrap_or(Err(LearnerError::Stopped));
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

/// Runs the learner until `shutdown` fires (or `learner.max_updates`).
pub async fn run(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<(), LearnerError> {
    start(config, registry, shutdown).await?.join().await
}

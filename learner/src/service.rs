//! The tonic `Learner` service: weights (stream and latest), checkpoints
//! (list, get streamed, save, restore, delete), status and evaluation
//! reports. Converts and validates at the boundary; the token that
//! state-changing calls need is checked before them, by the server's
//! `crossroads_transport::security::TokenLayer`.
//!
//! The weights stream sends a subscriber the newest version, skipping any
//! it fell behind on. Checkpoint files stream in chunks of 256 KiB;
//! an invalid id answers INVALID_ARGUMENT, an unknown one NOT_FOUND.

use std::collections::BTreeMap;
use std::io::Read;
use std::pin::Pin;
use std::sync::Arc;

use crossroads_common::Shutdown;
use crossroads_proto::v1 as pb;
use crossroads_transport::convert::{CheckpointSummary, checkpoint_to_wire, weights_to_wire};
use tokio::sync::{mpsc, oneshot};
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status};

use crate::LearnerError;
use crate::checkpoint::{CheckpointStore, StoreError};
use crate::training::{LearnerCommand, Shared};

/// Bytes per `CheckpointChunk`.
const CHUNK_BYTES: usize = 256 << 10;

type ResponseStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

/// The service; cheap to clone.
#[derive(Debug, Clone)]
pub(crate) struct LearnerService {
    shared: Arc<Shared>,
    shutdown: Shutdown,
}

impl LearnerService {
    /// A service over the learner's shared state.
    pub(crate) fn new(shared: Arc<Shared>, shutdown: Shutdown) -> Self {
        Self { shared, shutdown }
    }

    fn store(&self) -> Result<Arc<CheckpointStore>, Status> {
        self.shared
            .store
            .clone()
            .ok_or_else(|| to_status(LearnerError::NoCheckpoints))
    }

    async fn command<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<T>) -> LearnerCommand,
    ) -> Result<T, Status> {
        let (tx, rx) = oneshot::channel();
        self.shared
            .commands
            .send(make(tx))
            .await
            .map_err(|_| to_status(LearnerError::Stopped))?;
        rx.await.map_err(|_| to_status(LearnerError::Stopped))
    }
}

/// The gRPC status of a learner error.
fn to_status(e: LearnerError) -> Status {
    let message = e.to_string();
    match e {
        LearnerError::Store(StoreError::InvalidId { .. }) => Status::invalid_argument(message),
        LearnerError::Store(StoreError::NotFound(_)) => Status::not_found(message),
        LearnerError::Store(StoreError::Corrupt { .. }) => Status::data_loss(message),
        LearnerError::Store(StoreError::Io { .. }) => Status::internal(message),
        LearnerError::NoCheckpoints => Status::failed_precondition(message),
        LearnerError::Model(crossroads_model::ModelError::SpecMismatch { .. }) => {
            Status::failed_precondition(message)
        }
        LearnerError::Stopped => Status::unavailable(message),
        _ => Status::internal(message),
    }
}

fn store_status(e: StoreError) -> Status {
    to_status(LearnerError::Store(e))
}

async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, StoreError> + Send + 'static,
) -> Result<T, Status> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| Status::internal(format!("checkpoint task failed: {e}")))?
        .map_err(store_status)
}

#[tonic::async_trait]
impl pb::learner_server::Learner for LearnerService {
    type SubscribeWeightsStream = ResponseStream<pb::Weights>;
    type GetCheckpointStream = ResponseStream<pb::CheckpointChunk>;

    async fn subscribe_weights(
        &self,
        request: Request<pb::SubscribeWeightsRequest>,
    ) -> Result<Response<Self::SubscribeWeightsStream>, Status> {
        let mut have = request.into_inner().have_version;
        let mut watch = self.shared.weights.watch();
        let (tx, out) = mpsc::channel(2);
        let shutdown = self.shutdown.clone();
        let subscribers = self.shared.metrics.weight_subscribers.clone();
        subscribers.inc();
        tokio::spawn(async move {
            loop {
                if let Some(w) = watch.newer_than(have) {
                    have = w.version;
                    // A subscriber that stops reading must not hold the
                    // server's graceful shutdown open.
                    let sent = tokio::select! {
                        sent = tx.send(Ok(weights_to_wire(&w))) => sent.is_ok(),
                        _ = shutdown.wait() => false,
                    };
                    if !sent {
                        break;
                    }
                }
                tokio::select! {
                    changed = watch.changed() => if !changed { break },
                    _ = shutdown.wait() => break,
                    _ = tx.closed() => break,
                }
            }
            subscribers.dec();
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(out))))
    }

    async fn get_latest_weights(
        &self,
        _request: Request<pb::GetLatestWeightsRequest>,
    ) -> Result<Response<pb::Weights>, Status> {
        self.shared
            .weights
            .latest()
            .map(|w| Response::new(weights_to_wire(&w)))
            .ok_or_else(|| Status::not_found("no weights published yet"))
    }

    async fn list_checkpoints(
        &self,
        _request: Request<pb::ListCheckpointsRequest>,
    ) -> Result<Response<pb::ListCheckpointsResponse>, Status> {
        let store = self.store()?;
        let entries = blocking(move || store.list()).await?;
        Ok(Response::new(pb::ListCheckpointsResponse {
            checkpoints: entries
                .iter()
                .map(|e| checkpoint_to_wire(&CheckpointSummary::from(e)))
                .collect(),
        }))
    }

    async fn get_checkpoint(
        &self,
        request: Request<pb::GetCheckpointRequest>,
    ) -> Result<Response<Self::GetCheckpointStream>, Status> {
        let id = request.into_inner().id;
        let store = self.store()?;
        let entry = {
            let (store, id) = (store.clone(), id.clone());
            blocking(move || store.entry(&id)).await?
        };
        let info = checkpoint_to_wire(&CheckpointSummary::from(&entry));
        let (tx, out) = mpsc::channel(4);
        tokio::task::spawn_blocking(move || {
            let first = pb::CheckpointChunk {
                info: Some(info),
                ..Default::default()
            };
            if tx.blocking_send(Ok(first)).is_err() {
                return;
            }
            for name in entry.files() {
                if let Err(status) = stream_file(&store, &id, &name, &tx) {
                    let _ = tx.blocking_send(Err(status));
                    return;
                }
            }
        });
        Ok(Response::new(Box::pin(ReceiverStream::new(out))))
    }

    async fn save_checkpoint(
        &self,
        _request: Request<pb::SaveCheckpointRequest>,
    ) -> Result<Response<pb::CheckpointInfo>, Status> {
        self.store()?;
        let entry = self
            .command(LearnerCommand::Save)
            .await?
            .map_err(to_status)?;
        Ok(Response::new(checkpoint_to_wire(&CheckpointSummary::from(
            &entry,
        ))))
    }

    async fn restore_checkpoint(
        &self,
        request: Request<pb::RestoreCheckpointRequest>,
    ) -> Result<Response<pb::RestoreCheckpointResponse>, Status> {
        let id = request.into_inner().id;
        let store = self.store()?;
        {
            let id = id.clone();
            blocking(move || store.resolve(&id)).await?;
        }
        let (entry, version) = self
            .command(|reply| LearnerCommand::Restore(id, reply))
            .await?
            .map_err(to_status)?;
        Ok(Response::new(pb::RestoreCheckpointResponse {
            checkpoint: Some(checkpoint_to_wire(&CheckpointSummary::from(&entry))),
            weights_version: version,
        }))
    }

    async fn delete_checkpoint(
        &self,
        request: Request<pb::DeleteCheckpointRequest>,
    ) -> Result<Response<pb::DeleteCheckpointResponse>, Status> {
        let id = request.into_inner().id;
        let store = self.store()?;
        blocking(move || store.delete(&id)).await?;
        Ok(Response::new(pb::DeleteCheckpointResponse {}))
    }

    async fn status(
        &self,
        _request: Request<pb::StatusRequest>,
    ) -> Result<Response<pb::LearnerStatus>, Status> {
        let s = self.shared.status.lock().clone();
        let config = &self.shared.config;
        Ok(Response::new(pb::LearnerStatus {
            update_step: s.update_step,
            weights_version: s.weights_version,
            loss: s.loss,
            mean_q: s.mean_q,
            updates_per_second: s.updates_per_second,
            uptime_seconds: self.shared.started.elapsed().as_secs_f64(),
            scenario: config.sim.scenario.clone(),
            latest_checkpoint: s.latest_checkpoint,
            config_toml: config.to_toml(),
        }))
    }

    async fn report_evaluation(
        &self,
        request: Request<pb::ReportEvaluationRequest>,
    ) -> Result<Response<pb::ReportEvaluationResponse>, Status> {
        let r = request.into_inner();
        if r.metrics.is_empty() {
            return Err(Status::invalid_argument("metrics: empty"));
        }
        if let Some((k, v)) = r.metrics.iter().find(|(_, v)| !v.is_finite()) {
            return Err(Status::invalid_argument(format!(
                "metrics[{k:?}]: {v} is not finite"
            )));
        }
        let metrics: BTreeMap<String, f64> = r.metrics.into_iter().collect();
        self.command(|reply| LearnerCommand::ReportEvaluation {
            version: r.weights_version,
            metrics,
            reply,
        })
        .await?;
        Ok(Response::new(pb::ReportEvaluationResponse {}))
    }
}

fn stream_file(
    store: &CheckpointStore,
    id: &str,
    name: &str,
    tx: &mpsc::Sender<Result<pb::CheckpointChunk, Status>>,
) -> Result<(), Status> {
    let path = store.file_path(id, name).map_err(store_status)?;
    let mut file = std::fs::File::open(&path)
        .map_err(|e| Status::internal(format!("opening {}: {e}", path.display())))?;
    let mut offset = 0u64;
    let mut buf = vec![0u8; CHUNK_BYTES];
    loop {
        let mut filled = 0;
        while filled < buf.len() {
            match file.read(&mut buf[filled..]) {
                Ok(0) => break,
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(Status::internal(format!("reading {}: {e}", path.display())));
                }
            }
        }
        let end_of_file = filled < buf.len();
        let chunk = pb::CheckpointChunk {
            info: None,
            file: name.to_owned(),
            offset,
            data: buf[..filled].to_vec(),
            end_of_file,
        };
        offset += filled as u64;
        if tx.blocking_send(Ok(chunk)).is_err() {
            // The caller went away.
            return Ok(());
        }
        if end_of_file {
            return Ok(());
        }
    }
}

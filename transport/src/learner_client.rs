//! [`LearnerClient`]: the learner service's client, for `crossroads
//! checkpoints`, `crossroads train` (status, evaluations) and for actors
//! (weights). It answers in domain types ([`LearnerStatus`], [`Weights`],
//! [`CheckpointSummary`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crossroads_proto::v1 as pb;
use crossroads_proto::v1::learner_client::LearnerClient as PbClient;
use crossroads_types::Weights;
use crossroads_types::checkpoint::check_checkpoint_id;

use crate::channel::{AuthChannel, connect};
use crate::convert::{CheckpointSummary, checkpoint_from_wire, weights_from_wire};
use crate::grpc::{hint_plain_text, status_message};
use crate::security::{ClientSecurity, SecurityError};

/// Why a learner call failed.
#[derive(Debug, thiserror::Error)]
pub enum LearnerClientError {
    /// The endpoint, the TLS files or the token cannot be used.
    #[error(transparent)]
    Security(#[from] SecurityError),
    /// The learner answered with an error status.
    #[error("learner: {code:?}: {message}")]
    Status {
        /// gRPC code.
        code: tonic::Code,
        /// The learner's message.
        message: String,
    },
    /// No answer in time.
    #[error("the learner did not answer within {0:?}")]
    Timeout(Duration),
    /// The learner sent something invalid.
    #[error("invalid answer from the learner: {0}")]
    Invalid(String),
    /// A pulled file could not be written.
    #[error("{action} {}: {source}", path.display())]
    Io {
        /// What was being done.
        action: &'static str,
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl LearnerClientError {
    /// The gRPC code, if the learner answered.
    pub fn code(&self) -> Option<tonic::Code> {
        match self {
            LearnerClientError::Status { code, .. } => Some(*code),
            _ => None,
        }
    }
}

impl From<tonic::Status> for LearnerClientError {
    fn from(s: tonic::Status) -> Self {
        LearnerClientError::Status {
            code: s.code(),
            message: status_message(&s),
        }
    }
}

/// Where training stands, as `Status` reports it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LearnerStatus {
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
    /// Seconds since the learner started.
    pub uptime_seconds: f64,
    /// Scenario of the run.
    pub scenario: String,
    /// Latest checkpoint id; empty if none.
    pub latest_checkpoint: String,
    /// The effective configuration, as TOML (secrets redacted).
    pub config_toml: String,
}

impl LearnerStatus {
    /// From the wire (private: no prost type in the crate's public API
    /// outside `convert` and `wire`).
    fn from_wire(s: pb::LearnerStatus) -> Self {
        Self {
            update_step: s.update_step,
            weights_version: s.weights_version,
            loss: s.loss,
            mean_q: s.mean_q,
            updates_per_second: s.updates_per_second,
            uptime_seconds: s.uptime_seconds,
            scenario: s.scenario,
            latest_checkpoint: s.latest_checkpoint,
            config_toml: s.config_toml,
        }
    }
}

/// A connection to a learner. Cheap to clone.
#[derive(Debug, Clone)]
pub struct LearnerClient {
    inner: PbClient<AuthChannel>,
    endpoint: String,
    timeout: Duration,
}

impl LearnerClient {
    /// A client of `url` (e.g. `http://127.0.0.1:50052`), with TLS for
    /// `https://` and the token on every call as `security` says; connects
    /// lazily. `timeout` bounds connecting and each answer. Must be called
    /// inside a tokio runtime.
    pub fn new(
        url: &str,
        security: &ClientSecurity,
        timeout: Duration,
    ) -> Result<Self, LearnerClientError> {
        Ok(Self {
            inner: PbClient::new(connect(url, security, timeout)?)
                .max_decoding_message_size(1 << 30)
                .max_encoding_message_size(16 << 20),
            endpoint: url.to_owned(),
            timeout,
        })
    }

    async fn bounded<T>(
        &self,
        call: impl Future<Output = Result<tonic::Response<T>, tonic::Status>>,
    ) -> Result<T, LearnerClientError> {
        match tokio::time::timeout(self.timeout, call).await {
            Ok(Ok(r)) => Ok(r.into_inner()),
            Ok(Err(s)) => Err(LearnerClientError::Status {
                code: s.code(),
                message: hint_plain_text(&s, &self.endpoint, status_message(&s)),
            }),
            Err(_) => Err(LearnerClientError::Timeout(self.timeout)),
        }
    }

    /// Stored checkpoints, newest first.
    pub async fn list(&self) -> Result<Vec<CheckpointSummary>, LearnerClientError> {
        let mut c = self.inner.clone();
        let r = self
            .bounded(c.list_checkpoints(pb::ListCheckpointsRequest {}))
            .await?;
        Ok(r.checkpoints
            .into_iter()
            .map(checkpoint_from_wire)
            .collect())
    }

    /// Writes a checkpoint now.
    pub async fn save(&self) -> Result<CheckpointSummary, LearnerClientError> {
        let mut c = self.inner.clone();
        let r = self
            .bounded(c.save_checkpoint(pb::SaveCheckpointRequest {}))
            .await?;
        Ok(checkpoint_from_wire(r))
    }

    /// Restores a checkpoint; returns it and the version its weights were
    /// published under.
    pub async fn restore(&self, id: &str) -> Result<(CheckpointSummary, u64), LearnerClientError> {
        let mut c = self.inner.clone();
        let r = self
            .bounded(c.restore_checkpoint(pb::RestoreCheckpointRequest { id: id.to_owned() }))
            .await?;
        let info = r
            .checkpoint
            .ok_or_else(|| LearnerClientError::Invalid("no checkpoint in the answer".into()))?;
        Ok((checkpoint_from_wire(info), r.weights_version))
    }

    /// Removes a checkpoint.
    pub async fn delete(&self, id: &str) -> Result<(), LearnerClientError> {
        let mut c = self.inner.clone();
        self.bounded(c.delete_checkpoint(pb::DeleteCheckpointRequest { id: id.to_owned() }))
            .await?;
        Ok(())
    }

    /// Where training stands.
    pub async fn status(&self) -> Result<LearnerStatus, LearnerClientError> {
        let mut c = self.inner.clone();
        let status = self.bounded(c.status(pb::StatusRequest {})).await?;
        Ok(LearnerStatus::from_wire(status))
    }

    /// Reports an evaluation of a weights version.
    pub async fn report_evaluation(
        &self,
        weights_version: u64,
        metrics: BTreeMap<String, f64>,
    ) -> Result<(), LearnerClientError> {
        let mut c = self.inner.clone();
        self.bounded(c.report_evaluation(pb::ReportEvaluationRequest {
            weights_version,
            metrics: metrics.into_iter().collect(),
        }))
        .await?;
        Ok(())
    }

    /// The latest published weights.
    pub async fn latest_weights(&self) -> Result<Weights, LearnerClientError> {
        let mut c = self.inner.clone();
        let w = self
            .bounded(c.get_latest_weights(pb::GetLatestWeightsRequest {}))
            .await?;
        weights_from_wire(w).map_err(LearnerClientError::Invalid)
    }

    /// Subscribes to weights newer than `have_version`: the latest comes at
    /// once, then each new one.
    pub async fn subscribe_weights(
        &self,
        have_version: u64,
    ) -> Result<WeightsStream, LearnerClientError> {
        let mut c = self.inner.clone();
        let stream = self
            .bounded(c.subscribe_weights(pb::SubscribeWeightsRequest { have_version }))
            .await?;
        Ok(WeightsStream { stream })
    }

    /// Downloads checkpoint `id` into `out/<id>/` (written under a
    /// temporary name, then renamed); returns its description and folder.
    /// File names from the learner are checked, so nothing is written
    /// outside that folder.
    pub async fn pull(
        &self,
        id: &str,
        out: &Path,
    ) -> Result<(CheckpointSummary, PathBuf), LearnerClientError> {
        let mut c = self.inner.clone();
        let mut stream = self
            .bounded(c.get_checkpoint(pb::GetCheckpointRequest { id: id.to_owned() }))
            .await?;
        let io = |action: &'static str, path: &Path| {
            let path = path.to_path_buf();
            move |source| LearnerClientError::Io {
                action,
                path,
                source,
            }
        };
        let first = next_chunk(&mut stream, self.timeout)
            .await?
            .ok_or_else(|| LearnerClientError::Invalid("empty checkpoint stream".into()))?;
        let info = checkpoint_from_wire(
            first
                .info
                .ok_or_else(|| LearnerClientError::Invalid("first chunk has no info".into()))?,
        );
        check_checkpoint_id(&info.id).map_err(|problem| {
            LearnerClientError::Invalid(format!("invalid checkpoint id {:?}: {problem}", info.id))
        })?;
        std::fs::create_dir_all(out).map_err(io("creating", out))?;
        let tmp = out.join(format!(".pull-{}-{}", info.id, std::process::id()));
        let dest = out.join(&info.id);
        std::fs::create_dir_all(&tmp).map_err(io("creating", &tmp))?;
        let result = async {
            let mut files: BTreeMap<String, (std::fs::File, u64, bool)> = BTreeMap::new();
            while let Some(chunk) = next_chunk(&mut stream, self.timeout).await? {
                if check_checkpoint_id(&chunk.file).is_err() || !info.files.contains(&chunk.file) {
                    return Err(LearnerClientError::Invalid(format!(
                        "unexpected file name {:?}",
                        chunk.file
                    )));
                }
                let path = tmp.join(&chunk.file);
                if !files.contains_key(&chunk.file) {
                    let f = std::fs::File::create(&path).map_err(io("creating", &path))?;
                    files.insert(chunk.file.clone(), (f, 0, false));
                }
                let Some((f, written, done)) = files.get_mut(&chunk.file) else {
                    continue;
                };
                if *done || chunk.offset != *written {
                    return Err(LearnerClientError::Invalid(format!(
                        "chunk of {} at offset {} out of order",
                        chunk.file, chunk.offset
                    )));
                }
                std::io::Write::write_all(f, &chunk.data).map_err(io("writing", &path))?;
                *written += chunk.data.len() as u64;
                *done = chunk.end_of_file;
            }
            for name in &info.files {
                match files.get(name) {
                    Some((f, _, true)) => f.sync_all().map_err(io("syncing", &tmp.join(name)))?,
                    _ => {
                        return Err(LearnerClientError::Invalid(format!(
                            "the stream ended before {name} was complete"
                        )));
                    }
                }
            }
            Ok(())
        }
        .await;
        if let Err(e) = result {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(e);
        }
        if dest.exists() {
            std::fs::remove_dir_all(&dest).map_err(io("replacing", &dest))?;
        }
        std::fs::rename(&tmp, &dest).map_err(io("renaming into place", &dest))?;
        Ok((info, dest))
    }
}

async fn next_chunk(
    stream: &mut tonic::Streaming<pb::CheckpointChunk>,
    timeout: Duration,
) -> Result<Option<pb::CheckpointChunk>, LearnerClientError> {
    match tokio::time::timeout(timeout, stream.message()).await {
        Ok(Ok(m)) => Ok(m),
        Ok(Err(s)) => Err(s.into()),
        Err(_) => Err(LearnerClientError::Timeout(timeout)),
    }
}

/// A weights stream from [`LearnerClient::subscribe_weights`].
#[derive(Debug)]
pub struct WeightsStream {
    stream: tonic::Streaming<pb::Weights>,
}

impl WeightsStream {
    /// The next version (waits until one is published); `None` when the
    /// learner ended the stream.
    pub async fn next(&mut self) -> Result<Option<Weights>, LearnerClientError> {
        match self.stream.message().await? {
            Some(w) => weights_from_wire(w)
                .map(Some)
                .map_err(LearnerClientError::Invalid),
            None => Ok(None),
        }
    }
}

//! The replay server's gRPC client, as actors, the learner and the CLI use
//! it.
//!
//! [`ReplayClient`] wraps the generated client: it converts domain batches
//! to the wire and back (validating what the server sends), answers in
//! domain types ([`Sample`], [`PrioritiesUpdated`], [`TableInfo`],
//! [`JoinedActor`], [`SnapshotWritten`], ...), bounds every wait by a
//! timeout, and turns statuses into [`ClientError`]s that say whether a
//! retry can help. [`InsertStream`] is one streaming insert: send batches,
//! receive an acknowledgement per batch once its transitions are in the
//! table.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crossroads_config::TransportConfig;
use crossroads_proto::v1 as pb;
use crossroads_proto::v1::replay_client::ReplayClient as PbClient;
use crossroads_types::batch::{BatchError, TransitionBatch};
use crossroads_types::{PrioritiesUpdated, Sample};
use tokio::sync::mpsc;

use crate::channel::{AuthChannel, connect};
use crate::security::{ClientSecurity, SecurityError, error_chain};
use crate::wire;

/// Why a replay call failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The endpoint, the TLS files or the token cannot be used.
    #[error(transparent)]
    Security(#[from] SecurityError),
    /// The server answered with an error status.
    #[error("replay server: {code:?}: {message}")]
    Status {
        /// gRPC status code.
        code: tonic::Code,
        /// The server's message (names the field for invalid input).
        message: String,
    },
    /// No answer within the timeout.
    #[error("replay server did not answer within {0:?}")]
    Timeout(Duration),
    /// The insert stream ended (the server closed it or went away).
    #[error("the insert stream is closed")]
    Closed,
    /// The server sent a batch that does not validate.
    #[error("invalid batch from the replay server: {0}")]
    InvalidResponse(#[from] BatchError),
    /// The batch is too large for one message or has too many ids in flight.
    #[error("invalid request: {0}")]
    Request(String),
}

impl ClientError {
    /// Whether retrying the same call later may succeed (the server is
    /// down, restarting, busy or rate-limited), as opposed to a request the
    /// server will always refuse.
    pub fn is_retryable(&self) -> bool {
        match self {
            ClientError::Status { code, .. } => matches!(
                code,
                tonic::Code::Unavailable
                    | tonic::Code::DeadlineExceeded
                    | tonic::Code::Aborted
                    | tonic::Code::Unknown
                    | tonic::Code::Cancelled
            ),
            ClientError::Timeout(_) | ClientError::Closed => true,
            _ => false,
        }
    }

    /// The gRPC code, if the server answered.
    pub fn code(&self) -> Option<tonic::Code> {
        match self {
            ClientError::Status { code, .. } => Some(*code),
            _ => None,
        }
    }
}

impl From<tonic::Status> for ClientError {
    fn from(s: tonic::Status) -> Self {
        ClientError::Status {
            code: s.code(),
            message: status_message(&s),
        }
    }
}

/// A status's message with its sources (a failed connection or TLS
/// handshake says why only there).
pub(crate) fn status_message(s: &tonic::Status) -> String {
    match std::error::Error::source(s) {
        Some(source) => {
            let chain = error_chain(source);
            if chain.starts_with(s.message()) {
                chain
            } else {
                format!("{}: {chain}", s.message())
            }
        }
        None => s.message().to_owned(),
    }
}

/// `message`, with a hint when a plain-text client's connection broke the
/// way a TLS server breaks it: it answers plain HTTP/2 with an alert (read
/// as an oversized frame) and closes, which says nothing about TLS by
/// itself. A refused connection (a server that is down) gets no hint.
pub(crate) fn hint_plain_text(status: &tonic::Status, endpoint: &str, message: String) -> String {
    const SIGNS: [&str; 4] = [
        "frame with invalid size",
        "broken pipe",
        "connection reset",
        "connection closed",
    ];
    let lower = message.to_ascii_lowercase();
    if endpoint.starts_with("http://")
        && std::error::Error::source(status).is_some()
        && SIGNS.iter().any(|s| lower.contains(s))
    {
        format!(
            "{message} (if the server speaks TLS, reach it at https:// with \
             transport.tls.ca_file set)"
        )
    } else {
        message
    }
}

/// The acknowledgement of one inserted batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InsertAck {
    /// The id given by [`InsertStream::send`].
    pub batch_id: u64,
    /// Transitions stored.
    pub inserted: u32,
    /// Table size after the insert.
    pub table_size: u64,
}

/// Size, counters and rate-limiter state of a table, as `Info` reports
/// them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TableInfo {
    /// Table name.
    pub name: String,
    /// Items held.
    pub size: u64,
    /// Items it can hold.
    pub capacity: u64,
    /// Items ever inserted (across restores).
    pub inserts_total: u64,
    /// Items ever sampled (across restores).
    pub samples_total: u64,
    /// Priorities updated.
    pub priority_updates_total: u64,
    /// Updates for keys no longer held.
    pub ignored_updates_total: u64,
    /// Rejected inputs by reason, e.g. `observation_length` (reasons
    /// never seen are left out).
    pub rejections_total: BTreeMap<String, u64>,
    /// The rate limiter (the server always reports it).
    pub rate_limiter: Option<RateLimiterInfo>,
    /// Bytes of memory the table holds.
    pub bytes_stored: u64,
    /// Last snapshot written, Unix milliseconds; 0 if none.
    pub last_snapshot_unix_ms: i64,
}

/// A table's rate limiter: its settings and whether it lets calls through.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RateLimiterInfo {
    /// Inserts before the first sample.
    pub min_size_to_sample: u64,
    /// Target samples per insert; 0 turns the ratio off.
    pub samples_per_insert: f64,
    /// Allowed drift of the ratio, in samples.
    pub error_tolerance: f64,
    /// Whether a sample may proceed now.
    pub can_sample: bool,
    /// Whether an insert may proceed now.
    pub can_insert: bool,
    /// Samples that had to wait (the server process's).
    pub sample_waits_total: u64,
    /// Inserts that had to wait (the server process's).
    pub insert_waits_total: u64,
}

/// The index the replay server gave an actor ([`ReplayClient::join_actor`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JoinedActor {
    /// The actor's index (the same name gets the same index).
    pub index: u32,
    /// Actors that have joined so far, this one included.
    pub joined: u32,
}

/// A snapshot the replay server wrote ([`ReplayClient::snapshot`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SnapshotWritten {
    /// Where.
    pub path: String,
    /// Items in it.
    pub items: u64,
    /// Its size.
    pub bytes: u64,
    /// How long writing it took.
    pub duration_seconds: f64,
}

/// A connection to the replay server, for one table. Cheap to clone
/// (clones share the HTTP/2 connection).
#[derive(Debug, Clone)]
pub struct ReplayClient {
    inner: PbClient<AuthChannel>,
    endpoint: String,
    table: String,
    request_timeout: Duration,
    max_message_bytes: usize,
}

impl ReplayClient {
    /// A client of `config.replay_endpoint`, with the TLS settings and
    /// token of `config.tls` and `config.auth` (their files are read now).
    /// It connects lazily: a server that is not up yet makes calls fail
    /// with a retryable error, not this constructor. Must be called inside
    /// a tokio runtime.
    pub fn new(config: &TransportConfig, table: &str) -> Result<Self, ClientError> {
        Self::with_security(config, &ClientSecurity::load(config)?, table)
    }

    /// [`ReplayClient::new`] with TLS settings and token already loaded.
    pub fn with_security(
        config: &TransportConfig,
        security: &ClientSecurity,
        table: &str,
    ) -> Result<Self, ClientError> {
        let channel = connect(
            &config.replay_endpoint,
            security,
            Duration::from_millis(config.connect_timeout_ms),
        )?;
        let max_message_bytes = 1 << 30;
        Ok(Self {
            inner: PbClient::new(channel)
                .max_decoding_message_size(max_message_bytes)
                .max_encoding_message_size(max_message_bytes),
            endpoint: config.replay_endpoint.clone(),
            table: table.to_owned(),
            request_timeout: Duration::from_millis(config.request_timeout_ms),
            max_message_bytes,
        })
    }

    /// The table this client talks to.
    pub fn table(&self) -> &str {
        &self.table
    }

    /// The generated client, for one call (clones share the connection).
    fn rpc(&self) -> PbClient<AuthChannel> {
        self.inner.clone()
    }

    /// Waits for `call` at most the request timeout plus `extra`.
    async fn bounded<T>(
        &self,
        extra: Duration,
        call: impl Future<Output = Result<tonic::Response<T>, tonic::Status>>,
    ) -> Result<T, ClientError> {
        let limit = self.request_timeout + extra;
        match tokio::time::timeout(limit, call).await {
            Ok(Ok(response)) => Ok(response.into_inner()),
            Ok(Err(status)) => Err(ClientError::Status {
                code: status.code(),
                message: hint_plain_text(&status, &self.endpoint, status_message(&status)),
            }),
            Err(_) => Err(ClientError::Timeout(limit)),
        }
    }

    /// Waits for `call` at most the request timeout.
    async fn call<T>(
        &self,
        call: impl Future<Output = Result<tonic::Response<T>, tonic::Status>>,
    ) -> Result<T, ClientError> {
        self.bounded(Duration::ZERO, call).await
    }

    /// Samples `batch_size` items with importance exponent `beta`, waiting
    /// at most `wait` for the rate limiter (zero: the server's default).
    /// The batch is validated on arrival.
    pub async fn sample(
        &self,
        batch_size: u32,
        beta: f32,
        wait: Duration,
    ) -> Result<Sample, ClientError> {
        let request = pb::SampleRequest {
            table: self.table.clone(),
            batch_size,
            beta,
            timeout_ms: u32::try_from(wait.as_millis()).unwrap_or(u32::MAX),
        };
        let response = self.bounded(wait, self.rpc().sample(request)).await?;
        Ok(wire::sample_from_wire(response)?)
    }

    /// Sets new priorities (finite, >= 0) of sampled items.
    pub async fn update_priorities(
        &self,
        keys: Vec<u64>,
        priorities: Vec<f32>,
    ) -> Result<PrioritiesUpdated, ClientError> {
        let request = pb::UpdatePrioritiesRequest {
            table: self.table.clone(),
            keys,
            priorities,
        };
        let r = self.call(self.rpc().update_priorities(request)).await?;
        Ok(PrioritiesUpdated {
            updated: r.updated,
            ignored: r.ignored,
        })
    }

    /// Size, counters and rate-limiter state of the table.
    pub async fn info(&self) -> Result<TableInfo, ClientError> {
        let request = pb::InfoRequest {
            table: self.table.clone(),
        };
        let info = self.call(self.rpc().info(request)).await?;
        Ok(wire::table_info_from_wire(info))
    }

    /// Asks the server for this actor's index, naming it `name` (see the
    /// `JoinActor` call).
    pub async fn join_actor(&self, name: &str) -> Result<JoinedActor, ClientError> {
        let name = name.to_owned();
        let r = self
            .call(self.rpc().join_actor(pb::JoinActorRequest { name }))
            .await?;
        Ok(JoinedActor {
            index: r.index,
            joined: r.joined,
        })
    }

    /// Asks the server to write a snapshot now; returns its path and size.
    pub async fn snapshot(&self) -> Result<SnapshotWritten, ClientError> {
        let r = self
            .call(self.rpc().snapshot(pb::SnapshotRequest {}))
            .await?;
        Ok(SnapshotWritten {
            path: r.path,
            items: r.items,
            bytes: r.bytes,
            duration_seconds: r.duration_seconds,
        })
    }

    /// Opens a streaming insert with at most `window` batches in flight
    /// (sent, not acknowledged).
    pub async fn insert_stream(&self, window: usize) -> Result<InsertStream, ClientError> {
        let window = window.max(1);
        let (tx, rx) = mpsc::channel(window);
        let stream = tokio_stream::wrappers::ReceiverStream::new(rx);
        let acks = self.call(self.rpc().insert(stream)).await?;
        Ok(InsertStream {
            tx,
            acks,
            table: self.table.clone(),
            next_id: 0,
            in_flight: VecDeque::new(),
            window,
            timeout: self.request_timeout,
            max_message_bytes: self.max_message_bytes,
        })
    }

    /// Inserts one batch on a fresh stream and waits for its
    /// acknowledgement (convenient, not fast: actors keep a stream open).
    pub async fn insert(&self, batch: TransitionBatch) -> Result<InsertAck, ClientError> {
        let mut stream = self.insert_stream(1).await?;
        stream.send(batch).await?;
        let ack = stream.next_ack().await?;
        stream.finish().await?;
        Ok(ack)
    }
}

/// One streaming insert: batches go out, one acknowledgement per batch
/// comes back in order once the batch is stored. Every wait is bounded by
/// the request timeout, so a dead server surfaces as an error, never a hang.
#[derive(Debug)]
pub struct InsertStream {
    tx: mpsc::Sender<pb::InsertRequest>,
    acks: tonic::Streaming<pb::InsertAck>,
    table: String,
    next_id: u64,
    in_flight: VecDeque<u64>,
    window: usize,
    timeout: Duration,
    max_message_bytes: usize,
}

impl InsertStream {
    /// Queues `batch`; returns the id its acknowledgement will carry. Fails
    /// when `window` batches are in flight: take an acknowledgement with
    /// [`InsertStream::next_ack`] first.
    pub async fn send(&mut self, batch: TransitionBatch) -> Result<u64, ClientError> {
        if self.is_full() {
            return Err(ClientError::Request(format!(
                "{} batches in flight; take an acknowledgement first",
                self.window
            )));
        }
        let id = self.next_id;
        let request = pb::InsertRequest {
            table: self.table.clone(),
            batch_id: id,
            batch: Some(wire::batch_to_wire(batch)),
        };
        let size = prost::Message::encoded_len(&request);
        if size > self.max_message_bytes {
            return Err(ClientError::Request(format!(
                "batch is {size} bytes, above {} per message",
                self.max_message_bytes
            )));
        }
        match tokio::time::timeout(self.timeout, self.tx.send(request)).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return Err(ClientError::Closed),
            Err(_) => return Err(ClientError::Timeout(self.timeout)),
        }
        self.next_id += 1;
        self.in_flight.push_back(id);
        Ok(id)
    }

    /// Batches sent and not yet acknowledged, oldest first.
    pub fn in_flight(&self) -> impl Iterator<Item = u64> + '_ {
        self.in_flight.iter().copied()
    }

    /// Whether the window is full (the next `send` would fail).
    pub fn is_full(&self) -> bool {
        self.in_flight.len() >= self.window
    }

    /// The next acknowledgement. An error status (invalid batch, rate
    /// limiter timeout, server shutting down) ends the stream; batches
    /// still in flight then were not stored.
    pub async fn next_ack(&mut self) -> Result<InsertAck, ClientError> {
        if self.in_flight.is_empty() {
            return Err(ClientError::Request("no batch in flight".to_owned()));
        }
        let message = match tokio::time::timeout(self.timeout, self.acks.message()).await {
            Ok(Ok(Some(ack))) => ack,
            Ok(Ok(None)) => return Err(ClientError::Closed),
            Ok(Err(status)) => return Err(status.into()),
            Err(_) => return Err(ClientError::Timeout(self.timeout)),
        };
        if self.in_flight.front() != Some(&message.batch_id) {
            return Err(ClientError::Request(format!(
                "acknowledgement for batch {} out of order (expected {:?})",
                message.batch_id,
                self.in_flight.front()
            )));
        }
        self.in_flight.pop_front();
        Ok(InsertAck {
            batch_id: message.batch_id,
            inserted: message.inserted,
            table_size: message.table_size,
        })
    }

    /// Closes the stream after the acknowledgements of every batch in
    /// flight; returns them.
    pub async fn finish(mut self) -> Result<Vec<InsertAck>, ClientError> {
        let mut acks = Vec::with_capacity(self.in_flight.len());
        while !self.in_flight.is_empty() {
            acks.push(self.next_ack().await?);
        }
        drop(self.tx);
        // The server ends its side once ours is closed.
        let _ = tokio::time::timeout(self.timeout, self.acks.message()).await;
        Ok(acks)
    }
}

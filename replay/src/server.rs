//! The replay server: tables restored from the newest snapshot, the gRPC
//! service, the shared-memory ingest and periodic snapshots, all stopped by
//! one [`Shutdown`].
//!
//! [`start`] binds (port 0 picks a free port) and returns a
//! [`RunningServer`] that reports its address; [`RunningServer::join`]
//! waits for the stop: the gRPC server drains, insert streams finish their
//! current batch, the ingest thread empties its queues, then the last
//! snapshot is written, so every acknowledged transition is in it.
//! [`run`] is both in one call.
//!
//! A server serves one table today, named by `replay.table`; the service
//! and snapshots already handle several. Actors insert over gRPC or
//! iceoryx2; the learner samples and updates priorities over gRPC only.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_proto::v1::replay_server::ReplayServer as PbServer;
use crossroads_transport::auth::REPLAY_OPEN_CALLS;
use crossroads_transport::shm::ShmError;
use crossroads_transport::{SecurityError, ServerSecurity};
use prometheus::Registry;
use tokio::net::TcpListener;
use tokio::task::JoinHandle;
use tokio_stream::wrappers::TcpListenerStream;
use tokio_util::task::TaskTracker;

use crate::ingest::ShmIngest;
use crate::metrics::ReplayMetrics;
use crate::roster::Roster;
use crate::service::{Limits, ReplayService, State};
use crate::snapshot::{SnapshotError, Snapshots};
use crate::table::{Table, TableConfig};
use crate::wal::{self, Wal, WalConfig, WalError};

/// Longest the gRPC server may take to drain after shutdown before its
/// connections are dropped.
const DRAIN: Duration = Duration::from_secs(10);

/// Why the server could not start or stopped badly.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The gRPC address could not be bound.
    #[error("cannot listen for gRPC on {addr}: {source}")]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TLS files or the token cannot be used.
    #[error(transparent)]
    Security(#[from] SecurityError),
    /// A metric could not be registered.
    #[error("cannot register replay metrics: {0}")]
    Metrics(#[from] prometheus::Error),
    /// A snapshot could not be restored or written.
    #[error(transparent)]
    Snapshot(#[from] SnapshotError),
    /// The write-ahead log could not be replayed or opened.
    #[error(transparent)]
    Wal(#[from] WalError),
    /// A snapshot's table does not fit the configured one.
    #[error("cannot restore table {table:?} from {path}: {problem}")]
    Restore {
        /// The table.
        table: String,
        /// The snapshot.
        path: String,
        /// What does not fit.
        problem: String,
    },
    /// Shared memory could not be set up.
    #[error("shared-memory ingest: {0}")]
    Shm(#[from] ShmError),
    /// The gRPC server failed.
    #[error("gRPC server: {0}")]
    Serve(String),
}

/// A started server.
#[derive(Debug)]
pub struct RunningServer {
    addr: SocketAddr,
    state: Arc<State>,
    task: JoinHandle<Result<(), ServerError>>,
}

impl RunningServer {
    /// The gRPC address actually bound.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The table named `name`.
    pub fn table(&self, name: &str) -> Option<Arc<Table>> {
        self.state.tables.get(name).cloned()
    }

    /// Waits until the server has stopped (after shutdown fired) and its
    /// last snapshot is written.
    pub async fn join(self) -> Result<(), ServerError> {
        match self.task.await {
            Ok(result) => result,
            Err(e) => Err(ServerError::Serve(format!("server task failed: {e}"))),
        }
    }
}

/// Starts the server `config.replay` describes, registering its metrics in
/// `registry` (when given). Restores the newest valid snapshot first when
/// `replay.restore` is set; fails (naming the files) if snapshots exist and
/// none is valid. Must be called inside a tokio runtime.
pub async fn start(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<RunningServer, ServerError> {
    let rc = &config.replay;
    // TLS files and token first: a missing file stops the start at once.
    let security = ServerSecurity::load(&config.transport)?;
    let mut builder = security.builder(REPLAY_OPEN_CALLS)?;
    let metrics = ReplayMetrics::new(registry)?;
    let table_config = TableConfig::from_config(rc);
    let table = Arc::new(Table::new(table_config, metrics.table(&rc.table)));
    let mut tables = BTreeMap::new();
    tables.insert(rc.table.clone(), table);

    let (snapshots, wal) = match &rc.snapshot_dir {
        Some(dir) => {
            let (snapshots, wal) = recover(config, dir, &tables, &metrics).await?;
            (Some(snapshots), wal)
        }
        None => (None, None),
    };

    let listener = TcpListener::bind(rc.listen)
        .await
        .map_err(|source| ServerError::Bind {
            addr: rc.listen,
            source,
        })?;
    let addr = listener.local_addr().map_err(|source| ServerError::Bind {
        addr: rc.listen,
        source,
    })?;

    let state = Arc::new(State {
        tables,
        metrics,
        snapshots: snapshots.clone(),
        wal,
        limits: Limits {
            insert_timeout: Duration::from_millis(rc.insert_timeout_ms),
            sample_timeout: Duration::from_millis(rc.sample_timeout_ms),
            max_batch_transitions: rc.max_batch_transitions as usize,
            max_sample_batch: rc.max_sample_batch as usize,
        },
        shutdown: shutdown.clone(),
        tasks: TaskTracker::new(),
        roster: Roster::default(),
    });
    let ingest = if rc.shm_ingest {
        Some(ShmIngest::start(&config.transport, state.clone())?)
    } else {
        None
    };

    let periodic = match (&snapshots, rc.snapshot_interval_secs) {
        (Some(s), secs) if secs > 0 => Some(tokio::spawn(periodic_snapshots(
            s.clone(),
            state.tables.values().cloned().collect(),
            Duration::from_secs(secs),
            shutdown.clone(),
        ))),
        _ => None,
    };

    let service = PbServer::new(ReplayService::new(state.clone()))
        .max_decoding_message_size(rc.max_message_bytes)
        .max_encoding_message_size(usize::MAX);
    let serve = builder.add_service(service).serve_with_incoming_shutdown(
        TcpListenerStream::new(listener),
        {
            let shutdown = shutdown.clone();
            async move { shutdown.wait().await }
        },
    );
    tracing::info!(
        %addr,
        table = %rc.table,
        capacity = rc.capacity,
        tls = security.tls(),
        client_certificates = security.client_certificates(),
        token = security.token(),
        "replay server listening"
    );

    let task_state = state.clone();
    let task = tokio::spawn(async move {
        let state = task_state;
        let served = tokio::select! {
            r = serve => r.map_err(|e| ServerError::Serve(e.to_string())),
            _ = async { shutdown.wait().await; tokio::time::sleep(DRAIN).await } => {
                tracing::warn!("gRPC connections did not drain in {DRAIN:?}; dropping them");
                Ok(())
            }
        };
        state.tasks.close();
        state.tasks.wait().await;
        if let Some(ingest) = ingest
            && tokio::task::spawn_blocking(move || ingest.join())
                .await
                .is_err()
        {
            tracing::error!("joining the shared-memory ingest");
        }
        if let Some(p) = periodic {
            let _ = p.await;
        }
        let mut result = served;
        if let Some(s) = snapshots {
            let tables: Vec<Arc<Table>> = state.tables.values().cloned().collect();
            let written = tokio::task::spawn_blocking(move || s.write(&tables)).await;
            match written {
                Ok(Ok(_)) => {}
                Ok(Err(e)) => result = result.and(Err(e.into())),
                Err(e) => {
                    result = result.and(Err(ServerError::Serve(format!("snapshot task: {e}"))))
                }
            }
        }
        tracing::info!("replay server stopped");
        result
    });
    Ok(RunningServer { addr, state, task })
}

/// Runs the server until `shutdown` fires and its last snapshot is written.
pub async fn run(
    config: &Config,
    registry: Option<&Registry>,
    shutdown: Shutdown,
) -> Result<(), ServerError> {
    start(config, registry, shutdown).await?.join().await
}

/// Opens the snapshots in `dir` and the write-ahead log beside them,
/// restores the newest snapshot and replays the log on top (when
/// `replay.restore`), and writes a snapshot at once if the log added
/// anything, so the log starts again from empty. A log that will not be
/// replayed (restore or the log off) is set aside, never replayed later.
async fn recover(
    config: &Config,
    dir: &std::path::Path,
    tables: &BTreeMap<String, Arc<Table>>,
    metrics: &ReplayMetrics,
) -> Result<(Arc<Snapshots>, Option<Arc<Wal>>), ServerError> {
    let rc = &config.replay;
    let snapshots = Arc::new(Snapshots::new(
        dir.to_path_buf(),
        rc.snapshot_keep as usize,
        metrics.clone(),
    )?);
    let wal_dir = dir.join("wal");
    let replayed = if rc.restore {
        restore(&snapshots, tables).await?;
        if rc.wal {
            let (d, t) = (wal_dir.clone(), tables.clone());
            Some(
                tokio::task::spawn_blocking(move || wal::replay_into(&d, &t))
                    .await
                    .map_err(|e| ServerError::Serve(format!("log replay task: {e}")))??,
            )
        } else {
            None
        }
    } else {
        None
    };
    if replayed.is_none() {
        let aside = wal::set_aside(&wal_dir)?;
        if aside > 0 {
            tracing::warn!(dir = %wal_dir.display(), segments = aside,
                "write-ahead log not replayed (replay.restore or replay.wal is off); set aside as *.skipped");
        }
    }
    if !rc.wal {
        return Ok((snapshots, None));
    }
    let wal = Arc::new(Wal::open(
        WalConfig {
            dir: wal_dir,
            sync_interval: Duration::from_millis(rc.wal_sync_ms),
            sync_bytes: rc.wal_sync_bytes,
        },
        metrics.clone(),
    )?);
    snapshots.attach_wal(wal.clone());
    if let Some(r) = replayed.filter(|r| r.batches > 0) {
        tracing::info!(
            segments = r.segments,
            batches = r.batches,
            transitions = r.transitions,
            already_in_snapshot = r.covered,
            torn_segments = r.torn,
            "replayed the write-ahead log; writing a snapshot that holds it"
        );
        let (s, t) = (
            snapshots.clone(),
            tables.values().cloned().collect::<Vec<_>>(),
        );
        tokio::task::spawn_blocking(move || s.write(&t))
            .await
            .map_err(|e| ServerError::Serve(format!("snapshot task: {e}")))??;
    }
    Ok((snapshots, Some(wal)))
}

async fn restore(
    snapshots: &Arc<Snapshots>,
    tables: &BTreeMap<String, Arc<Table>>,
) -> Result<(), ServerError> {
    let s = snapshots.clone();
    let found = tokio::task::spawn_blocking(move || s.restore_latest())
        .await
        .map_err(|e| ServerError::Serve(format!("restore task: {e}")))??;
    let Some((path, images)) = found else {
        tracing::info!(dir = %snapshots.dir().display(), "no snapshot to restore; starting empty");
        return Ok(());
    };
    for (name, image) in images {
        // Starting without them would prune them with the next snapshots.
        let Some(table) = tables.get(&name) else {
            return Err(ServerError::Restore {
                table: name,
                path: path.display().to_string(),
                problem: format!(
                    "this server has no such table (it serves {:?}); set replay.table to it, \
                     or replay.restore = false to start empty",
                    tables.keys().collect::<Vec<_>>()
                ),
            });
        };
        let dropped = table.restore(&image).map_err(|e| ServerError::Restore {
            table: name.clone(),
            path: path.display().to_string(),
            problem: e.to_string(),
        })?;
        if dropped > 0 {
            tracing::warn!(table = %name, dropped, "the snapshot holds more items than the capacity; the oldest were dropped");
        }
        tracing::info!(table = %name, items = image.len() - dropped, path = %path.display(), "restored");
    }
    Ok(())
}

async fn periodic_snapshots(
    snapshots: Arc<Snapshots>,
    tables: Vec<Arc<Table>>,
    every: Duration,
    shutdown: Shutdown,
) {
    let mut tick = tokio::time::interval_at(tokio::time::Instant::now() + every, every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = shutdown.wait() => return,
        }
        let (s, t) = (snapshots.clone(), tables.clone());
        // Errors are logged and counted by `write`; the next tick retries.
        let _ = tokio::task::spawn_blocking(move || s.write(&t)).await;
    }
}

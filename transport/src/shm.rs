//! Transition batches over iceoryx2 shared memory, for actors on the
//! replay server's host.
//!
//! A batch travels as one sample of the publish-subscribe service
//! `<prefix>/replay/<table>/insert` ([`service_name`]): the `#[repr(C)]`
//! user header [`BatchFrameHeader`] and a `[u8]` payload holding the
//! batch's columns followed by its observation pool, encoded by
//! `crossroads_types::codec` exactly as on gRPC ([`write_frame`],
//! [`read_frame`]). Both sides open the service with
//! [`open_batch_service`], so its settings are defined once. The server
//! validates what it reads, once, and answers every batch on
//! `<prefix>/replay/<table>/acks` ([`open_ack_service`]) with a
//! [`ShmInsertAck`] naming the publisher and batch once it is stored (or
//! rejected), as a gRPC acknowledgement does: a send only puts the batch in
//! the server's queue, so a publisher that crashes loses what it had not
//! seen acknowledged. [`ShmBatchPublisher`] is the actor's side.

use std::fmt;
use std::time::Duration;

use iceoryx2::port::BackpressureAction;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crossroads_config::TransportConfig;
use crossroads_types::ObservationLayout;
use crossroads_types::batch::{
    BatchError, ObservationPool, RejectReason, TransitionBatch, ValidBatch,
};
use crossroads_types::codec::ObservationEncoding;
use crossroads_types::columns::{Columns, ROW_BYTES};

use crate::iox::{self, FrameServiceSettings, open_frame_service};

/// `CRB1`, little-endian: marks a frame of this format.
pub const FRAME_MAGIC: u32 = u32::from_le_bytes(*b"CRB1");
/// Version of the frame layout (2: the observation layout as `channels`,
/// `rows`, `cols` and `extra_features`, as on gRPC, where 1 had a flat
/// shape).
pub const FRAME_VERSION: u32 = 2;
/// Longest observation kind, bytes.
pub const MAX_KIND: usize = 32;
/// Longest table name, bytes.
pub const MAX_TABLE: usize = 64;

/// The fixed part of a batch in shared memory: what the batch is and how
/// long its variable sections are. Plain data, the same layout in every
/// process (`#[repr(C)]`, no pointers).
///
/// The payload that follows holds, little-endian and back to back:
/// `actions`, `rewards`, `discounts`, `priorities`, `observation_index`,
/// `next_observation_index` (`num_transitions` 4-byte values each), the
/// pool's `offsets` (`num_observations` u32) and its `data` (`data_len`
/// bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("crossroads.v1.BatchFrameHeader")]
#[repr(C)]
pub struct BatchFrameHeader {
    /// [`FRAME_MAGIC`].
    pub magic: u32,
    /// [`FRAME_VERSION`].
    pub version: u32,
    /// The publisher's id for the batch, for logs.
    pub batch_id: u64,
    /// Transitions in the batch.
    pub num_transitions: u32,
    /// Entries in the observation pool.
    pub num_observations: u32,
    /// Size of the action set.
    pub num_actions: u32,
    /// Wire number of the pool's encoding.
    pub encoding: u32,
    /// Bytes of pool data.
    pub data_len: u32,
    /// The observation layout's grid channels.
    pub channels: u32,
    /// Its grid rows.
    pub rows: u32,
    /// Its grid columns.
    pub cols: u32,
    /// Its dense values after the grid.
    pub extra_features: u32,
    /// Bytes used in `kind`.
    pub kind_len: u32,
    /// The observation layout's kind, UTF-8.
    pub kind: [u8; MAX_KIND],
    /// Bytes used in `table`.
    pub table_len: u32,
    /// Target table name, UTF-8.
    pub table: [u8; MAX_TABLE],
}

impl Default for BatchFrameHeader {
    fn default() -> Self {
        Self {
            magic: 0,
            version: 0,
            batch_id: 0,
            num_transitions: 0,
            num_observations: 0,
            num_actions: 0,
            encoding: 0,
            data_len: 0,
            channels: 0,
            rows: 0,
            cols: 0,
            extra_features: 0,
            kind_len: 0,
            kind: [0; MAX_KIND],
            table_len: 0,
            table: [0; MAX_TABLE],
        }
    }
}

impl BatchFrameHeader {
    /// The header of `batch` for `table`, and the payload length it needs.
    pub fn for_batch(
        table: &str,
        batch_id: u64,
        batch: &ValidBatch,
    ) -> Result<(Self, usize), BatchError> {
        let mut h = Self {
            magic: FRAME_MAGIC,
            version: FRAME_VERSION,
            batch_id,
            ..Self::default()
        };
        let too_big =
            |field: &str, what: String| BatchError::new(RejectReason::Oversized, field, what);
        h.num_transitions = u32::try_from(batch.len())
            .map_err(|_| too_big("actions", "more than 2^32 transitions".into()))?;
        h.num_observations = u32::try_from(batch.observations.len())
            .map_err(|_| too_big("observations", "more than 2^32 entries".into()))?;
        h.data_len = u32::try_from(batch.observations.data().len())
            .map_err(|_| too_big("observations.data", "more than 4 GiB".into()))?;
        h.num_actions = batch.num_actions;
        h.encoding = batch.observations.encoding().to_wire();
        let layout = &batch.layout;
        // A valid batch's dimensions are between 0 and MAX_OBSERVATION_LEN.
        let dim = |d: i64| u32::try_from(d).unwrap_or(u32::MAX);
        h.channels = dim(layout.channels);
        h.rows = dim(layout.rows);
        h.cols = dim(layout.cols);
        h.extra_features = dim(layout.extra);
        let bytes_above = |n, max| format!("{n} bytes is above {max}");
        let kind = layout.kind.as_bytes();
        h.kind_len = copy_fixed("layout.kind", kind, &mut h.kind, bytes_above)?;
        h.table_len = copy_fixed("table", table.as_bytes(), &mut h.table, bytes_above)?;
        Ok((h, h.payload_len()))
    }

    /// Payload bytes this header announces.
    pub fn payload_len(&self) -> usize {
        ROW_BYTES * self.num_transitions as usize
            + 4 * self.num_observations as usize
            + self.data_len as usize
    }

    /// The target table name.
    pub fn table(&self) -> Result<&str, BatchError> {
        let bytes = self.table.get(..self.table_len as usize).ok_or_else(|| {
            BatchError::new(RejectReason::BadRequest, "table", "length out of range")
        })?;
        std::str::from_utf8(bytes)
            .map_err(|_| BatchError::new(RejectReason::BadRequest, "table", "not UTF-8"))
    }
}

/// Copies `items` into the start of the fixed array `into`; returns how
/// many. `Oversized`, naming `field`, with `too_long(len, capacity)` as the
/// problem, when they do not fit.
fn copy_fixed<T: Copy>(
    field: &str,
    items: &[T],
    into: &mut [T],
    too_long: impl FnOnce(usize, usize) -> String,
) -> Result<u32, BatchError> {
    let capacity = into.len();
    let slot = into.get_mut(..items.len()).ok_or_else(|| {
        BatchError::new(
            RejectReason::Oversized,
            field,
            too_long(items.len(), capacity),
        )
    })?;
    slot.copy_from_slice(items);
    Ok(items.len() as u32)
}

/// The server's answer to one batch, on the acks service. Plain data
/// (`#[repr(C)]`); every publisher's subscriber sees every answer and keeps
/// its own by `publisher`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("crossroads.v1.ShmInsertAck")]
#[repr(C)]
pub struct ShmInsertAck {
    /// High half of the iceoryx2 id of the publisher that sent the batch.
    pub publisher_hi: u64,
    /// Low half of that id.
    pub publisher_lo: u64,
    /// The publisher's batch id.
    pub batch_id: u64,
    /// Table size after the insert.
    pub table_size: u64,
    /// Transitions stored.
    pub inserted: u32,
    /// 0 when stored; otherwise 1 + the position of the [`RejectReason`] in
    /// [`RejectReason::ALL`].
    pub rejected: u32,
}

impl ShmInsertAck {
    /// The answer for a batch from `publisher`.
    pub fn new(publisher: u128, batch_id: u64, outcome: Result<(u32, u64), RejectReason>) -> Self {
        let (inserted, table_size, rejected) = match outcome {
            Ok((inserted, size)) => (inserted, size, 0),
            Err(reason) => (
                0,
                0,
                RejectReason::ALL
                    .iter()
                    .position(|r| *r == reason)
                    .map_or(u32::MAX, |i| i as u32 + 1),
            ),
        };
        Self {
            publisher_hi: (publisher >> 64) as u64,
            publisher_lo: publisher as u64,
            batch_id,
            table_size,
            inserted,
            rejected,
        }
    }

    /// The publisher's id.
    pub fn publisher(&self) -> u128 {
        (u128::from(self.publisher_hi) << 64) | u128::from(self.publisher_lo)
    }

    /// `Ok((inserted, table_size))`, or why the batch was rejected.
    pub fn outcome(&self) -> Result<(u32, u64), RejectReason> {
        match self.rejected {
            0 => Ok((self.inserted, self.table_size)),
            n => Err(RejectReason::ALL
                .get(n as usize - 1)
                .copied()
                .unwrap_or(RejectReason::BadRequest)),
        }
    }
}

/// Writes `batch`'s columns and pool into `out`, which is exactly
/// [`BatchFrameHeader::payload_len`] bytes.
pub fn write_frame(batch: &ValidBatch, out: &mut [u8]) {
    let (columns, rest) = out.split_at_mut(batch.columns.byte_len());
    batch.columns.write_le(columns);
    let pool = &batch.observations;
    let (offsets, data) = rest.split_at_mut(4 * pool.len());
    for (word, offset) in offsets.chunks_exact_mut(4).zip(pool.offsets()) {
        word.copy_from_slice(&offset.to_le_bytes());
    }
    data.copy_from_slice(pool.data());
}

/// Reads a frame into a validated batch; returns the table it is for and
/// the publisher's batch id too. Nothing in the header or payload is
/// trusted: lengths, encoding, and the whole batch are checked.
pub fn read_frame(
    header: &BatchFrameHeader,
    payload: &[u8],
) -> Result<(String, u64, ValidBatch), BatchError> {
    let bad =
        |field: &str, problem: String| BatchError::new(RejectReason::BadRequest, field, problem);
    if header.magic != FRAME_MAGIC || header.version != FRAME_VERSION {
        return Err(bad(
            "header",
            format!(
                "not a version {FRAME_VERSION} batch frame (magic {:#x}, version {})",
                header.magic, header.version
            ),
        ));
    }
    if payload.len() != header.payload_len() {
        return Err(BatchError::new(
            RejectReason::LengthMismatch,
            "payload",
            format!(
                "{} bytes, but the header announces {}",
                payload.len(),
                header.payload_len()
            ),
        ));
    }
    let table = header.table()?.to_owned();
    let kind = header
        .kind
        .get(..header.kind_len as usize)
        .and_then(|b| std::str::from_utf8(b).ok())
        .ok_or_else(|| {
            BatchError::new(RejectReason::Spec, "layout.kind", "not UTF-8 or too long")
        })?;
    let layout = ObservationLayout::new(
        kind,
        i64::from(header.channels),
        i64::from(header.rows),
        i64::from(header.cols),
        i64::from(header.extra_features),
    );
    let encoding = ObservationEncoding::from_wire(header.encoding).ok_or_else(|| {
        BatchError::new(
            RejectReason::ObservationEncoding,
            "observations.encoding",
            format!("{} is not a known encoding", header.encoding),
        )
    })?;
    let n = header.num_transitions as usize;
    let m = header.num_observations as usize;
    let (columns, rest) = payload.split_at(ROW_BYTES * n);
    let (offsets, data) = rest.split_at(4 * m);
    let offsets = offsets
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let batch = ValidBatch::new(TransitionBatch {
        layout,
        num_actions: header.num_actions,
        // Whole rows: the payload's length is the header's.
        columns: Columns::read_le(columns).unwrap_or_default(),
        observations: ObservationPool::from_parts(encoding, offsets, data.to_vec()),
    })?;
    Ok((table, header.batch_id, batch))
}

/// Name of the insert service of `table`.
pub fn service_name(prefix: &str, table: &str) -> String {
    format!("{prefix}/replay/{table}/insert")
}

/// Name of the acknowledgement service of `table`.
pub fn ack_service_name(prefix: &str, table: &str) -> String {
    format!("{prefix}/replay/{table}/acks")
}

/// Acknowledgements one publisher's subscriber holds before the oldest are
/// overwritten (a publisher that does not poll loses old answers, never
/// blocks the server).
pub const ACK_BUFFER: usize = 1024;

/// Why shared memory could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ShmError {
    /// An iceoryx2 call failed (node, service, port or loan).
    #[error("iceoryx2 {what}: {message}")]
    Iceoryx {
        /// What was being done.
        what: &'static str,
        /// iceoryx2's error.
        message: String,
    },
    /// The batch does not fit a frame; it was not sent.
    #[error("invalid batch: {0}")]
    Invalid(#[from] BatchError),
    /// No replay server is subscribed; the batch was not delivered.
    #[error("no replay server is listening on {service}")]
    NoSubscriber {
        /// The service name.
        service: String,
    },
    /// Batches sent were not acknowledged within the timeout.
    #[error("{pending} batches on {service} not acknowledged within {timeout:?}")]
    Unacknowledged {
        /// The service name.
        service: String,
        /// Batches still waiting for an answer.
        pending: usize,
        /// The timeout.
        timeout: Duration,
    },
    /// The server's queue stayed full for the whole send timeout.
    #[error("the replay server's queue on {service} stayed full for {timeout:?}; batch dropped")]
    Full {
        /// The service name.
        service: String,
        /// The timeout.
        timeout: Duration,
    },
}

impl ShmError {
    /// Wraps an iceoryx2 error (they implement `Debug`, not always
    /// `Error`).
    pub fn iceoryx(what: &'static str, e: impl fmt::Debug) -> Self {
        ShmError::Iceoryx {
            what,
            message: format!("{e:?}"),
        }
    }
}

/// A fresh iceoryx2 node for this process. iceoryx2's own console log is
/// limited to errors unless `IOX2_LOG_LEVEL` says otherwise (it warns about
/// running on its default config, which is what we want).
pub fn node() -> Result<Node<ipc::Service>, ShmError> {
    set_log_level_from_env_or(LogLevel::Error);
    NodeBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| ShmError::iceoryx("creating node", e))
}

/// Opens (or creates) the insert service of `table`, with the settings both
/// sides share: no history, no overflow (a full queue pushes back on the
/// publisher instead of dropping batches), `shm_buffer` batches queued.
pub fn open_batch_service(
    node: &Node<ipc::Service>,
    config: &TransportConfig,
    table: &str,
) -> Result<PortFactory<ipc::Service, [u8], BatchFrameHeader>, ShmError> {
    let settings = FrameServiceSettings {
        safe_overflow: false,
        history: 0,
        subscriber_buffer: config.shm_buffer,
        borrowed_samples: 4,
        max_publishers: config.shm_max_publishers,
        max_subscribers: 4,
    };
    let name = service_name(&config.shm_prefix, table);
    open_frame_service(node, &name, settings, "opening service")
}

/// Opens (or creates) the acknowledgement service of `table`: one server
/// publishes, every batch publisher subscribes; old answers are overwritten
/// rather than blocking the server.
pub fn open_ack_service(
    node: &Node<ipc::Service>,
    config: &TransportConfig,
    table: &str,
) -> Result<PortFactory<ipc::Service, ShmInsertAck, ()>, ShmError> {
    let name = iox::service_name(&ack_service_name(&config.shm_prefix, table))?;
    node.service_builder(&name)
        .publish_subscribe::<ShmInsertAck>()
        .enable_safe_overflow(true)
        .history_size(0)
        .subscriber_max_buffer_size(ACK_BUFFER)
        .subscriber_max_borrowed_samples(4)
        .max_publishers(4)
        .max_subscribers(config.shm_max_publishers)
        .open_or_create()
        .map_err(|e| ShmError::iceoryx("opening ack service", e))
}

/// What the server did with one batch sent over shared memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShmAck {
    /// The id given to [`ShmBatchPublisher::send`].
    pub batch_id: u64,
    /// `Ok((inserted, table_size))` once stored, or why it was rejected.
    pub outcome: Result<(u32, u64), RejectReason>,
}

/// An actor's publisher of batches to the replay server on this host.
///
/// Not `Send`: create and use it on one thread. Each [`send`](Self::send)
/// writes a validated batch into shared memory once and hands it to the
/// server's queue; it waits at most `shm_send_timeout_ms` when the queue
/// is full and fails when no server listens, so the caller can buffer and
/// retry (or fall back to gRPC). [`poll_acks`](Self::poll_acks) returns the
/// server's answers (stored or rejected) for batches sent;
/// [`flush`](Self::flush) waits for all of them.
pub struct ShmBatchPublisher {
    service_name: String,
    table: String,
    timeout: Duration,
    id: u128,
    in_flight: std::collections::VecDeque<u64>,
    publisher: Publisher<ipc::Service, [u8], BatchFrameHeader>,
    acks: Subscriber<ipc::Service, ShmInsertAck, ()>,
    service: PortFactory<ipc::Service, [u8], BatchFrameHeader>,
    _ack_service: PortFactory<ipc::Service, ShmInsertAck, ()>,
    _node: Node<ipc::Service>,
}

impl fmt::Debug for ShmBatchPublisher {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ShmBatchPublisher")
            .field("service", &self.service_name)
            .field("timeout", &self.timeout)
            .field("in_flight", &self.in_flight.len())
            .finish_non_exhaustive()
    }
}

impl ShmBatchPublisher {
    /// A publisher of batches for `table`.
    pub fn new(config: &TransportConfig, table: &str) -> Result<Self, ShmError> {
        let node = node()?;
        let service = open_batch_service(&node, config, table)?;
        let timeout = Duration::from_millis(config.shm_send_timeout_ms);
        let publisher = service
            .publisher_builder()
            .initial_max_slice_len(config.shm_initial_batch_bytes)
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .set_backpressure_handler(move |info: &iceoryx2::port::BackpressureInfo| {
                if info.elapsed_time < timeout {
                    std::thread::sleep(Duration::from_micros(200));
                    BackpressureAction::Retry
                } else {
                    BackpressureAction::DiscardDataAndFail
                }
            })
            .create()
            .map_err(|e| ShmError::iceoryx("creating publisher", e))?;
        let ack_service = open_ack_service(&node, config, table)?;
        let acks = ack_service
            .subscriber_builder()
            .buffer_size(ACK_BUFFER)
            .create()
            .map_err(|e| ShmError::iceoryx("creating ack subscriber", e))?;
        Ok(Self {
            service_name: service_name(&config.shm_prefix, table),
            table: table.to_owned(),
            timeout,
            id: publisher.id().value(),
            in_flight: std::collections::VecDeque::new(),
            publisher,
            acks,
            service,
            _ack_service: ack_service,
            _node: node,
        })
    }

    /// The service this publisher sends on.
    pub fn service_name(&self) -> &str {
        &self.service_name
    }

    /// Number of replay servers listening.
    pub fn subscribers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    /// Batches sent and not yet answered, oldest first.
    pub fn in_flight(&self) -> impl Iterator<Item = u64> + '_ {
        self.in_flight.iter().copied()
    }

    /// Sends one batch. `Ok` means a replay server's queue holds it; the
    /// server validates it (it trusts nothing from another process), stores
    /// it and answers (see [`poll_acks`](Self::poll_acks)).
    /// [`ShmError::Invalid`] means it does not fit a frame.
    pub fn send(&mut self, batch_id: u64, batch: &ValidBatch) -> Result<(), ShmError> {
        let (header, len) = BatchFrameHeader::for_batch(&self.table, batch_id, batch)?;
        let mut sample = self
            .publisher
            .loan_slice(len)
            .map_err(|e| ShmError::iceoryx("loaning a slot", e))?;
        *sample.user_header_mut() = header;
        write_frame(batch, sample.payload_mut());
        match sample.send() {
            // Nobody got it: either nobody listens, or the only queue stayed
            // full for the whole timeout (iceoryx2 reports both as zero
            // deliveries).
            Ok(0) if self.subscribers() > 0 => Err(ShmError::Full {
                service: self.service_name.clone(),
                timeout: self.timeout,
            }),
            Ok(0) => Err(ShmError::NoSubscriber {
                service: self.service_name.clone(),
            }),
            Ok(_) => {
                self.in_flight.push_back(batch_id);
                Ok(())
            }
            Err(iceoryx2::port::SendError::UnableToDeliver) => Err(ShmError::Full {
                service: self.service_name.clone(),
                timeout: self.timeout,
            }),
            Err(e) => Err(ShmError::iceoryx("sending", e)),
        }
    }

    /// The server's answers that arrived for this publisher's batches, in
    /// the order received; does not wait.
    pub fn poll_acks(&mut self) -> Result<Vec<ShmAck>, ShmError> {
        let mut out = Vec::new();
        while let Some(sample) = self
            .acks
            .receive()
            .map_err(|e| ShmError::iceoryx("receiving acks", e))?
        {
            let ack = *sample.payload();
            if ack.publisher() != self.id {
                continue;
            }
            if let Some(i) = self.in_flight.iter().position(|b| *b == ack.batch_id) {
                self.in_flight.remove(i);
            }
            out.push(ShmAck {
                batch_id: ack.batch_id,
                outcome: ack.outcome(),
            });
        }
        Ok(out)
    }

    /// Waits until every batch sent is answered, at most `timeout`;
    /// returns the answers. Call before dropping the publisher: iceoryx2
    /// drops batches still queued from a publisher that is gone.
    pub fn flush(&mut self, timeout: Duration) -> Result<Vec<ShmAck>, ShmError> {
        let start = std::time::Instant::now();
        let mut acks = self.poll_acks()?;
        while !self.in_flight.is_empty() {
            if start.elapsed() >= timeout {
                return Err(ShmError::Unacknowledged {
                    service: self.service_name.clone(),
                    pending: self.in_flight.len(),
                    timeout,
                });
            }
            std::thread::sleep(Duration::from_millis(1));
            acks.extend(self.poll_acks()?);
        }
        Ok(acks)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossroads_types::batch::Transition;

    #[test]
    fn ack_round_trip() {
        let id = (7u128 << 64) | 9;
        let a = ShmInsertAck::new(id, 3, Ok((10, 99)));
        assert_eq!((a.publisher(), a.outcome()), (id, Ok((10, 99))));
        for reason in RejectReason::ALL {
            assert_eq!(ShmInsertAck::new(id, 3, Err(reason)).outcome(), Err(reason));
        }
    }

    #[test]
    fn frame_round_trip() {
        let mut b = TransitionBatch::new(
            ObservationLayout::new("toy", 1, 2, 2, 0),
            3,
            ObservationEncoding::SparseF32,
        );
        let o0 = b.push_observation(&[0.0, 1.0, 0.0, 0.0]);
        let o1 = b.push_observation(&[0.5, 0.0, 0.0, 0.0]);
        for i in 0..3 {
            b.push(Transition {
                observation: o0,
                action: i,
                reward: i as f32,
                discount: 0.5,
                priority: 1.0 + i as f32,
                next_observation: o1,
            });
        }
        let b = ValidBatch::new(b).expect("valid");
        let (header, len) = BatchFrameHeader::for_batch("t", 42, &b).expect("fits");
        let mut payload = vec![0; len];
        write_frame(&b, &mut payload);
        let (table, id, back) = read_frame(&header, &payload).expect("valid");
        assert_eq!((table.as_str(), id), ("t", 42));
        assert_eq!(back, b);

        let mut long = b.clone().into_inner();
        long.layout.kind = "k".repeat(MAX_KIND + 1);
        let long = ValidBatch::new(long).expect("valid, only too long for a frame");
        let err = BatchFrameHeader::for_batch("t", 0, &long).expect_err("kind too long");
        assert_eq!(err.to_string(), "layout.kind: 33 bytes is above 32");
        let err =
            BatchFrameHeader::for_batch(&"t".repeat(MAX_TABLE + 1), 0, &b).expect_err("table");
        assert_eq!(err.to_string(), "table: 65 bytes is above 64");

        let err = read_frame(&header, &payload[..len - 1]).expect_err("short");
        assert_eq!(err.field, "payload");
        let mut wrong = header;
        wrong.magic = 0;
        assert!(read_frame(&wrong, &payload).is_err());
        let mut nan = payload.clone();
        nan[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
        let err = read_frame(&header, &nan).expect_err("NaN reward");
        assert_eq!(err.field, "rewards[0]");
    }
}

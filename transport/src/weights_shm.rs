//! Weights over iceoryx2 shared memory, for actors on the learner's host.
//!
//! One sample of the publish-subscribe service `<prefix>/learner/weights`
//! ([`service_name`]) is the `#[repr(C)]` [`WeightsFrameHeader`] and a `[u8]`
//! payload holding the safetensors bytes (which carry the network spec and
//! version in their metadata). The service keeps a history of one sample,
//! so a subscriber that joins late gets the latest weights at once; a
//! subscriber's queue overwrites its oldest sample, so a slow actor skips
//! versions instead of holding the learner back. Both sides open the
//! service with [`open_weights_service`].

use std::fmt;

use crossroads_config::TransportConfig;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crate::shm::{ShmError, node};

/// `CRW1`, little-endian: marks a weights frame.
pub const WEIGHTS_MAGIC: u32 = u32::from_le_bytes(*b"CRW1");

/// The fixed part of a weights sample. Plain data (`#[repr(C)]`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("crossroads.v1.WeightsFrameHeader")]
#[repr(C)]
pub struct WeightsFrameHeader {
    /// [`WEIGHTS_MAGIC`].
    pub magic: u32,
    /// Layout version, 1.
    pub frame_version: u32,
    /// Weights version.
    pub weights_version: u64,
    /// Learner update step of the weights.
    pub update_step: u64,
    /// Unix milliseconds of publication.
    pub published_unix_ms: i64,
}

/// Name of the weights service.
pub fn service_name(prefix: &str) -> String {
    format!("{prefix}/learner/weights")
}

/// Opens (or creates) the weights service with the settings both sides
/// share.
pub fn open_weights_service(
    node: &Node<ipc::Service>,
    config: &TransportConfig,
) -> Result<PortFactory<ipc::Service, [u8], WeightsFrameHeader>, ShmError> {
    let name = service_name(&config.shm_prefix);
    let name: ServiceName = name
        .as_str()
        .try_into()
        .map_err(|e| ShmError::iceoryx("service name", e))?;
    node.service_builder(&name)
        .publish_subscribe::<[u8]>()
        .user_header::<WeightsFrameHeader>()
        .enable_safe_overflow(true)
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .subscriber_max_borrowed_samples(1)
        .max_publishers(1)
        .max_subscribers(config.shm_max_publishers)
        .open_or_create()
        .map_err(|e| ShmError::iceoryx("opening weights service", e))
}

/// The learner's side. Not `Send`: created and used by the training
/// thread.
pub struct ShmWeightsPublisher {
    publisher: Publisher<ipc::Service, [u8], WeightsFrameHeader>,
    _service: PortFactory<ipc::Service, [u8], WeightsFrameHeader>,
    _node: Node<ipc::Service>,
    name: String,
}

impl fmt::Debug for ShmWeightsPublisher {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ShmWeightsPublisher")
            .field("service", &self.name)
            .finish_non_exhaustive()
    }
}

impl ShmWeightsPublisher {
    /// A publisher whose first slot fits `initial_bytes` (slots grow).
    pub fn new(config: &TransportConfig, initial_bytes: usize) -> Result<Self, ShmError> {
        let node = node()?;
        let service = open_weights_service(&node, config)?;
        let publisher = service
            .publisher_builder()
            .initial_max_slice_len(initial_bytes.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| ShmError::iceoryx("creating weights publisher", e))?;
        Ok(Self {
            publisher,
            _service: service,
            _node: node,
            name: service_name(&config.shm_prefix),
        })
    }

    /// The service name.
    pub fn service_name(&self) -> &str {
        &self.name
    }

    /// Publishes one version; returns the number of subscribers reached.
    pub fn publish(
        &mut self,
        weights_version: u64,
        update_step: u64,
        published_unix_ms: i64,
        safetensors: &[u8],
    ) -> Result<usize, ShmError> {
        let mut sample = self
            .publisher
            .loan_slice(safetensors.len())
            .map_err(|e| ShmError::iceoryx("loaning a weights slot", e))?;
        *sample.user_header_mut() = WeightsFrameHeader {
            magic: WEIGHTS_MAGIC,
            frame_version: 1,
            weights_version,
            update_step,
            published_unix_ms,
        };
        sample.payload_mut().copy_from_slice(safetensors);
        sample
            .send()
            .map_err(|e| ShmError::iceoryx("sending weights", e))
    }

    /// Connects subscribers that joined since the last call and hands them
    /// the latest sample (iceoryx2 delivers history on connection).
    pub fn update_connections(&self) {
        if let Err(e) = self.publisher.update_connections() {
            tracing::debug!(error = ?e, "updating weights subscribers");
        }
    }
}

/// One version received over shared memory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ShmWeights {
    /// Weights version.
    pub version: u64,
    /// Update step.
    pub update_step: u64,
    /// Unix milliseconds of publication.
    pub published_unix_ms: i64,
    /// The safetensors bytes (load with
    /// `crossroads_model::QNetwork::load_safetensors`, which checks the
    /// spec).
    pub safetensors: Vec<u8>,
}

/// An actor's side: polls for the newest weights. Not `Send`.
pub struct ShmWeightsSubscriber {
    subscriber: Subscriber<ipc::Service, [u8], WeightsFrameHeader>,
    _service: PortFactory<ipc::Service, [u8], WeightsFrameHeader>,
    _node: Node<ipc::Service>,
}

impl fmt::Debug for ShmWeightsSubscriber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ShmWeightsSubscriber")
            .finish_non_exhaustive()
    }
}

impl ShmWeightsSubscriber {
    /// A subscriber that asks for the latest published sample on joining.
    pub fn new(config: &TransportConfig) -> Result<Self, ShmError> {
        let node = node()?;
        let service = open_weights_service(&node, config)?;
        let subscriber = service
            .subscriber_builder()
            .buffer_size(1)
            .history_request(1)
            .create()
            .map_err(|e| ShmError::iceoryx("creating weights subscriber", e))?;
        Ok(Self {
            subscriber,
            _service: service,
            _node: node,
        })
    }

    /// The newest weights received since the last call, if any; frames that
    /// are not valid weights frames are skipped with a warning.
    pub fn latest(&mut self) -> Result<Option<ShmWeights>, ShmError> {
        let mut newest: Option<ShmWeights> = None;
        while let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| ShmError::iceoryx("receiving weights", e))?
        {
            let h = *sample.user_header();
            if h.magic != WEIGHTS_MAGIC || h.frame_version != 1 {
                tracing::warn!(magic = h.magic, "skipping a frame that is not weights");
                continue;
            }
            if newest
                .as_ref()
                .is_none_or(|n| h.weights_version > n.version)
            {
                newest = Some(ShmWeights {
                    version: h.weights_version,
                    update_step: h.update_step,
                    published_unix_ms: h.published_unix_ms,
                    safetensors: sample.payload().to_vec(),
                });
            }
        }
        Ok(newest)
    }
}

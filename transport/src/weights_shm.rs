//! Weights over iceoryx2 shared memory, for actors on the learner's host.
//!
//! One sample of the publish-subscribe service `<prefix>/learner/weights`
//! ([`service_name`]) is the `#[repr(C)]` [`WeightsFrameHeader`] and a `[u8]`
//! payload holding the safetensors bytes (which carry the network spec and
//! version in their metadata). The service keeps a history of one sample,
//! so a subscriber that joins late gets the latest weights at once; a
//! subscriber's queue overwrites its oldest sample, so a slow actor skips
//! versions instead of holding the learner back. Both sides open the
//! service with [`open_weights_service`]; [`read_weights_frame`] is the
//! subscriber's whole check of a received frame.

use std::fmt;

use crossroads_config::TransportConfig;
use crossroads_types::{SpecError, Weights};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crate::iox::{FrameServiceSettings, open_frame_service};
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
    /// [`WEIGHTS_FRAME_VERSION`].
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
    let settings = FrameServiceSettings {
        safe_overflow: true,
        history: 1,
        subscriber_buffer: 1,
        borrowed_samples: 1,
        max_publishers: 1,
        max_subscribers: config.shm_max_publishers,
    };
    let name = service_name(&config.shm_prefix);
    open_frame_service(node, &name, settings, "opening weights service")
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
    pub fn publish(&mut self, weights: &Weights) -> Result<usize, ShmError> {
        let mut sample = self
            .publisher
            .loan_slice(weights.safetensors.len())
            .map_err(|e| ShmError::iceoryx("loaning a weights slot", e))?;
        *sample.user_header_mut() = weights_frame_header(weights);
        sample.payload_mut().copy_from_slice(&weights.safetensors);
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

    /// The newest weights received since the last call, if any. Frames
    /// that [`read_weights_frame`] refuses (not a weights frame, unreadable
    /// safetensors metadata, or metadata that do not say the frame's
    /// version) are skipped with a warning.
    pub fn latest(&mut self) -> Result<Option<Weights>, ShmError> {
        let mut newest: Option<(WeightsFrameHeader, Vec<u8>)> = None;
        while let Some(sample) = self
            .subscriber
            .receive()
            .map_err(|e| ShmError::iceoryx("receiving weights", e))?
        {
            let h = *sample.user_header();
            if h.magic != WEIGHTS_MAGIC || h.frame_version != WEIGHTS_FRAME_VERSION {
                tracing::warn!(magic = h.magic, "skipping a frame that is not weights");
                continue;
            }
            if newest
                .as_ref()
                .is_none_or(|(n, _)| h.weights_version > n.weights_version)
            {
                newest = Some((h, sample.payload().to_vec()));
            }
        }
        let Some((h, safetensors)) = newest else {
            return Ok(None);
        };
        match read_weights_frame(&h, safetensors) {
            Ok(w) => Ok(Some(w)),
            Err(e) => {
                tracing::warn!(version = h.weights_version, error = %e, "skipping weights");
                Ok(None)
            }
        }
    }
}

/// Why a received frame is not weights.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WeightsFrameError {
    /// Another magic or frame version.
    #[error("not a weights frame (magic {magic:#x}, frame version {frame_version})")]
    NotWeights {
        /// The header's magic.
        magic: u32,
        /// The header's frame version.
        frame_version: u32,
    },
    /// The safetensors bytes or their metadata are not valid weights.
    #[error("unreadable weights: {0}")]
    Unreadable(#[from] SpecError),
    /// The header and the metadata name different versions.
    #[error("the frame says version {frame}, its metadata {metadata}")]
    VersionMismatch {
        /// The header's version.
        frame: u64,
        /// The metadata's.
        metadata: u64,
    },
}

/// Layout version of [`WeightsFrameHeader`].
pub const WEIGHTS_FRAME_VERSION: u32 = 1;

/// Reads one received frame into [`Weights`]: a weights header, and
/// safetensors bytes whose metadata (read from the header only; the
/// tensors are checked where they are loaded) are valid and name the
/// header's version. Trusts nothing of either.
pub fn read_weights_frame(
    header: &WeightsFrameHeader,
    payload: Vec<u8>,
) -> Result<Weights, WeightsFrameError> {
    if header.magic != WEIGHTS_MAGIC || header.frame_version != WEIGHTS_FRAME_VERSION {
        return Err(WeightsFrameError::NotWeights {
            magic: header.magic,
            frame_version: header.frame_version,
        });
    }
    let w = Weights::from_safetensors(payload, header.update_step, header.published_unix_ms)?;
    if w.version != header.weights_version {
        return Err(WeightsFrameError::VersionMismatch {
            frame: header.weights_version,
            metadata: w.version,
        });
    }
    Ok(w)
}

/// The header of `weights`' frame.
pub fn weights_frame_header(weights: &Weights) -> WeightsFrameHeader {
    WeightsFrameHeader {
        magic: WEIGHTS_MAGIC,
        frame_version: WEIGHTS_FRAME_VERSION,
        weights_version: weights.version,
        update_step: weights.update_step,
        published_unix_ms: weights.published_unix_ms,
    }
}

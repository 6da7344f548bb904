//! How crossroads opens its iceoryx2 services: one function for every
//! publish-subscribe service of `[u8]` frames behind a `#[repr(C)]` user
//! header (transition batches in [`shm`](crate::shm), weights in
//! [`weights_shm`](crate::weights_shm)), so each side opens a service with
//! the same settings, as iceoryx2 requires, and names it the same way.
//!
//! iceoryx2 keeps its segments in `/dev/shm` and its service bookkeeping
//! under `/tmp/iceoryx2`: processes that share a service (containers too)
//! must share both, the IPC namespace and a user id, and agree on
//! `transport.shm_prefix`, which starts every service name.

use std::fmt::Debug;

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

use crate::shm::ShmError;

/// The settings of a frame service that every side must agree on
/// (iceoryx2 refuses to open a service with settings other than its
/// creator's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameServiceSettings {
    /// A full subscriber queue overwrites its oldest frame (true) or pushes
    /// back on the publisher (false).
    pub safe_overflow: bool,
    /// Frames kept for subscribers that join later.
    pub history: usize,
    /// Frames a subscriber's queue holds.
    pub subscriber_buffer: usize,
    /// Frames a subscriber may hold at once.
    pub borrowed_samples: usize,
    /// Publishers at most.
    pub max_publishers: usize,
    /// Subscribers at most.
    pub max_subscribers: usize,
}

/// `name` as an iceoryx2 service name.
pub fn service_name(name: &str) -> Result<ServiceName, ShmError> {
    name.try_into()
        .map_err(|e| ShmError::iceoryx("service name", e))
}

/// Opens (or creates) the publish-subscribe service `name` of `[u8]`
/// frames behind a `Header`, with `settings`; `what` names the service in
/// the error.
pub fn open_frame_service<Header: Debug + ZeroCopySend>(
    node: &Node<ipc::Service>,
    name: &str,
    settings: FrameServiceSettings,
    what: &'static str,
) -> Result<PortFactory<ipc::Service, [u8], Header>, ShmError> {
    node.service_builder(&service_name(name)?)
        .publish_subscribe::<[u8]>()
        .user_header::<Header>()
        .enable_safe_overflow(settings.safe_overflow)
        .history_size(settings.history)
        .subscriber_max_buffer_size(settings.subscriber_buffer)
        .subscriber_max_borrowed_samples(settings.borrowed_samples)
        .max_publishers(settings.max_publishers)
        .max_subscribers(settings.max_subscribers)
        .open_or_create()
        .map_err(|e| ShmError::iceoryx(what, e))
}

//! [`WeightsHub`]: the latest published weights, for the gRPC stream and
//! `GetLatestWeights`. Versions only increase.

use std::sync::Arc;

use crossroads_model::NetworkSpec;
use tokio::sync::watch;

/// One published version of the online network.
#[derive(Debug, Clone, PartialEq)]
pub struct PublishedWeights {
    /// Strictly increasing over the learner's life, across restores and
    /// restarts.
    pub version: u64,
    /// Update step the weights come from.
    pub update_step: u64,
    /// The network.
    pub spec: NetworkSpec,
    /// safetensors bytes (with the spec and version in their metadata).
    pub safetensors: Vec<u8>,
    /// Unix milliseconds of publication.
    pub published_unix_ms: i64,
}

/// Holds the latest weights; subscribers are woken on each new version
/// (one that falls behind sees only the newest, never a stale one).
/// Thread-safe and cheap to share.
#[derive(Debug)]
pub struct WeightsHub {
    tx: watch::Sender<Option<Arc<PublishedWeights>>>,
}

impl Default for WeightsHub {
    fn default() -> Self {
        Self::new()
    }
}

impl WeightsHub {
    /// A hub with nothing published.
    pub fn new() -> Self {
        Self {
            tx: watch::Sender::new(None),
        }
    }

    /// Publishes `weights` if newer than the latest; returns whether it was.
    pub fn publish(&self, weights: PublishedWeights) -> bool {
        let weights = Arc::new(weights);
        self.tx.send_if_modified(|latest| {
            if latest.as_ref().is_none_or(|l| weights.version > l.version) {
                *latest = Some(weights.clone());
                true
            } else {
                false
            }
        })
    }

    /// The latest weights, if any.
    pub fn latest(&self) -> Option<Arc<PublishedWeights>> {
        self.tx.borrow().clone()
    }

    /// A receiver that sees every later publication.
    pub fn subscribe(&self) -> watch::Receiver<Option<Arc<PublishedWeights>>> {
        self.tx.subscribe()
    }
}

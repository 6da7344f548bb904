//! [`WeightsHub`]: the latest published weights
//! ([`PublishedWeights`], a `crossroads_transport` type), for the gRPC
//! stream and `GetLatestWeights`. Versions only increase.

use std::sync::Arc;

use crossroads_transport::convert::PublishedWeights;
use tokio::sync::watch;

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

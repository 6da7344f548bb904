//! [`WeightsSlot`]: the newest [`Weights`] a process holds, newest wins.
//! The learner offers each version it publishes (its gRPC stream and
//! `GetLatestWeights` read the slot); an actor's subscription offers each
//! version it receives (its network reads the slot between steps).

use std::sync::Arc;

use crossroads_types::Weights;
use tokio::sync::watch;

/// Holds the newest weights offered; older or equal versions offered later
/// are ignored, so versions only increase. Cheap to clone (clones share the
/// slot) and thread-safe: any thread offers, any number of
/// [`WeightsWatch`]es read.
#[derive(Debug, Clone)]
pub struct WeightsSlot {
    tx: Arc<watch::Sender<Option<Arc<Weights>>>>,
}

impl Default for WeightsSlot {
    fn default() -> Self {
        Self::new()
    }
}

impl WeightsSlot {
    /// An empty slot.
    pub fn new() -> Self {
        Self {
            tx: Arc::new(watch::Sender::new(None)),
        }
    }

    /// Keeps `weights` if newer than what the slot holds (waking every
    /// watch); returns whether it was.
    pub fn offer(&self, weights: Weights) -> bool {
        let weights = Arc::new(weights);
        self.tx.send_if_modified(|held| {
            if held.as_ref().is_none_or(|h| weights.version > h.version) {
                *held = Some(Arc::clone(&weights));
                true
            } else {
                false
            }
        })
    }

    /// The version held (0 when none).
    pub fn version(&self) -> u64 {
        self.tx.borrow().as_ref().map_or(0, |w| w.version)
    }

    /// The weights held, if any.
    pub fn latest(&self) -> Option<Arc<Weights>> {
        self.tx.borrow().clone()
    }

    /// A reader that sees what the slot holds now, then each later offer
    /// that was kept (one that falls behind sees only the newest).
    pub fn watch(&self) -> WeightsWatch {
        let mut rx = self.tx.subscribe();
        rx.mark_changed();
        WeightsWatch { rx }
    }
}

/// A reader of a [`WeightsSlot`], from [`WeightsSlot::watch`].
#[derive(Debug)]
pub struct WeightsWatch {
    rx: watch::Receiver<Option<Arc<Weights>>>,
}

impl WeightsWatch {
    /// The slot's weights if the slot changed since the last call and they
    /// are newer than `version`. Cheap when nothing changed (one atomic
    /// load), so an acting loop can ask before every step.
    pub fn newer_than(&mut self, version: u64) -> Option<Arc<Weights>> {
        if !self.rx.has_changed().unwrap_or(false) {
            return None;
        }
        self.rx
            .borrow_and_update()
            .as_ref()
            .filter(|w| w.version > version)
            .cloned()
    }

    /// Waits until the slot changes (the next
    /// [`newer_than`](Self::newer_than) sees the change); `false` once every
    /// [`WeightsSlot`] is gone.
    pub async fn changed(&mut self) -> bool {
        let alive = self.rx.changed().await.is_ok();
        // `changed` marks the value seen; `newer_than` must still read it.
        self.rx.mark_changed();
        alive
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crossroads_types::{NetworkSpec, ObservationLayout, TrunkKind};

    fn weights(version: u64) -> Weights {
        Weights {
            version,
            update_step: version * 10,
            published_unix_ms: 0,
            spec: NetworkSpec::new(
                ObservationLayout::new("toy", 2, 3, 4, 1),
                "ttg",
                TrunkKind::Mlp,
                vec![8],
            )
            .expect("spec"),
            safetensors: Vec::new(),
        }
    }

    #[test]
    fn the_newest_version_wins_and_watches_see_it_once() {
        let slot = WeightsSlot::new();
        assert_eq!(slot.version(), 0);
        assert!(slot.latest().is_none());
        assert!(slot.offer(weights(3)));
        // A watch made after the offer still sees what the slot holds.
        let mut watch = slot.watch();
        assert_eq!(watch.newer_than(0).map(|w| w.version), Some(3));
        assert!(watch.newer_than(0).is_none(), "seen already");
        assert!(!slot.offer(weights(2)), "older");
        assert!(!slot.offer(weights(3)), "the same");
        assert!(watch.newer_than(0).is_none());
        assert!(slot.clone().offer(weights(5)));
        assert_eq!(watch.newer_than(5), None, "not newer than 5");
        assert!(slot.offer(weights(6)));
        assert_eq!(watch.newer_than(5).map(|w| w.version), Some(6));
        assert_eq!(slot.version(), 6);
        assert_eq!(slot.latest().map(|w| w.update_step), Some(60));
    }

    #[tokio::test]
    async fn a_watch_wakes_on_a_newer_version_and_reads_it() {
        let slot = WeightsSlot::new();
        let mut watch = slot.watch();
        assert!(watch.newer_than(0).is_none(), "empty");
        let offering = tokio::spawn({
            let slot = slot.clone();
            async move { slot.offer(weights(1)) }
        });
        assert!(watch.changed().await);
        assert!(offering.await.expect("offer"));
        assert_eq!(watch.newer_than(0).map(|w| w.version), Some(1));
        drop(slot);
        assert!(!watch.changed().await, "no slot left");
    }
}

//! The shutdown signal: servers and loops take a [`Shutdown`] as an input
//! and stop when it fires, whether from SIGINT, SIGTERM or a test.
//!
//! [`Shutdown::on_signals`] fires it on SIGINT or SIGTERM; a second signal
//! exits at once, unless it comes within [`SAME_REQUEST`] of the first (a
//! group kill or `timeout` delivers SIGTERM twice). [`Shutdown::child`]
//! stops one component alone.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use tokio_util::sync::CancellationToken;

/// Signals closer than this to the first one are the same request, not a
/// second one that forces an exit.
pub const SAME_REQUEST: std::time::Duration = std::time::Duration::from_secs(1);

/// A cloneable shutdown signal. Firing it is idempotent; every clone sees it.
///
/// Cheap to clone and to poll from any thread: async code awaits
/// [`Shutdown::wait`], synchronous loops (simulation workers) check
/// [`Shutdown::is_triggered`] between steps.
#[derive(Debug, Clone, Default)]
pub struct Shutdown {
    token: CancellationToken,
    by_signal: Arc<AtomicBool>,
}

impl Shutdown {
    /// A signal that only fires when [`Shutdown::trigger`] is called.
    pub fn new() -> Self {
        Self::default()
    }

    /// A signal that also fires on SIGINT or SIGTERM. A second signal exits
    /// the process at once with status 130, for when a clean stop hangs;
    /// signals within [`SAME_REQUEST`] of the first count as the same
    /// request (coreutils `timeout` and process-group kills deliver one
    /// SIGTERM twice, which must not skip a last checkpoint). Must be
    /// called inside a tokio runtime; the handlers are registered before
    /// it returns.
    pub fn on_signals() -> std::io::Result<Self> {
        use tokio::signal::unix::{SignalKind, signal};
        let shutdown = Self::new();
        let mut int = signal(SignalKind::interrupt())?;
        let mut term = signal(SignalKind::terminate())?;
        let fire = shutdown.clone();
        tokio::spawn(async move {
            let mut first: Option<std::time::Instant> = None;
            loop {
                let name = tokio::select! {
                    _ = int.recv() => "SIGINT",
                    _ = term.recv() => "SIGTERM",
                };
                if let Some(at) = first {
                    if at.elapsed() < SAME_REQUEST {
                        tracing::debug!(signal = name, "repeated signal, same request");
                        continue;
                    }
                    tracing::warn!(signal = name, "second signal, exiting now");
                    std::process::exit(130);
                }
                first = Some(std::time::Instant::now());
                tracing::info!(signal = name, "shutting down (send again to force)");
                fire.by_signal.store(true, Ordering::SeqCst);
                fire.trigger();
            }
        });
        Ok(shutdown)
    }

    /// Fires the signal.
    pub fn trigger(&self) {
        self.token.cancel();
    }

    /// Whether the signal has fired.
    pub fn is_triggered(&self) -> bool {
        self.token.is_cancelled()
    }

    /// Whether it fired because of SIGINT or SIGTERM.
    pub fn by_signal(&self) -> bool {
        self.by_signal.load(Ordering::SeqCst)
    }

    /// Completes when the signal fires (at once if it has).
    pub async fn wait(&self) {
        self.token.cancelled().await;
    }

    /// A child signal: fires with this one, and can also be fired alone to
    /// stop one component without stopping the rest.
    pub fn child(&self) -> Shutdown {
        Shutdown {
            token: self.token.child_token(),
            by_signal: self.by_signal.clone(),
        }
    }

    /// The underlying token, for APIs that take a `CancellationToken`.
    pub fn token(&self) -> &CancellationToken {
        &self.token
    }
}

//! Weights from the learner: a background subscription (the learner's gRPC
//! `SubscribeWeights` stream, or its iceoryx2 broadcast on the same host)
//! that keeps the newest version in a [`WeightsSlot`], and [`LiveNetwork`],
//! the Q-network that takes that version between two steps.
//!
//! Data flow: learner publishes version v -> the subscription receives it
//! (on a tokio task or, for iceoryx2, a thread of its own, since the
//! subscriber is not `Send`) -> [`WeightsSlot::offer`] keeps it if newer ->
//! at the start of the next [`ActionValues::q_values`] call the acting
//! thread loads it into its network (a few hundred microseconds for the
//! default network; the environments never wait on the network). While the
//! learner is unreachable the subscription retries with backoff and the
//! actor acts on the last weights it has. The iceoryx2 subscription polls
//! every 20 ms; [`LiveNetwork`] says which weights it accepts.

use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crossroads_common::{Backoff, Shutdown};
use crossroads_config::ActorTransport;
use crossroads_config::TransportConfig;
use crossroads_model::{NativeMlp, QNetwork};
use crossroads_transport::weights_shm::ShmWeightsSubscriber;
use crossroads_transport::{ClientSecurity, LearnerClient, WeightsSlot, WeightsWatch};
use crossroads_types::Weights;

use crate::error::ActorError;
use crate::metrics::ActorMetrics;
use crate::values::{ActionValues, ValuesError};
use crate::worker::Worker;

/// A Q-network that applies the newest version in its [`WeightsSlot`] at
/// the start of each [`ActionValues::q_values`] call, and reports the
/// version in use and its age, and each forward pass and its time, to
/// [`ActorMetrics`].
///
/// An MLP network in f32 is computed by [`NativeMlp`] over a copy of its
/// weights, made again for each version applied (0.67 M values for the
/// default network): at the actor's batch sizes libtorch's per-operator
/// overhead costs more than the arithmetic. Other networks (conv, bf16)
/// run in libtorch.
///
/// Weights of another architecture with the same input length and action
/// count replace the network; weights that cannot drive these environments
/// (another observation or action set) are an error naming both, which
/// stops the actor: acting on with weights the learner no longer trains
/// would fill the replay with useless transitions.
pub struct LiveNetwork {
    net: QNetwork,
    /// `net`'s forward pass in plain Rust, where it has one.
    native: Option<NativeMlp>,
    version: u64,
    applied_at: (Instant, Option<i64>),
    slot: WeightsWatch,
    metrics: ActorMetrics,
    applied: u64,
}

impl std::fmt::Debug for LiveNetwork {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveNetwork")
            .field("spec", self.net.spec())
            .field("version", &self.version)
            .field("native", &self.native.is_some())
            .field("applied", &self.applied)
            .finish_non_exhaustive()
    }
}

impl LiveNetwork {
    /// Starts from `net` (version 0, e.g. built from `[learner]` with the
    /// learner's seed) and follows `slot`.
    pub fn new(
        net: QNetwork,
        slot: &WeightsSlot,
        metrics: ActorMetrics,
    ) -> Result<Self, ActorError> {
        metrics.weights(0, 0.0);
        Ok(Self {
            native: native_of(&net)?,
            net,
            version: 0,
            applied_at: (Instant::now(), None),
            slot: slot.watch(),
            metrics,
            applied: 0,
        })
    }

    /// Whether the forward pass runs in plain Rust ([`NativeMlp`]) rather
    /// than libtorch.
    pub fn is_native(&self) -> bool {
        self.native.is_some()
    }

    /// The version in use (0: the initial network).
    pub fn version(&self) -> u64 {
        self.version
    }

    /// Versions applied so far.
    pub fn applied(&self) -> u64 {
        self.applied
    }

    /// The network in use.
    pub fn network(&self) -> &QNetwork {
        &self.net
    }

    /// Takes the slot's version if newer than the one in use; updates the
    /// version and staleness metrics either way.
    pub fn refresh(&mut self) -> Result<(), ActorError> {
        if let Some(w) = self.slot.newer_than(self.version) {
            self.apply(&w)?;
        }
        let age = match self.applied_at {
            (_, Some(published_ms)) => (unix_ms() - published_ms) as f64 / 1e3,
            (applied, None) => applied.elapsed().as_secs_f64(),
        };
        self.metrics.weights(self.version, age);
        Ok(())
    }

    fn apply(&mut self, w: &Weights) -> Result<(), ActorError> {
        if let Err(e) = self.net.load_safetensors(&w.safetensors) {
            let (net, _) = QNetwork::from_safetensors(&w.safetensors).map_err(|e2| {
                ActorError::Values(format!(
                    "weights version {} from the learner cannot be read: {e2} (loading into this network: {e})",
                    w.version
                ))
            })?;
            let (ours, theirs) = (self.net.spec(), net.spec());
            if ours.input_len() != theirs.input_len() || ours.num_actions != theirs.num_actions {
                return Err(ActorError::Values(format!(
                    "weights version {} from the learner are for {} observations of {} values and {} actions ({}); this actor's environments give {} values and take {} actions ({}); check that [actor] and [learner] name the same scenario kind and action set",
                    w.version,
                    theirs.observation.kind,
                    theirs.input_len(),
                    theirs.num_actions,
                    theirs.action_set,
                    ours.input_len(),
                    ours.num_actions,
                    ours.action_set,
                )));
            }
            tracing::info!(
                version = w.version,
                "the learner's network differs from the actor's first one; using the learner's"
            );
            let mut net = net;
            net.set_precision(self.net.precision());
            self.net = net;
        }
        self.native = native_of(&self.net)?;
        self.version = w.version;
        self.applied += 1;
        self.applied_at = (Instant::now(), Some(w.published_unix_ms));
        tracing::debug!(
            version = w.version,
            update_step = w.update_step,
            "applied newer weights"
        );
        Ok(())
    }
}

/// The plain-Rust forward pass of `net`, where it has one.
fn native_of(net: &QNetwork) -> Result<Option<NativeMlp>, ActorError> {
    NativeMlp::of(net)
        .map_err(|e| ActorError::Values(format!("copying the network's weights: {e}")))
}

impl LiveNetwork {
    /// [`LiveNetwork::refresh`], its error as an [`ActionValues`] one.
    fn refresh_for_values(&mut self) -> Result<(), ValuesError> {
        self.refresh().map_err(|e| match e {
            ActorError::Values(message) => ValuesError::from(message),
            other => Box::new(other),
        })
    }
}

impl ActionValues for LiveNetwork {
    fn obs_len(&self) -> usize {
        ActionValues::obs_len(&self.net)
    }

    fn num_actions(&self) -> usize {
        ActionValues::num_actions(&self.net)
    }

    fn q_values(&mut self, obs: &[f32], n: usize, out: &mut [f32]) -> Result<(), ValuesError> {
        self.refresh_for_values()?;
        let started = Instant::now();
        let result = match &mut self.native {
            Some(native) => native.q_values(obs, n, out).map_err(ValuesError::from),
            None => ActionValues::q_values(&mut self.net, obs, n, out),
        };
        self.metrics.forward_pass(started.elapsed().as_secs_f64());
        result
    }

    fn reads_sparse(&self) -> bool {
        ActionValues::reads_sparse(&self.net)
    }

    fn q_values_sparse(
        &mut self,
        rows: &[Vec<(u32, f32)>],
        out: &mut [f32],
    ) -> Result<(), ValuesError> {
        self.refresh_for_values()?;
        let started = Instant::now();
        let result = match &mut self.native {
            Some(native) => native.q_values_sparse(rows, out).map_err(ValuesError::from),
            None => ActionValues::q_values_sparse(&mut self.net, rows, out),
        };
        self.metrics.forward_pass(started.elapsed().as_secs_f64());
        result
    }
}

/// A running weights subscription; stops with its `Shutdown` (or
/// [`stop`](Self::stop)).
#[derive(Debug)]
pub struct WeightsSubscription {
    stop: Shutdown,
    worker: Option<Worker>,
}

impl WeightsSubscription {
    /// Starts receiving into `slot`: from the learner's gRPC stream at
    /// `connection.learner_endpoint` (needs a tokio runtime), or from its
    /// iceoryx2 broadcast under `connection.shm_prefix`. Neither needs the
    /// learner to be up.
    pub fn start(
        transport: ActorTransport,
        connection: &TransportConfig,
        slot: WeightsSlot,
        shutdown: &Shutdown,
    ) -> Result<Self, ActorError> {
        let stop = shutdown.child();
        let worker = match transport {
            ActorTransport::Grpc => {
                let timeout = Duration::from_millis(connection.connect_timeout_ms);
                let security = ClientSecurity::load(connection)
                    .map_err(|e| ActorError::Config(e.to_string()))?;
                let client = LearnerClient::new(&connection.learner_endpoint, &security, timeout)
                    .map_err(|e| {
                    ActorError::Config(format!("transport.learner_endpoint: {e}"))
                })?;
                let backoff = Backoff::from_config(connection);
                Worker::Task(tokio::spawn(grpc_worker(
                    client,
                    slot,
                    backoff,
                    stop.clone(),
                    connection.learner_endpoint.clone(),
                )))
            }
            ActorTransport::Shm => {
                let connection = connection.clone();
                let stop = stop.clone();
                Worker::thread("actor-shm-weights", "weights", move || {
                    shm_worker(&connection, &slot, &stop)
                })?
            }
        };
        Ok(Self {
            stop,
            worker: Some(worker),
        })
    }

    /// Stops receiving and waits for the worker.
    pub async fn stop(mut self) {
        self.stop.trigger();
        if let Some(worker) = self.worker.take() {
            let _ = worker.join().await;
        }
    }
}

impl Drop for WeightsSubscription {
    fn drop(&mut self) {
        self.stop.trigger();
    }
}

async fn grpc_worker(
    client: LearnerClient,
    slot: WeightsSlot,
    mut backoff: Backoff,
    stop: Shutdown,
    endpoint: String,
) {
    let mut failing = false;
    while !stop.is_triggered() {
        let subscribed = tokio::select! {
            () = stop.wait() => return,
            s = client.subscribe_weights(slot.version()) => s,
        };
        match subscribed {
            Ok(mut stream) => loop {
                let next = tokio::select! {
                    () = stop.wait() => return,
                    n = stream.next() => n,
                };
                match next {
                    Ok(Some(w)) => {
                        if failing {
                            tracing::info!(%endpoint, version = w.version, "receiving weights from the learner again");
                            failing = false;
                        }
                        backoff.reset();
                        slot.offer(w);
                    }
                    Ok(None) => {
                        tracing::info!(%endpoint, "the learner ended the weights stream; resubscribing");
                        break;
                    }
                    Err(e) => {
                        report(&mut failing, &endpoint, &e);
                        break;
                    }
                }
            },
            Err(e) => report(&mut failing, &endpoint, &e),
        }
        tokio::select! {
            () = stop.wait() => return,
            () = backoff.wait() => {}
        }
    }
}

fn report(failing: &mut bool, endpoint: &str, e: &dyn std::fmt::Display) {
    if *failing {
        tracing::debug!(%endpoint, error = %e, "learner still unreachable");
    } else {
        tracing::warn!(%endpoint, error = %e, "learner unreachable; acting on the last weights and retrying");
        *failing = true;
    }
}

/// How often the iceoryx2 subscriber looks for a newer version.
const SHM_POLL: Duration = Duration::from_millis(20);

fn shm_worker(connection: &TransportConfig, slot: &WeightsSlot, stop: &Shutdown) {
    let mut backoff = Backoff::from_config(connection);
    let mut failing = false;
    let what = format!("iceoryx2 service {}/learner/weights", connection.shm_prefix);
    while !stop.is_triggered() {
        match ShmWeightsSubscriber::new(connection) {
            Ok(mut subscriber) => {
                backoff.reset();
                while !stop.is_triggered() {
                    match subscriber.latest() {
                        Ok(Some(w)) => {
                            failing = false;
                            slot.offer(w);
                        }
                        Ok(None) => std::thread::sleep(SHM_POLL),
                        Err(e) => {
                            report(&mut failing, &what, &e);
                            break;
                        }
                    }
                }
            }
            Err(e) => report(&mut failing, &what, &e),
        }
        let delay = backoff.next_delay();
        let until = Instant::now() + delay;
        while !stop.is_triggered() && Instant::now() < until {
            std::thread::sleep(SHM_POLL.min(delay));
        }
    }
}

fn unix_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
}

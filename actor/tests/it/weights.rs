//! Newer weights reach a running actor: from a real learner over its gRPC
//! stream (the learner trained from a real replay server the actor fills),
//! and over the learner's iceoryx2 broadcast; a learner that goes away
//! leaves the actor acting on its last weights.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::RecvTimeoutError;
use std::time::Duration;

use crossroads_actor::{
    ActionValues, Actor, ActorMetrics, ActorSettings, LiveNetwork, PushConfig, Pusher, RunReport,
    WeightsSubscription,
};
use crossroads_common::Shutdown;
use crossroads_config::{ActorTransport, Config, SimConfig};
use crossroads_model::{NetworkSpec, QNetwork, TrunkKind};
use crossroads_transport::WeightsSlot;
use crossroads_transport::weights_shm::ShmWeightsPublisher;
use crossroads_types::Weights;

use crate::util::{actor_config, eventually, replay_config, transport, unique_prefix};

/// The simulator's layout of view `kind`.
fn layout(kind: &str) -> crossroads_types::ObservationLayout {
    crossroads_sim::observation_layout(kind).expect("a view")
}

fn small_spec() -> NetworkSpec {
    NetworkSpec::new(layout("ttg"), "ttg", TrunkKind::Mlp, vec![32, 32]).expect("spec")
}

/// A training actor on left with a small network following `slot`.
fn live_actor(slot: &WeightsSlot) -> (Actor, LiveNetwork, ActorMetrics) {
    let config = actor_config(4, 32);
    let settings = ActorSettings::from_config(&SimConfig::default(), &config, 0).expect("settings");
    let metrics = ActorMetrics::new(None, "left").expect("metrics");
    let actor = Actor::new(settings, metrics.clone()).expect("actor");
    let net = QNetwork::new(small_spec(), 1).expect("network");
    let live = LiveNetwork::new(net, slot, metrics.clone()).expect("live network");
    (actor, live, metrics)
}

/// Triggers its shutdown when dropped: a test that panics before it stops
/// the acting thread still ends it, so the runtime can shut down and the
/// failure is reported instead of hanging.
struct StopOnDrop(Shutdown);

impl Drop for StopOnDrop {
    fn drop(&mut self) {
        self.0.trigger();
    }
}

/// Runs the actor on a blocking thread until `stop`; returns its report and
/// the versions applied.
fn spawn_acting(
    mut actor: Actor,
    mut live: LiveNetwork,
    pusher: Option<Pusher>,
    stop: Shutdown,
) -> tokio::task::JoinHandle<(RunReport, u64, Option<Pusher>)> {
    tokio::task::spawn_blocking(move || {
        let report = actor
            .run(&mut live, pusher.as_ref(), &stop, None)
            .expect("acting");
        (report, live.applied(), pusher)
    })
}

fn version(metrics: &ActorMetrics) -> u64 {
    u64::try_from(metrics.weights_version.get()).unwrap_or(0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_running_actor_follows_a_real_learner_over_grpc_and_outlives_it() {
    let servers = Shutdown::new();
    let mut config: Config = replay_config("127.0.0.1:0", None);
    config.replay.min_size_to_sample = 64;
    let replay = crossroads_replay::start(&config, None, servers.clone())
        .await
        .expect("replay");
    let replay_url = format!("http://{}", replay.local_addr());
    config.transport = transport(&replay_url, "unused");
    config.learner.listen = ([127, 0, 0, 1], 0).into();
    config.sim.action_set = "ttg".to_owned();
    crossroads_actor::resolve_observation(&mut config.sim).expect("a built-in pairing");
    config.learner.hidden = vec![32, 32];
    config.learner.batch_size = 16;
    config.learner.publish_every = 10;
    config.learner.checkpoint_dir = None;
    config.learner.shm_publish = false;
    let learner_stop = Shutdown::new();
    let learner = crossroads_learner::start(&config, None, learner_stop.clone())
        .await
        .expect("learner");
    config.transport.learner_endpoint = format!("http://{}", learner.local_addr());

    let slot = WeightsSlot::new();
    let (actor, live, metrics) = live_actor(&slot);
    let subscription = WeightsSubscription::start(
        ActorTransport::Grpc,
        &config.transport,
        slot.clone(),
        &Shutdown::new(),
    )
    .expect("subscription");
    let pusher = Pusher::start(
        &PushConfig {
            transport: ActorTransport::Grpc,
            connection: config.transport.clone(),
            table: "t".to_owned(),
            buffer_batches: 1024,
            in_flight: 4,
        },
        metrics.clone(),
        &Shutdown::new(),
    )
    .expect("pusher");
    let stop = Shutdown::new();
    let _stop_on_panic = StopOnDrop(stop.clone());
    let acting = spawn_acting(actor, live, Some(pusher), stop.clone());

    // The learner's first weights (published at its start), then newer
    // ones trained from what this actor pushed, all while it runs.
    eventually(
        Duration::from_secs(60),
        "the learner's first weights",
        || version(&metrics) >= 1,
    )
    .await;
    let first = version(&metrics);
    eventually(Duration::from_secs(120), "a newer version", || {
        version(&metrics) > first
    })
    .await;
    assert!(!acting.is_finished(), "the actor stopped");
    assert!(learner.status().update_step > 0);

    // The learner goes away: the actor keeps stepping on its last weights.
    learner_stop.trigger();
    learner.join().await.expect("learner stops cleanly");
    let steps = metrics_steps(&metrics);
    eventually(Duration::from_secs(30), "steps without a learner", || {
        metrics_steps(&metrics) > steps + 500
    })
    .await;
    // Weights already on their way when the learner went away (it
    // publishes a final version as it stops) may still arrive and be
    // applied; once those are in use the version must stay put.
    eventually(
        Duration::from_secs(30),
        "the last received weights in use",
        || version(&metrics) == slot.version(),
    )
    .await;
    let last = version(&metrics);
    let steps = metrics_steps(&metrics);
    eventually(
        Duration::from_secs(30),
        "more steps without a learner",
        || metrics_steps(&metrics) > steps + 500,
    )
    .await;
    assert_eq!(version(&metrics), last, "no weights without a learner");
    assert!(
        metrics.weights_staleness.get() >= 0.0,
        "staleness is an age"
    );

    stop.trigger();
    let (report, applied, pusher) = acting.await.expect("acting thread");
    assert!(applied >= 2, "applied {applied} versions");
    assert!(report.transitions > 0);
    if let Some(p) = pusher {
        p.close(Duration::from_secs(5)).await;
    }
    subscription.stop().await;
    servers.trigger();
    replay.join().await.expect("replay stops cleanly");
}

fn metrics_steps(metrics: &ActorMetrics) -> u64 {
    metrics.env_steps_total()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_running_actor_takes_newer_weights_from_shared_memory() {
    let prefix = unique_prefix("weights");
    let connection = transport("http://127.0.0.1:1", &prefix);
    let slot = WeightsSlot::new();
    let subscription = WeightsSubscription::start(
        ActorTransport::Shm,
        &connection,
        slot.clone(),
        &Shutdown::new(),
    )
    .expect("subscription");
    let (actor, live, metrics) = live_actor(&slot);
    let stop = Shutdown::new();
    let _stop_on_panic = StopOnDrop(stop.clone());
    let acting = spawn_acting(actor, live, None, stop.clone());

    // The learner's publisher lives on one thread (it is not Send): publish
    // version 1, then, once the actor uses it, version 7.
    let published = Arc::new(AtomicBool::new(false));
    let (tx, rx) = std::sync::mpsc::channel::<u64>();
    let publisher_thread = {
        let connection = connection.clone();
        let published = Arc::clone(&published);
        std::thread::spawn(move || {
            let net = QNetwork::new(small_spec(), 9).expect("network");
            let bytes = net.to_safetensors(0).expect("bytes").len();
            let mut publisher = ShmWeightsPublisher::new(&connection, bytes).expect("publisher");
            let mut next = rx.recv().ok();
            while let Some(v) = next {
                let w = Weights::from_safetensors(net.to_safetensors(v).expect("bytes"), v * 10, 0)
                    .expect("weights");
                publisher.publish(&w).expect("publish");
                published.store(true, Ordering::SeqCst);
                // Late subscribers are connected on the next update: update
                // until the test sends the next version or hangs up.
                next = loop {
                    publisher.update_connections();
                    match rx.recv_timeout(Duration::from_millis(10)) {
                        Ok(v) => break Some(v),
                        Err(RecvTimeoutError::Timeout) => {}
                        Err(RecvTimeoutError::Disconnected) => break None,
                    }
                };
            }
        })
    };
    tx.send(1).expect("send");
    eventually(Duration::from_secs(30), "version 1 in use", || {
        version(&metrics) == 1
    })
    .await;
    assert!(published.load(Ordering::SeqCst));
    tx.send(7).expect("send");
    eventually(Duration::from_secs(30), "version 7 in use", || {
        version(&metrics) == 7
    })
    .await;
    assert!(!acting.is_finished(), "the actor stopped");
    drop(tx);
    publisher_thread.join().expect("publisher thread");
    stop.trigger();
    let (report, applied, _) = acting.await.expect("acting thread");
    assert_eq!(applied, 2);
    assert!(report.steps > 0);
    subscription.stop().await;
}

#[test]
fn weights_for_other_environments_stop_the_actor_with_a_clear_error() {
    let slot = WeightsSlot::new();
    let (mut actor, mut live, _) = live_actor(&slot);
    actor.step(&mut live).expect("first step");
    // A Sequential network (5x11x4 grid, 12 actions) cannot drive TTG
    // environments.
    let other = NetworkSpec::new(layout("sequential"), "sequential", TrunkKind::Mlp, vec![8])
        .expect("spec");
    let bytes = QNetwork::new(other, 3)
        .expect("network")
        .to_safetensors(4)
        .expect("bytes");
    assert!(slot.offer(Weights::from_safetensors(bytes, 40, 0).expect("weights")));
    let err = actor.step(&mut live).expect_err("mismatched weights");
    let text = err.to_string();
    assert!(text.contains("weights version 4"), "{text}");
    assert!(text.contains("12 actions"), "{text}");
    assert_eq!(live.version(), 0, "the old weights stay");

    // Weights of another architecture for the same environments replace
    // the network; an older version offered later is ignored.
    let wider = NetworkSpec::new(layout("ttg"), "ttg", TrunkKind::Mlp, vec![16]).expect("spec");
    let net = QNetwork::new(wider.clone(), 5).expect("network");
    let bytes = |version| net.to_safetensors(version).expect("bytes");
    assert!(slot.offer(Weights::from_safetensors(bytes(6), 60, 0).expect("weights")));
    actor
        .step(&mut live)
        .expect("step with the learner's network");
    assert_eq!(live.version(), 6);
    assert_eq!(live.network().spec(), &wider);
    assert!(!slot.offer(Weights::from_safetensors(bytes(5), 50, 0).expect("weights")));
    assert_eq!(slot.version(), 6);
    assert_eq!(live.obs_len(), actor.obs_len());
}

/// An MLP in f32 runs in plain Rust; each version applied is copied again,
/// so the Q-values are always those of the weights in use (libtorch's, up
/// to the order of float additions); a conv network from the learner runs
/// in libtorch.
#[test]
fn the_native_forward_pass_follows_each_version() {
    let slot = WeightsSlot::new();
    let metrics = ActorMetrics::new(None, "left").expect("metrics");
    let mut live = LiveNetwork::new(
        QNetwork::new(small_spec(), 1).expect("network"),
        &slot,
        metrics,
    )
    .expect("live network");
    assert!(live.is_native());
    let scenario = Arc::new(crossroads_sim::Scenario::builtin("left").expect("scenario"));
    let config = crossroads_sim::EnvConfig::for_actions(crossroads_sim::ActionSet::Ttg);
    let mut envs = crossroads_sim::VecEnv::new(scenario, config, 6, 2, None).expect("envs");
    for _ in 0..15 {
        envs.step(&[0, 1, 2, 3, 4, 0]).expect("step");
    }
    let rows = envs.sparse_observations().to_vec();
    let check = |live: &mut LiveNetwork, net: &QNetwork, what: &str| {
        let expected = net.infer_sparse(&rows).expect("libtorch").q;
        let mut q = vec![f32::NAN; expected.len()];
        live.q_values_sparse(&rows, &mut q).expect("sparse");
        for (x, y) in q.iter().zip(&expected) {
            assert!(
                (x - y).abs() <= 1e-5 * (1.0 + y.abs()),
                "{what}: {q:?} vs {expected:?}"
            );
        }
    };
    let first = QNetwork::new(small_spec(), 1).expect("network");
    check(&mut live, &first, "version 0");
    let newer = QNetwork::new(small_spec(), 2).expect("network");
    assert!(slot.offer(
        Weights::from_safetensors(newer.to_safetensors(3).expect("bytes"), 30, 0).expect("weights")
    ));
    check(&mut live, &newer, "version 3");
    assert_eq!(live.version(), 3);
    assert!(live.is_native());
    let conv = QNetwork::new(
        NetworkSpec::new(layout("ttg"), "ttg", TrunkKind::Conv, vec![4, 8, 16]).expect("spec"),
        4,
    )
    .expect("network");
    assert!(slot.offer(
        Weights::from_safetensors(conv.to_safetensors(4).expect("bytes"), 40, 0).expect("weights")
    ));
    check(&mut live, &conv, "version 4, conv");
    assert!(!live.is_native(), "a conv network runs in libtorch");
}

//! The learner as a user runs it: a real replay server and the learner
//! service over loopback gRPC (port 0), checkpoints on disk, Prometheus
//! text from the registry.

use std::path::Path;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::Config;
use crossroads_learner::bench::fill_replay;
use crossroads_learner::{RunningLearner, TrainerConfig};
use crossroads_test_support::crash_copy;
use crossroads_transport::auth::Token;
use crossroads_transport::grpc::ReplayClient;
use crossroads_transport::{ClientSecurity, LearnerClient};
use tonic::Code;

const TOKEN: &str = "s3cret-token";

struct Replay {
    shutdown: Shutdown,
    server: crossroads_replay::RunningServer,
}

async fn replay_with_data(config: &Config) -> Replay {
    let mut c = config.clone();
    c.replay.listen = ([127, 0, 0, 1], 0).into();
    c.replay.shm_ingest = false;
    c.replay.min_size_to_sample = 1;
    c.replay.snapshot_dir = None;
    let shutdown = Shutdown::new();
    let server = crossroads_replay::start(&c, None, shutdown.clone())
        .await
        .expect("test setup");
    let mut transport = c.transport.clone();
    transport.replay_endpoint = format!("http://{}", server.local_addr());
    let client = ReplayClient::new(&transport, &c.replay.table).expect("test setup");
    let spec = TrainerConfig::from_config(&c.sim, &c.learner)
        .expect("test setup")
        .spec;
    fill_replay(&client, &spec, 2_000)
        .await
        .expect("test setup");
    Replay { shutdown, server }
}

fn learner_config(checkpoints: &Path) -> Config {
    let mut c = Config::default();
    c.learner.listen = ([127, 0, 0, 1], 0).into();
    crate::set_observation(&mut c.sim, "sequential");
    c.sim.action_set = "ttg".to_owned();
    c.learner.hidden = vec![32, 32];
    c.learner.batch_size = 16;
    c.learner.publish_every = 5;
    c.learner.checkpoint_every = 0;
    c.learner.checkpoint_dir = Some(checkpoints.to_path_buf());
    c.learner.shm_publish = false;
    // The token from a file, as a mounted secret would give it; the
    // learner's replay client sends it too.
    let token_file = checkpoints.with_file_name("token");
    std::fs::create_dir_all(checkpoints.parent().expect("a parent")).expect("test setup");
    std::fs::write(&token_file, format!("{TOKEN}\n")).expect("test setup");
    c.transport.auth.token_file = Some(token_file);
    c
}

async fn start_learner(
    config: &Config,
    replay: &Replay,
    registry: Option<&prometheus::Registry>,
) -> RunningLearner {
    let mut c = config.clone();
    c.transport.replay_endpoint = format!("http://{}", replay.server.local_addr());
    crossroads_learner::start(&c, registry, Shutdown::new())
        .await
        .expect("test setup")
}

fn client(learner: &RunningLearner, token: Option<&str>) -> LearnerClient {
    let token = token.map(|t| Token::new(t, "test").expect("test setup"));
    LearnerClient::new(
        &format!("http://{}", learner.local_addr()),
        &ClientSecurity::none().with_token(token),
        Duration::from_secs(30),
    )
    .expect("test setup")
}

async fn wait_for_step(c: &LearnerClient, step: u64) {
    for _ in 0..600 {
        if c.status().await.expect("test setup").update_step >= step {
            return;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("the learner did not reach step {step}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn checkpoint_api_validates_ids_and_tokens_over_grpc() {
    let dir = tempfile::tempdir().unwrap();
    let config = learner_config(&dir.path().join("ckpts"));
    let replay = replay_with_data(&config).await;
    let learner = start_learner(&config, &replay, None).await;
    let open = client(&learner, Some(TOKEN));
    let anonymous = client(&learner, None);
    let wrong = client(&learner, Some("nope"));
    wait_for_step(&open, 10).await;

    // Mutating calls need the token; reading ones do not.
    for c in [&anonymous, &wrong] {
        let err = c.save().await.unwrap_err();
        assert_eq!(err.code(), Some(Code::Unauthenticated), "{err}");
        let err = c.delete("ckpt-000000000001").await.unwrap_err();
        assert_eq!(err.code(), Some(Code::Unauthenticated), "{err}");
        let err = c.restore("ckpt-000000000001").await.unwrap_err();
        assert_eq!(err.code(), Some(Code::Unauthenticated), "{err}");
    }
    assert!(anonymous.list().await.unwrap().is_empty());

    let saved = open.save().await.unwrap();
    assert!(saved.update_step >= 10);
    assert_eq!(saved.scenario, "left");
    let listed = anonymous.list().await.unwrap();
    assert_eq!(listed.len(), 1);
    assert_eq!(listed[0].id, saved.id);
    assert!(listed[0].files.contains(&"weights.safetensors".to_owned()));

    // Ids: unknown is NOT_FOUND, escaping is INVALID_ARGUMENT, for every call.
    let out = tempfile::tempdir().unwrap();
    for (id, code) in [
        ("ckpt-999999999999", Code::NotFound),
        ("../../etc", Code::InvalidArgument),
        ("..", Code::InvalidArgument),
        ("a/b", Code::InvalidArgument),
        ("", Code::InvalidArgument),
    ] {
        let err = anonymous.pull(id, out.path()).await.unwrap_err();
        assert_eq!(err.code(), Some(code), "pull {id:?}: {err}");
        let err = open.restore(id).await.unwrap_err();
        assert_eq!(err.code(), Some(code), "restore {id:?}: {err}");
        let err = open.delete(id).await.unwrap_err();
        assert_eq!(err.code(), Some(code), "delete {id:?}: {err}");
    }

    // Pull streams the files; they are byte-identical to the learner's.
    let (info, folder) = anonymous.pull(&saved.id, out.path()).await.unwrap();
    assert_eq!(info.id, saved.id);
    for file in &info.files {
        let ours = std::fs::read(folder.join(file)).unwrap();
        let theirs = std::fs::read(dir.path().join("ckpts").join(&saved.id).join(file)).unwrap();
        assert_eq!(ours, theirs, "{file}");
    }

    // Restore publishes the checkpoint's weights under a higher version.
    let before = open.status().await.unwrap();
    let (restored, version) = open.restore(&saved.id).await.unwrap();
    assert_eq!(restored.id, saved.id);
    assert!(version > before.weights_version);
    let latest = anonymous.latest_weights().await.unwrap();
    assert!(latest.version >= version);

    // Evaluation reports are validated and recorded.
    let err = open
        .report_evaluation(version, [("success_rate".to_owned(), f64::NAN)].into())
        .await
        .unwrap_err();
    assert_eq!(err.code(), Some(Code::InvalidArgument), "{err}");
    open.report_evaluation(
        version,
        [
            ("success_rate".to_owned(), 0.75),
            ("mean_return".to_owned(), -0.5),
        ]
        .into(),
    )
    .await
    .unwrap();
    let second = open.save().await.unwrap();
    assert_eq!(second.eval_metrics.get("success_rate"), Some(&0.75));
    // The best checkpoint is picked by learner.best_metric, mean_return by
    // default (the rule train keeps its best/ weights by).
    assert!(second.best);

    open.delete(&saved.id).await.unwrap();
    let err = open.delete(&saved.id).await.unwrap_err();
    assert_eq!(err.code(), Some(Code::NotFound));

    learner.stop();
    learner.join().await.unwrap();
    replay.shutdown.trigger();
    replay.server.join().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn resume_after_restart_continues_step_and_version() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = learner_config(&dir.path().join("ckpts"));
    config.learner.max_updates = 30;
    let replay = replay_with_data(&config).await;

    let registry = crossroads_common::metrics::registry("learner").unwrap();
    let first = start_learner(&config, &replay, Some(&registry)).await;
    let c = client(&first, None);
    // A late subscriber gets the latest weights at once.
    let mut sub = c.subscribe_weights(0).await.unwrap();
    let got = sub.next().await.unwrap().unwrap();
    assert!(got.version >= 1);
    first.join().await.unwrap();

    // The last checkpoint holds step 30 and the last version published.
    let store =
        crossroads_learner::CheckpointStore::open(dir.path().join("ckpts"), 3, "success_rate")
            .unwrap();
    let entries = store.list().unwrap();
    let last = &entries[0].manifest;
    assert_eq!(last.update_step, 30);
    let version_then = last.weights_version;
    assert!(version_then >= 30 / 5);

    // Prometheus text of the first run.
    let text = crossroads_common::metrics::render(&registry);
    let scrape = prometheus_parse::Scrape::parse(text.lines().map(|l| Ok(l.to_owned()))).unwrap();
    let value = |name: &str| {
        scrape
            .samples
            .iter()
            .find(|s| s.metric == name)
            .map(|s| match s.value {
                prometheus_parse::Value::Counter(v) | prometheus_parse::Value::Gauge(v) => v,
                prometheus_parse::Value::Untyped(v) => v,
                _ => f64::NAN,
            })
            .unwrap_or_else(|| panic!("{name} missing from\n{text}"))
    };
    assert_eq!(value("crossroads_learner_updates_total"), 30.0);
    assert_eq!(
        value("crossroads_learner_weights_version"),
        version_then as f64
    );
    assert_eq!(value("crossroads_learner_checkpoints_total"), 1.0);
    assert!(value("crossroads_learner_loss").is_finite());
    assert!(value("crossroads_learner_grad_norm") > 0.0);
    for name in [
        "crossroads_learner_q_mean",
        "crossroads_learner_q_max",
        "crossroads_learner_td_error_abs_mean",
        "crossroads_learner_sample_wait_seconds_total",
        "crossroads_learner_checkpoint_age_seconds",
    ] {
        assert!(value(name).is_finite(), "{name}");
    }
    assert!(text.contains("crossroads_learner_sample_wait_seconds_bucket"));

    // Restart: the step continues from 30, the version from the last one.
    // No budget this time, so the learner is still serving when asked (with
    // a budget of 20 more updates it could finish, and cancel the calls,
    // first: seen in CI).
    config.learner.max_updates = 0;
    let second = start_learner(&config, &replay, None).await;
    let c = client(&second, None);
    let status = c.status().await.unwrap();
    assert!(status.update_step >= 30, "{status:?}");
    assert!(status.weights_version > version_then, "{status:?}");
    let w = c.latest_weights().await.unwrap();
    assert!(w.version > version_then);
    wait_for_step(&c, 50).await;
    second.stop();
    second.join().await.unwrap();
    let entries = store.list().unwrap();
    let stopped_at = entries[0].manifest.update_step;
    assert!(stopped_at >= 50, "{stopped_at}");
    assert!(entries[0].manifest.weights_version > version_then);

    // A budget after a restart counts from the restored step: it ends at
    // exactly the budget.
    config.learner.max_updates = stopped_at + 10;
    let third = start_learner(&config, &replay, None).await;
    third.join().await.unwrap();
    let entries = store.list().unwrap();
    assert_eq!(entries[0].manifest.update_step, stopped_at + 10);

    replay.shutdown.trigger();
    replay.server.join().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replay_of_another_observation_kind_stops_the_learner_with_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let config = learner_config(&dir.path().join("ckpts"));
    let replay = replay_with_data(&config).await;
    let mut other = config.clone();
    crate::set_observation(&mut other.sim, "ttg");
    other.learner.resume = false;
    other.learner.checkpoint_dir = None;
    let learner = start_learner(&other, &replay, None).await;
    let err = learner.join().await.unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("sequential") && text.contains("ttg"),
        "{text}"
    );
    assert!(text.contains("sim.observation"), "{text}");
    replay.shutdown.trigger();
    replay.server.join().await.unwrap();
}

#[test]
fn weights_reach_a_late_shared_memory_subscriber() {
    use crossroads_model::{NetworkSpec, QNetwork, TrunkKind};
    use crossroads_transport::weights_shm::{ShmWeightsPublisher, ShmWeightsSubscriber};
    use crossroads_types::Weights;
    let transport = crossroads_config::TransportConfig {
        shm_prefix: format!("crossroads-test-{}-weights", std::process::id()),
        ..Default::default()
    };
    let weights = |version: u64, hidden: i64| {
        let spec =
            NetworkSpec::new(crate::layout("ttg"), "ttg", TrunkKind::Mlp, vec![hidden]).unwrap();
        let bytes = QNetwork::new(spec, 1)
            .unwrap()
            .to_safetensors(version)
            .unwrap();
        Weights::from_safetensors(bytes, version * 10, 100 + version as i64).unwrap()
    };
    let (first, second) = (weights(1, 2), weights(2, 2));
    let mut publisher = ShmWeightsPublisher::new(&transport, first.safetensors.len()).unwrap();
    publisher.publish(&first).unwrap();
    publisher.publish(&second).unwrap();
    let mut subscriber = ShmWeightsSubscriber::new(&transport).unwrap();
    publisher.update_connections();
    let got = subscriber
        .latest()
        .unwrap()
        .expect("history delivers the latest");
    assert_eq!(got, second);
    // A larger payload than the first slot grows it.
    let big = weights(3, 16);
    assert!(big.safetensors.len() > 4 * second.safetensors.len());
    publisher.publish(&big).unwrap();
    assert_eq!(subscriber.latest().unwrap(), Some(big));
    // A frame whose version is not the one its metadata say is skipped.
    let mut wrong = weights(4, 2);
    wrong.version = 5;
    publisher.publish(&wrong).unwrap();
    assert_eq!(subscriber.latest().unwrap(), None);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_learner_killed_past_its_last_checkpoint_restarts_above_every_version() {
    let dir = tempfile::tempdir().unwrap();
    let live = dir.path().join("live");
    let mut config = learner_config(&live);
    // One checkpoint, at start; then only publications.
    config.learner.checkpoint_every = 1_000_000;
    let replay = replay_with_data(&config).await;
    let first = start_learner(&config, &replay, None).await;
    let c = client(&first, None);
    wait_for_step(&c, 60).await;
    let seen = c.status().await.unwrap().weights_version;
    assert!(seen >= 60 / 5, "published {seen} versions");
    let crashed = dir.path().join("crashed");
    crash_copy(&live, &crashed);
    first.stop();
    first.join().await.unwrap();

    let lease: u64 = std::fs::read_to_string(crashed.join("versions.lease"))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert!(lease >= seen, "lease {lease} covers version {seen}");
    let mut after = learner_config(&crashed);
    after.learner.checkpoint_every = 1_000_000;
    let second = start_learner(&after, &replay, None).await;
    let status = client(&second, None).status().await.unwrap();
    assert!(
        status.weights_version > seen,
        "restarted at version {} after {seen} was published",
        status.weights_version
    );
    second.stop();
    second.join().await.unwrap();
}

/// Sends bytes as they are, as one gRPC message, and reads answers as
/// bytes: a client that does not speak protobuf.
#[derive(Debug, Clone, Copy, Default)]
struct RawBytes;

impl tonic::codec::Codec for RawBytes {
    type Encode = Vec<u8>;
    type Decode = Vec<u8>;
    type Encoder = RawBytes;
    type Decoder = RawBytes;

    fn encoder(&mut self) -> RawBytes {
        RawBytes
    }

    fn decoder(&mut self) -> RawBytes {
        RawBytes
    }
}

impl tonic::codec::Encoder for RawBytes {
    type Item = Vec<u8>;
    type Error = tonic::Status;

    fn encode(
        &mut self,
        item: Vec<u8>,
        dst: &mut tonic::codec::EncodeBuf<'_>,
    ) -> Result<(), tonic::Status> {
        bytes::BufMut::put_slice(dst, &item);
        Ok(())
    }
}

impl tonic::codec::Decoder for RawBytes {
    type Item = Vec<u8>;
    type Error = tonic::Status;

    fn decode(
        &mut self,
        src: &mut tonic::codec::DecodeBuf<'_>,
    ) -> Result<Option<Vec<u8>>, tonic::Status> {
        let n = bytes::Buf::remaining(src);
        Ok(Some(bytes::Buf::copy_to_bytes(src, n).to_vec()))
    }
}

/// Not a protobuf message: field 15 with wire type 7, which does not exist.
const GARBAGE: &[u8] = b"\xff\xff\xff\xff\x0fnot protobuf";

async fn raw_client(addr: std::net::SocketAddr) -> tonic::client::Grpc<tonic::transport::Channel> {
    let channel = tonic::transport::Endpoint::from_shared(format!("http://{addr}"))
        .expect("test setup")
        .connect()
        .await
        .expect("test setup");
    tonic::client::Grpc::new(channel)
}

fn path(p: &'static str) -> tonic::codegen::http::uri::PathAndQuery {
    tonic::codegen::http::uri::PathAndQuery::from_static(p)
}

/// The status a streaming call ends with when its request is refused:
/// either at once or as the first message of the response stream.
async fn stream_refusal<M: std::fmt::Debug>(
    result: Result<tonic::Response<tonic::codec::Streaming<M>>, tonic::Status>,
) -> tonic::Status {
    match result {
        Err(status) => status,
        Ok(response) => response
            .into_inner()
            .message()
            .await
            .expect_err("garbage is refused"),
    }
}

fn assert_undecodable(status: &tonic::Status, message: &str) {
    assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().contains("did not decode")
            && status
                .message()
                .contains(&format!("crossroads.v1.{message}")),
        "{status:?}"
    );
}

/// Bytes that are not protobuf answer INVALID_ARGUMENT naming the message
/// (tonic-prost alone says INTERNAL), on unary and streaming calls of both
/// servers, and each server keeps serving.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bytes_that_are_not_protobuf_are_invalid_argument_on_both_servers() {
    let dir = tempfile::tempdir().unwrap();
    let mut config = learner_config(&dir.path().join("ckpts"));
    // A client without the token would be stopped before the decoder.
    config.transport.auth = Default::default();
    let replay = replay_with_data(&config).await;
    let learner = start_learner(&config, &replay, None).await;

    let mut grpc = raw_client(replay.server.local_addr()).await;
    grpc.ready().await.expect("connected");
    let status = grpc
        .unary(
            tonic::Request::new(GARBAGE.to_vec()),
            path("/crossroads.v1.Replay/Sample"),
            RawBytes,
        )
        .await
        .expect_err("garbage is refused");
    assert_undecodable(&status, "SampleRequest");
    grpc.ready().await.expect("connected");
    let outgoing = tokio_stream::iter([GARBAGE.to_vec()]);
    let status = stream_refusal(
        grpc.streaming(
            tonic::Request::new(outgoing),
            path("/crossroads.v1.Replay/Insert"),
            RawBytes,
        )
        .await,
    )
    .await;
    assert_undecodable(&status, "InsertRequest");
    let mut transport = config.transport.clone();
    transport.replay_endpoint = format!("http://{}", replay.server.local_addr());
    let replay_client = ReplayClient::new(&transport, &config.replay.table).expect("test setup");
    let info = replay_client
        .info()
        .await
        .expect("the replay server still serves");
    assert!(info.size > 0);

    let mut grpc = raw_client(learner.local_addr()).await;
    grpc.ready().await.expect("connected");
    let status = grpc
        .unary(
            tonic::Request::new(GARBAGE.to_vec()),
            path("/crossroads.v1.Learner/Status"),
            RawBytes,
        )
        .await
        .expect_err("garbage is refused");
    assert_undecodable(&status, "StatusRequest");
    grpc.ready().await.expect("connected");
    let status = stream_refusal(
        grpc.server_streaming(
            tonic::Request::new(GARBAGE.to_vec()),
            path("/crossroads.v1.Learner/SubscribeWeights"),
            RawBytes,
        )
        .await,
    )
    .await;
    assert_undecodable(&status, "SubscribeWeightsRequest");
    client(&learner, None)
        .status()
        .await
        .expect("the learner still serves");

    learner.stop();
    learner.join().await.unwrap();
    replay.shutdown.trigger();
    replay.server.join().await.unwrap();
}

//! TLS and tokens on the gRPC endpoints, over real sockets on loopback with
//! real TLS: a throwaway CA, server and client certificates made here with
//! rcgen, the replay server and the learner started in this process (and,
//! last, a whole `crossroads train` over gRPC as child processes), and
//! clients with and without each credential.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crossroads_common::Shutdown;
use crossroads_config::{Config, TransportConfig};
use crossroads_test_support::toy_batch;
use crossroads_transport::auth::Token;
use crossroads_transport::grpc::{ClientError, ReplayClient};
use crossroads_transport::{ClientSecurity, LearnerClient, LearnerClientError};
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};

const TOKEN: &str = "c0rrect-h0rse-battery-staple";

/// The layout of the simulator's TTG view, which [`config`]'s network
/// reads.
fn ttg() -> crossroads_types::ObservationLayout {
    crossroads_sim::observation_layout("ttg").expect("a view")
}

/// PEM files of a throwaway PKI in a temporary folder: a CA, a server
/// certificate for `localhost` and 127.0.0.1, a client certificate, and a
/// second CA that signed neither (a stranger's).
struct Pki {
    dir: tempfile::TempDir,
}

impl Pki {
    fn new() -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        let ca = Self::ca("crossroads test CA");
        let stranger = Self::ca("someone else's CA");
        Self::leaf(
            &ca.1,
            "server",
            ExtendedKeyUsagePurpose::ServerAuth,
            dir.path(),
        );
        Self::leaf(
            &ca.1,
            "client",
            ExtendedKeyUsagePurpose::ClientAuth,
            dir.path(),
        );
        std::fs::write(dir.path().join("ca.pem"), ca.0).expect("write");
        std::fs::write(dir.path().join("stranger-ca.pem"), stranger.0).expect("write");
        std::fs::write(dir.path().join("token"), format!("{TOKEN}\n")).expect("write");
        Self { dir }
    }

    /// A self-signed CA: its PEM certificate and an issuer for leaves.
    fn ca(name: &str) -> (String, Issuer<'static, KeyPair>) {
        let key = KeyPair::generate().expect("key");
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("params");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        let cert = params.self_signed(&key).expect("self-signed CA");
        (cert.pem(), Issuer::new(params, key))
    }

    /// `<name>.pem` and `<name>.key`, signed by `ca`, for `localhost` and
    /// 127.0.0.1.
    fn leaf(ca: &Issuer<'_, KeyPair>, name: &str, usage: ExtendedKeyUsagePurpose, dir: &Path) {
        let key = KeyPair::generate().expect("key");
        let mut params =
            CertificateParams::new(vec!["localhost".to_owned(), "127.0.0.1".to_owned()])
                .expect("params");
        params.distinguished_name.push(DnType::CommonName, name);
        params.extended_key_usages = vec![usage];
        let cert = params.signed_by(&key, ca).expect("signed");
        std::fs::write(dir.join(format!("{name}.pem")), cert.pem()).expect("write");
        std::fs::write(dir.join(format!("{name}.key")), key.serialize_pem()).expect("write");
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// Servers with TLS (and client certificates when `mtls`) and the
    /// token; clients with the CA, the client certificate and the token.
    fn secure(&self, config: &mut Config, mtls: bool) {
        let tls = &mut config.transport.tls;
        tls.cert_file = Some(self.path("server.pem"));
        tls.key_file = Some(self.path("server.key"));
        tls.client_ca_file = mtls.then(|| self.path("ca.pem"));
        tls.ca_file = Some(self.path("ca.pem"));
        tls.client_cert_file = Some(self.path("client.pem"));
        tls.client_key_file = Some(self.path("client.key"));
        config.transport.auth.token_file = Some(self.path("token"));
        // Not the test process's environment: only the file counts here.
        config.transport.auth.token_env = String::new();
    }
}

/// A config for small in-process servers on free loopback ports.
fn config() -> Config {
    let mut c = Config::default();
    c.replay.listen = ([127, 0, 0, 1], 0).into();
    c.replay.shm_ingest = false;
    c.replay.snapshot_dir = None;
    c.replay.min_size_to_sample = 1;
    c.replay.samples_per_insert = 0.0;
    c.learner.listen = ([127, 0, 0, 1], 0).into();
    c.learner.shm_publish = false;
    c.learner.hidden = vec![16];
    c.learner.batch_size = 8;
    c.learner.publish_every = 5;
    c.sim.action_set = "ttg".to_owned();
    crossroads_actor::resolve_observation(&mut c.sim).expect("a built-in pairing");
    c.transport.auth.token_env = String::new();
    c.transport.connect_timeout_ms = 5_000;
    c.transport.request_timeout_ms = 10_000;
    c
}

/// A replay client of the server at `addr` as `transport` describes the
/// client side.
fn replay_client(
    transport: &TransportConfig,
    scheme: &str,
    addr: std::net::SocketAddr,
) -> ReplayClient {
    let mut t = transport.clone();
    t.replay_endpoint = format!("{scheme}://{addr}");
    ReplayClient::new(&t, &config().replay.table).expect("client")
}

fn assert_unauthenticated(result: Result<impl std::fmt::Debug, ClientError>, says: &str) {
    let err = result.expect_err("refused");
    assert_eq!(err.code(), Some(tonic::Code::Unauthenticated), "{err}");
    assert!(err.to_string().contains(says), "{err}");
}

fn assert_learner_unauthenticated(result: Result<impl std::fmt::Debug, LearnerClientError>) {
    let err = result.expect_err("refused");
    assert_eq!(err.code(), Some(tonic::Code::Unauthenticated), "{err}");
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime")
}

/// Insert, sample, priority updates over TLS with the token; the learner
/// samples over TLS, serves its weights and checkpoints over TLS; and
/// neither server lets a guarded call through without the token, or with
/// another, while the read-only calls stay open.
#[test]
fn tls_with_token_carries_inserts_samples_and_weights_and_guards_every_mutating_call() {
    let pki = Pki::new();
    let ckpts = tempfile::tempdir().expect("temp dir");
    let mut c = config();
    pki.secure(&mut c, false);
    c.learner.checkpoint_dir = Some(ckpts.path().to_path_buf());
    runtime().block_on(async {
        let shutdown = Shutdown::new();
        let replay = crossroads_replay::start(&c, None, shutdown.clone())
            .await
            .expect("replay over TLS");
        let client = replay_client(&c.transport, "https", replay.local_addr());
        let ack = client
            .insert(toy_batch(ttg()))
            .await
            .expect("insert over TLS");
        assert_eq!(ack.inserted, 10);
        let sample = client
            .sample(4, 0.4, Duration::from_secs(5))
            .await
            .expect("sample over TLS");
        assert_eq!(sample.keys.len(), 4);
        let updated = client
            .update_priorities(sample.keys.clone(), vec![2.0; 4])
            .await
            .expect("update over TLS");
        assert_eq!(updated.updated, 4);
        assert_eq!(client.join_actor("a").await.expect("join").index, 0);

        // Without the token (same TLS), every state-changing call is
        // refused, naming what is missing; Info stays open.
        let mut anonymous = c.transport.clone();
        anonymous.auth.token_file = None;
        let anonymous = replay_client(&anonymous, "https", replay.local_addr());
        let missing = "missing authorization metadata";
        assert_unauthenticated(anonymous.insert(toy_batch(ttg())).await, missing);
        assert_unauthenticated(
            anonymous.sample(4, 0.4, Duration::from_secs(1)).await,
            missing,
        );
        assert_unauthenticated(
            anonymous
                .update_priorities(sample.keys.clone(), vec![1.0; 4])
                .await,
            missing,
        );
        assert_unauthenticated(anonymous.join_actor("b").await, missing);
        assert_unauthenticated(anonymous.snapshot().await, missing);
        let info = anonymous.info().await.expect("Info needs no token");
        assert_eq!(info.size, 10, "nothing got in without the token");
        assert_eq!(info.inserts_total, 10);

        // Another token is refused as not matching.
        let wrong_file = pki.path("wrong-token");
        std::fs::write(&wrong_file, "not-the-token").expect("write");
        let mut wrong = c.transport.clone();
        wrong.auth.token_file = Some(wrong_file);
        let wrong = replay_client(&wrong, "https", replay.local_addr());
        let differs = "does not match";
        assert_unauthenticated(wrong.insert(toy_batch(ttg())).await, differs);
        assert_unauthenticated(wrong.sample(4, 0.4, Duration::from_secs(1)).await, differs);
        assert_unauthenticated(wrong.join_actor("c").await, differs);
        assert_eq!(client.info().await.expect("info").size, 10);

        // The learner samples from the TLS replay with the token, and
        // serves weights over TLS.
        crossroads_learner::bench::fill_replay(
            &client,
            &crossroads_learner::TrainerConfig::from_config(&c.sim, &c.learner)
                .expect("spec")
                .spec,
            500,
        )
        .await
        .expect("fill");
        let mut lc = c.clone();
        lc.transport.replay_endpoint = format!("https://{}", replay.local_addr());
        let learner = crossroads_learner::start(&lc, None, shutdown.clone())
            .await
            .expect("learner over TLS");
        let url = format!("https://{}", learner.local_addr());
        let security = ClientSecurity::load(&c.transport).expect("client security");
        let learner_client =
            LearnerClient::new(&url, &security, Duration::from_secs(30)).expect("client");
        let mut trained = 0;
        for _ in 0..600 {
            trained = learner_client.status().await.expect("status").update_step;
            if trained >= 10 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        assert!(trained >= 10, "the learner trained {trained} updates");
        let mut weights = learner_client
            .subscribe_weights(0)
            .await
            .expect("subscribe over TLS");
        let w = weights.next().await.expect("weights").expect("a version");
        assert!(w.version >= 1);
        let saved = learner_client.save().await.expect("save with the token");

        // The learner's guarded calls need the token too; its reading
        // calls do not.
        let anonymous = LearnerClient::new(
            &url,
            &security.clone().with_token(None),
            Duration::from_secs(30),
        )
        .expect("client");
        assert_learner_unauthenticated(anonymous.save().await);
        assert_learner_unauthenticated(anonymous.restore(&saved.id).await);
        assert_learner_unauthenticated(anonymous.delete(&saved.id).await);
        assert_learner_unauthenticated(
            anonymous
                .report_evaluation(1, [("mean_return".to_owned(), 1.0)].into())
                .await,
        );
        let wrong = LearnerClient::new(
            &url,
            &security
                .clone()
                .with_token(Some(Token::new("nope", "test").expect("token"))),
            Duration::from_secs(30),
        )
        .expect("client");
        let err = wrong.delete(&saved.id).await.expect_err("refused");
        assert!(err.to_string().contains("does not match"), "{err}");
        assert_eq!(anonymous.list().await.expect("list is open").len(), 1);
        assert!(anonymous.status().await.is_ok(), "status is open");
        assert!(anonymous.latest_weights().await.is_ok(), "weights are open");

        // The subscription above is not read any further; once versions
        // pile up behind it, shutdown must still end its stream.
        let mut version = 0;
        for _ in 0..600 {
            version = learner_client
                .status()
                .await
                .expect("status")
                .weights_version;
            if version >= w.version + 40 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        assert!(version >= w.version + 40, "published up to {version}");
        shutdown.trigger();
        tokio::time::timeout(Duration::from_secs(60), learner.join())
            .await
            .expect("a stalled weights subscriber does not hold the learner's shutdown")
            .expect("learner stops");
        replay.join().await.expect("replay stops");
    });
}

/// A client that speaks plain HTTP/2 to a TLS server, or trusts another
/// CA, gets no answer, and an error that says why.
#[test]
fn plain_text_and_untrusted_clients_fail_against_a_tls_server() {
    let pki = Pki::new();
    let mut c = config();
    pki.secure(&mut c, false);
    runtime().block_on(async {
        let shutdown = Shutdown::new();
        let replay = crossroads_replay::start(&c, None, shutdown.clone())
            .await
            .expect("replay over TLS");
        let addr = replay.local_addr();

        let plain = replay_client(&config().transport, "http", addr);
        // The connection fails in one of several ways (a closed pipe, the
        // TLS alert read as an oversized HTTP/2 frame); each says why
        // below the top and carries the hint.
        for _ in 0..3 {
            let err = plain.info().await.expect_err("plain text against TLS");
            let text = err.to_string();
            assert!(text.contains("if the server speaks TLS"), "{text}");
            assert!(
                text.contains("broken pipe")
                    || text.contains("frame with invalid size")
                    || text.contains("connection"),
                "{text}"
            );
        }
        // A server that is simply not there gets no TLS hint.
        let closed = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
        let nobody = closed.local_addr().expect("addr");
        drop(closed);
        let err = replay_client(&config().transport, "http", nobody)
            .info()
            .await
            .expect_err("nobody listens");
        assert!(
            !err.to_string().contains("if the server speaks TLS"),
            "{err}"
        );

        let mut stranger = c.transport.clone();
        stranger.tls.ca_file = Some(pki.path("stranger-ca.pem"));
        let stranger = replay_client(&stranger, "https", addr);
        let err = stranger
            .info()
            .await
            .expect_err("untrusted server certificate");
        let text = err.to_string();
        assert!(text.contains("UnknownIssuer"), "{text}");
        assert!(!text.contains("if the server speaks TLS"), "{text}");

        // TLS settings on an http:// endpoint are refused before any call.
        let mut mixed = c.transport.clone();
        mixed.replay_endpoint = format!("http://{addr}");
        let err = ReplayClient::new(&mixed, "transitions").expect_err("http:// with a CA");
        assert!(err.to_string().contains("use https://"), "{err}");

        assert_eq!(
            replay_client(&c.transport, "https", addr)
                .info()
                .await
                .expect("the right client")
                .size,
            0
        );
        shutdown.trigger();
        replay.join().await.expect("replay stops");
    });
}

/// With client certificates required, a client without one is refused at
/// the handshake; with one it is served.
#[test]
fn mutual_tls_refuses_a_client_without_a_certificate() {
    let pki = Pki::new();
    let mut c = config();
    pki.secure(&mut c, true);
    runtime().block_on(async {
        let shutdown = Shutdown::new();
        let replay = crossroads_replay::start(&c, None, shutdown.clone())
            .await
            .expect("replay with mTLS");
        let addr = replay.local_addr();

        let mut no_cert = c.transport.clone();
        no_cert.tls.client_cert_file = None;
        no_cert.tls.client_key_file = None;
        let no_cert = replay_client(&no_cert, "https", addr);
        // Under TLS 1.3 the client may finish its half of the handshake
        // before the server's alert arrives: it reads CertificateRequired
        // or a closed connection, never an answer.
        for _ in 0..3 {
            let err = no_cert.info().await.expect_err("no client certificate");
            assert!(err.to_string().contains("transport error"), "{err}");
            assert!(no_cert.insert(toy_batch(ttg())).await.is_err());
        }

        let with_cert = replay_client(&c.transport, "https", addr);
        assert_eq!(
            with_cert.info().await.expect("info").size,
            0,
            "nothing got in"
        );
        assert_eq!(
            with_cert
                .insert(toy_batch(ttg()))
                .await
                .expect("insert")
                .inserted,
            10
        );
        shutdown.trigger();
        replay.join().await.expect("replay stops");
    });
}

/// A missing file stops a server's start with an error naming the key and
/// the file.
#[test]
fn missing_tls_and_token_files_are_named_at_start() {
    let pki = Pki::new();
    let rt = runtime();
    let start = |c: Config| {
        rt.block_on(async {
            crossroads_replay::start(&c, None, Shutdown::new())
                .await
                .map(|_| ())
                .expect_err("a missing file")
                .to_string()
        })
    };
    let gone = pki.path("no-such-file.pem");
    let mut c = config();
    pki.secure(&mut c, true);
    c.transport.tls.cert_file = Some(gone.clone());
    let err = start(c);
    assert!(
        err.contains("transport.tls.cert_file") && err.contains(&gone.display().to_string()),
        "{err}"
    );

    let mut c = config();
    pki.secure(&mut c, true);
    c.transport.tls.client_ca_file = Some(pki.path("token"));
    let err = start(c);
    assert!(
        err.contains("transport.tls.client_ca_file") && err.contains("CERTIFICATE"),
        "{err}"
    );

    let mut c = config();
    pki.secure(&mut c, false);
    c.transport.auth.token_file = Some(gone.clone());
    let err = start(c);
    assert!(err.contains("transport.auth.token_file"), "{err}");

    let empty = pki.path("empty-token");
    std::fs::write(&empty, "\n").expect("write");
    let mut c = config();
    c.transport.auth.token_file = Some(empty);
    let err = start(c);
    assert!(err.contains("is empty"), "{err}");
}

/// `crossroads train` with TLS, client certificates and a token, actors on
/// gRPC: every child process reads the same settings, and the run
/// finishes; `crossroads checkpoints` then needs the CA and the token.
#[test]
fn a_tiny_train_run_works_over_mutual_tls_with_a_token() {
    let pki = Pki::new();
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("run");
    let p = |name: &str| pki.path(name).display().to_string();
    let sets = [
        "telemetry.metrics_addr=127.0.0.1:0".to_owned(),
        "learner.trunk=mlp".to_owned(),
        "learner.hidden=[32]".to_owned(),
        "replay.min_size_to_sample=100".to_owned(),
        "train.eval_every=10".to_owned(),
        "train.eval_trials=10".to_owned(),
        "train.confirm_trials=10".to_owned(),
        "train.transport=grpc".to_owned(),
        format!("transport.tls.cert_file={}", p("server.pem")),
        format!("transport.tls.key_file={}", p("server.key")),
        format!("transport.tls.client_ca_file={}", p("ca.pem")),
        format!("transport.tls.ca_file={}", p("ca.pem")),
        format!("transport.tls.client_cert_file={}", p("client.pem")),
        format!("transport.tls.client_key_file={}", p("client.key")),
        "transport.replay_endpoint=https://127.0.0.1:50051".to_owned(),
        "transport.learner_endpoint=https://127.0.0.1:50052".to_owned(),
    ];
    let mut args: Vec<String> = Vec::new();
    for s in &sets {
        args.extend(["--set".to_owned(), s.clone()]);
    }
    args.extend(
        [
            "train",
            "--scenario",
            "right",
            "--updates",
            "20",
            "--out",
            out.to_str().expect("utf-8"),
        ]
        .map(str::to_owned),
    );
    let o = crate::crossroads()
        .command()
        .args(&args)
        .env("CROSSROADS_TOKEN", TOKEN)
        .env("RUST_LOG", "info")
        .output()
        .expect("run crossroads train");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).expect("summary"))
            .expect("json");
    assert_eq!(summary["status"], "finished", "{summary}");
    assert!(summary["updates"].as_u64() >= Some(20), "{summary}");
    // The children served TLS with the token required, and the actor
    // pushed over gRPC.
    for role in ["replay", "learner"] {
        let log = std::fs::read_to_string(out.join(format!("logs/{role}.log"))).expect("log");
        assert!(
            log.contains("tls=true")
                && log.contains("client_certificates=true")
                && log.contains("token=true"),
            "{role}: {log}"
        );
    }
    let config = std::fs::read_to_string(out.join("config.toml")).expect("config");
    assert!(
        !config.contains(TOKEN),
        "the token is not written into the run's config"
    );
}

/// `deploy/make-certs.sh` makes a PKI our servers and clients accept as
/// compose and Kubernetes use it (mutual TLS, the token from its file), by
/// the names the certificate gives (localhost, 127.0.0.1); and it does not
/// overwrite a folder that has one.
#[test]
fn make_certs_script_makes_certificates_the_servers_and_clients_accept() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().expect("temp dir");
    let script = repo.join("deploy/make-certs.sh");
    let o = Command::new(&script)
        .arg(dir.path())
        .output()
        .expect("run make-certs.sh (needs openssl)");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let again = Command::new(&script)
        .arg(dir.path())
        .output()
        .expect("run make-certs.sh");
    assert!(!again.status.success(), "an existing PKI is not replaced");
    assert!(String::from_utf8_lossy(&again.stderr).contains("FORCE=1"));

    let f = |name: &str| Some(dir.path().join(name));
    let mut c = config();
    let tls = &mut c.transport.tls;
    (tls.cert_file, tls.key_file, tls.client_ca_file) =
        (f("server.pem"), f("server.key"), f("ca.pem"));
    (tls.ca_file, tls.client_cert_file, tls.client_key_file) =
        (f("ca.pem"), f("client.pem"), f("client.key"));
    c.transport.auth.token_file = f("token");
    runtime().block_on(async {
        let shutdown = Shutdown::new();
        let replay = crossroads_replay::start(&c, None, shutdown.clone())
            .await
            .expect("replay with the script's PKI");
        let port = replay.local_addr().port();
        for host in ["localhost", "127.0.0.1"] {
            let mut t = c.transport.clone();
            t.replay_endpoint = format!("https://{host}:{port}");
            let client = ReplayClient::new(&t, &c.replay.table).expect("client");
            let ack = client
                .insert(toy_batch(ttg()))
                .await
                .unwrap_or_else(|e| panic!("insert by {host}: {e}"));
            assert_eq!(ack.inserted, 10, "{host}");
        }
        let mut no_token = c.transport.clone();
        no_token.auth.token_file = None;
        assert_unauthenticated(
            replay_client(&no_token, "https", replay.local_addr())
                .insert(toy_batch(ttg()))
                .await,
            "missing authorization metadata",
        );
        shutdown.trigger();
        replay.join().await.expect("replay stops");
    });
}

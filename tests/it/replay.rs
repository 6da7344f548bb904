//! `crossroads replay` as an operator runs it: flags over the config, port
//! 0, SIGTERM, a snapshot on the way out, restored on the way back in.

use std::time::Duration;

use crossroads_config::TransportConfig;
use crossroads_test_support::{RoleProcess, toy_batch};
use crossroads_transport::grpc::ReplayClient;

/// How long the server has to log its address, and to exit after SIGTERM.
const PATIENCE: Duration = Duration::from_secs(30);

/// Starts the server and returns it with the address it logged.
fn start(dir: &std::path::Path) -> (RoleProcess, String) {
    start_with(dir, "telemetry.metrics=false")
}

/// [`start`] with one more `--set`.
fn start_with(dir: &std::path::Path, set: &str) -> (RoleProcess, String) {
    let server = RoleProcess::spawn(
        crate::crossroads()
            .command()
            .args([
                "--set",
                set,
                "replay",
                "--listen",
                "127.0.0.1:0",
                "--no-shm",
                "--capacity",
                "100",
                "--table",
                "cli",
                "--snapshot-dir",
            ])
            .arg(dir),
    );
    let addr = server.addr_within("replay server listening", PATIENCE);
    (server, addr)
}

#[test]
fn replay_serves_until_sigterm_and_restores_its_snapshot() {
    let dir = tempfile::tempdir().expect("temp dir");
    // A runtime per phase: dropping it closes the client's connection, as a
    // client process that ends would.
    let runtime = || {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime")
    };
    let (mut child, addr) = start(dir.path());
    let transport = TransportConfig {
        replay_endpoint: format!("http://{addr}"),
        ..TransportConfig::default()
    };
    let ack = runtime()
        .block_on(async {
            ReplayClient::new(&transport, "cli")?
                .insert(toy_batch(
                    crossroads_sim::observation_layout("ttg").expect("a view"),
                ))
                .await
        })
        .expect("insert");
    assert_eq!((ack.inserted, ack.table_size), (10, 10));
    child.terminate_within(PATIENCE);
    let snapshots: Vec<_> = std::fs::read_dir(dir.path())
        .expect("list")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".crsnap"))
        .collect();
    assert_eq!(snapshots.len(), 1, "one snapshot written at SIGTERM");

    let (mut child, addr) = start(dir.path());
    let transport = TransportConfig {
        replay_endpoint: format!("http://{addr}"),
        ..TransportConfig::default()
    };
    let info = runtime()
        .block_on(async { ReplayClient::new(&transport, "cli")?.info().await })
        .expect("info");
    assert_eq!(
        (info.size, info.capacity),
        (10, 100),
        "restored after a restart"
    );
    child.terminate_within(PATIENCE);
}

/// `crossroads health` (a container's health check) answers for a live
/// role and fails, naming the URL, once it is gone.
#[test]
fn health_follows_the_role_s_liveness() {
    let dir = tempfile::tempdir().expect("temp dir");
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let (mut child, _) = start_with(
        dir.path(),
        &format!("telemetry.metrics_addr=127.0.0.1:{port}"),
    );
    let health = || {
        crate::crossroads()
            .command()
            .args(["--set", &format!("telemetry.metrics_addr=0.0.0.0:{port}")])
            .args(["health", "--timeout-ms", "3000"])
            .output()
            .expect("crossroads health")
    };
    let up = health();
    assert!(up.status.success(), "{up:?}");
    assert_eq!(
        String::from_utf8_lossy(&up.stdout).trim(),
        format!("ok: http://127.0.0.1:{port}/healthz")
    );
    child.terminate_within(PATIENCE);
    let down = health();
    assert_eq!(down.status.code(), Some(1));
    let err = String::from_utf8_lossy(&down.stderr);
    assert!(
        err.contains(&format!(
            "unhealthy: http://127.0.0.1:{port}/healthz: connecting"
        )),
        "{err}"
    );
}

/// A scaled actor asks the replay server for its index; until the server
/// is up it waits, and SIGTERM meanwhile is a clean stop.
#[test]
fn an_actor_waiting_for_its_index_stops_cleanly() {
    let mut actor = crate::crossroads().spawn_role(&[
        "actor",
        "--transport",
        "grpc",
        "--weights",
        "grpc",
        "--replay",
        "http://127.0.0.1:1",
        "--learner",
        "http://127.0.0.1:1",
    ]);
    let waiting = |actor: &RoleProcess, needle: &str| actor.wait_for(needle, PATIENCE).is_some();
    assert!(waiting(
        &actor,
        "waiting for the replay server to hand out an index"
    ));
    actor.terminate_within(PATIENCE);
    assert!(waiting(&actor, "actor stopped before it started acting"));
}

#[test]
fn replay_flags_are_validated_like_the_config() {
    let out = crate::crossroads().output(&["replay", "--capacity", "0", "--no-shm"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("replay.capacity") && err.contains("command line"),
        "{err}"
    );
}

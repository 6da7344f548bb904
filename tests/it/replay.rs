//! `crossroads replay` as an operator runs it: flags over the config, port
//! 0, SIGTERM, a snapshot on the way out, restored on the way back in.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use crossroads_config::TransportConfig;
use crossroads_transport::grpc::ReplayClient;
use crossroads_types::{ObservationEncoding, ObservationSpec, Transition, TransitionBatch};

/// Starts the server and returns it with the address it logged.
fn start(dir: &std::path::Path) -> (Child, String) {
    start_with(dir, "telemetry.metrics=false")
}

/// [`start`] with one more `--set`.
fn start_with(dir: &std::path::Path, set: &str) -> (Child, String) {
    let mut args: Vec<std::ffi::OsString> = [
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
    ]
    .into_iter()
    .map(Into::into)
    .collect();
    args.push(dir.into());
    let (child, lines) = spawn_logging(&args);
    let start = std::time::Instant::now();
    while start.elapsed() < Duration::from_secs(30) {
        if let Ok(line) = lines.recv_timeout(Duration::from_secs(1))
            && line.contains("replay server listening")
            && let Some(addr) = line
                .split_whitespace()
                .find_map(|w| w.strip_prefix("addr="))
        {
            return (child, addr.to_owned());
        }
    }
    panic!("the server never logged its address");
}

/// Runs `crossroads args` with its log lines (stderr, info level) sent to
/// the returned channel.
fn spawn_logging<S: AsRef<std::ffi::OsStr>>(
    args: &[S],
) -> (Child, std::sync::mpsc::Receiver<String>) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_crossroads"))
        .args(args)
        .env_remove("CROSSROADS_CONFIG")
        .env_remove("CROSSROADS_ACTOR__INDEX")
        .env("RUST_LOG", "info")
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn crossroads");
    let stderr = child.stderr.take().expect("stderr");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    (child, rx)
}

fn terminate(mut child: Child) {
    let status = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .expect("kill");
    assert!(status.success());
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(status.success(), "exit status {status}");
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn batch() -> TransitionBatch {
    let mut b = TransitionBatch::new(ObservationSpec::ttg(), 5, ObservationEncoding::SparseF32);
    let mut grid = vec![0.0; ObservationSpec::ttg().num_values().expect("a shape")];
    let mut current = b.push_observation(&grid);
    for i in 0..10 {
        grid[i * 3 + 2] = 1.0;
        let next = b.push_observation(&grid);
        b.push(Transition {
            observation: current,
            action: (i % 5) as u32,
            reward: i as f32,
            discount: 0.99,
            priority: 1.0,
            next_observation: next,
        });
        current = next;
    }
    b
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
    let (child, addr) = start(dir.path());
    let transport = TransportConfig {
        replay_endpoint: format!("http://{addr}"),
        ..TransportConfig::default()
    };
    let ack = runtime()
        .block_on(async { ReplayClient::new(&transport, "cli")?.insert(batch()).await })
        .expect("insert");
    assert_eq!((ack.inserted, ack.table_size), (10, 10));
    terminate(child);
    let snapshots: Vec<_> = std::fs::read_dir(dir.path())
        .expect("list")
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".crsnap"))
        .collect();
    assert_eq!(snapshots.len(), 1, "one snapshot written at SIGTERM");

    let (child, addr) = start(dir.path());
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
    terminate(child);
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
    let (child, _) = start_with(
        dir.path(),
        &format!("telemetry.metrics_addr=127.0.0.1:{port}"),
    );
    let health = || {
        Command::new(env!("CARGO_BIN_EXE_crossroads"))
            .args(["--set", &format!("telemetry.metrics_addr=0.0.0.0:{port}")])
            .args(["health", "--timeout-ms", "3000"])
            .env_remove("CROSSROADS_CONFIG")
            .output()
            .expect("crossroads health")
    };
    let up = health();
    assert!(up.status.success(), "{up:?}");
    assert_eq!(
        String::from_utf8_lossy(&up.stdout).trim(),
        format!("ok: http://127.0.0.1:{port}/healthz")
    );
    terminate(child);
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
    let (child, rx) = spawn_logging(&[
        "--set",
        "telemetry.metrics=false",
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
    let waiting = |rx: &std::sync::mpsc::Receiver<String>, needle: &str| {
        let start = std::time::Instant::now();
        while start.elapsed() < Duration::from_secs(30) {
            if let Ok(line) = rx.recv_timeout(Duration::from_secs(1))
                && line.contains(needle)
            {
                return true;
            }
        }
        false
    };
    assert!(waiting(
        &rx,
        "waiting for the replay server to hand out an index"
    ));
    terminate(child);
    assert!(waiting(&rx, "actor stopped before it started acting"));
}

#[test]
fn replay_flags_are_validated_like_the_config() {
    let out = Command::new(env!("CARGO_BIN_EXE_crossroads"))
        .args(["replay", "--capacity", "0", "--no-shm"])
        .env_remove("CROSSROADS_CONFIG")
        .output()
        .expect("run");
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("replay.capacity") && err.contains("command line"),
        "{err}"
    );
}

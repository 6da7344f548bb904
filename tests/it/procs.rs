//! Real `crossroads` processes for the tests that start, stop and kill
//! them: their log lines on a channel, the address they bind, SIGTERM and
//! SIGKILL.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

/// A running `crossroads` process and its log lines (stderr, info level).
#[derive(Debug)]
pub struct Proc {
    child: Child,
    lines: Receiver<String>,
}

impl Proc {
    /// Starts `crossroads args` without a config from the environment and
    /// without metrics.
    pub fn spawn<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Self {
        Self::spawn_from(Command::new(env!("CARGO_BIN_EXE_crossroads")), args)
    }

    /// [`spawn`](Self::spawn) inside network namespace `netns`.
    pub fn spawn_in<S: AsRef<std::ffi::OsStr>>(netns: &str, args: &[S]) -> Self {
        let mut command = Command::new("ip");
        command
            .args(["netns", "exec", netns])
            .arg(env!("CARGO_BIN_EXE_crossroads"));
        Self::spawn_from(command, args)
    }

    fn spawn_from<S: AsRef<std::ffi::OsStr>>(mut command: Command, args: &[S]) -> Self {
        let mut child = command
            .args(["--set", "telemetry.metrics=false"])
            .args(args)
            .env_remove("CROSSROADS_CONFIG")
            .env_remove("CROSSROADS_ACTOR__INDEX")
            .env("RUST_LOG", "info")
            .stderr(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .expect("spawn crossroads");
        let stderr = child.stderr.take().expect("stderr");
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        Self { child, lines }
    }

    /// The first log line containing `needle` within `timeout`.
    pub fn wait_for(&self, needle: &str, timeout: Duration) -> Option<String> {
        let deadline = Instant::now() + timeout;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(line) if line.contains(needle) => return Some(line),
                Ok(_) => {}
                Err(_) => return None,
            }
        }
        None
    }

    /// The `addr=` of the first log line containing `needle`; fails the
    /// test if none comes within a minute.
    pub fn addr(&self, needle: &str) -> String {
        let line = self
            .wait_for(needle, Duration::from_secs(60))
            .unwrap_or_else(|| panic!("never logged {needle:?}"));
        addr_in(&line)
    }

    /// The `addr=` of the first log line containing each of `needles`, in
    /// whatever order they come; fails the test if one does not come
    /// within a minute.
    pub fn addrs<const N: usize>(&self, needles: [&str; N]) -> [String; N] {
        let mut found: [Option<String>; N] = std::array::from_fn(|_| None);
        let deadline = Instant::now() + Duration::from_secs(60);
        while found.iter().any(Option::is_none) {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = self
                .lines
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("never logged all of {needles:?} (found {found:?})"));
            for (needle, slot) in needles.iter().zip(&mut found) {
                if slot.is_none() && line.contains(needle) {
                    *slot = Some(addr_in(&line));
                }
            }
        }
        found.map(|a| a.expect("found"))
    }

    /// Whether it is still running.
    pub fn is_running(&mut self) -> bool {
        self.child.try_wait().expect("wait").is_none()
    }

    /// Every log line so far.
    pub fn drain(&self) -> Vec<String> {
        self.lines.try_iter().collect()
    }

    /// SIGKILL: no chance to flush or snapshot anything.
    pub fn kill9(mut self) {
        self.child.kill().expect("SIGKILL");
        self.child.wait().expect("reap");
    }

    /// SIGTERM, then waits (a minute at most) for a clean exit.
    pub fn terminate(mut self) {
        rustix::process::kill_process(
            rustix::process::Pid::from_child(&self.child),
            rustix::process::Signal::TERM,
        )
        .expect("SIGTERM");
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().expect("wait") {
                assert!(status.success(), "exit status {status}");
                return;
            }
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "no exit after SIGTERM"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        // A failed test leaves no process behind.
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The `addr=` field of a log line.
fn addr_in(line: &str) -> String {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix("addr="))
        .unwrap_or_else(|| panic!("no addr= in {line:?}"))
        .to_owned()
}

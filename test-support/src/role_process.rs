//! A running role: its log lines on a channel, the address it binds,
//! SIGTERM and SIGKILL.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

/// How long a role has to log an address or to exit after SIGTERM, unless
/// the test says otherwise.
const PATIENCE: Duration = Duration::from_secs(60);

/// A running `crossroads` process and its log lines (standard error, info
/// level). Dropping it kills the process, so a failed test leaves none
/// behind.
#[derive(Debug)]
pub struct RoleProcess {
    child: Child,
    lines: Receiver<String>,
}

impl RoleProcess {
    /// Starts `command` (from [`Crossroads::command`](crate::Crossroads::command),
    /// with its arguments) with `RUST_LOG=info`, its standard error read
    /// line by line onto a channel and its standard output discarded.
    pub fn spawn(command: &mut Command) -> Self {
        let mut child = command
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

    /// The first log line containing `needle` within `timeout`; `None` if
    /// none comes or the process closed its standard error first.
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
        self.addr_within(needle, PATIENCE)
    }

    /// [`addr`](Self::addr) within `timeout`.
    pub fn addr_within(&self, needle: &str, timeout: Duration) -> String {
        let line = self
            .wait_for(needle, timeout)
            .unwrap_or_else(|| panic!("never logged {needle:?} within {timeout:?}"));
        addr_in(&line)
    }

    /// The `addr=` of the first log line containing each of `needles`, in
    /// whatever order they come; fails the test if one does not come
    /// within a minute.
    pub fn addrs<const N: usize>(&self, needles: [&str; N]) -> [String; N] {
        let mut found: [Option<String>; N] = std::array::from_fn(|_| None);
        let deadline = Instant::now() + PATIENCE;
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

    /// SIGTERM, then waits (a minute at most) for a clean exit: fails the
    /// test on a non-zero status or no exit.
    pub fn terminate(mut self) {
        self.terminate_within(PATIENCE);
    }

    /// [`terminate`](Self::terminate) with `limit` for the exit, keeping
    /// the process's lines readable ([`wait_for`](Self::wait_for)) after.
    pub fn terminate_within(&mut self, limit: Duration) {
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
            assert!(start.elapsed() < limit, "no exit after SIGTERM");
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for RoleProcess {
    fn drop(&mut self) {
        // A failed test leaves no process behind; after a clean exit both
        // calls are no-ops.
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

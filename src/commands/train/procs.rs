//! The role processes of a training run: this very binary started as
//! `crossroads replay`, `learner` and `actor`, each in its own process
//! group (so Ctrl-C reaches only `train`, which then stops them in order),
//! each logging into its own file under the run folder.

use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use rustix::process::{Pid, Signal, kill_process};

/// A free TCP port on loopback (bound, read, released; the role binds it
/// again a moment later).
pub fn free_port() -> anyhow::Result<SocketAddr> {
    let l = TcpListener::bind("127.0.0.1:0").context("finding a free port")?;
    l.local_addr().context("finding a free port")
}

/// One role process.
#[derive(Debug)]
pub struct Role {
    /// `replay`, `learner`, `actor-3`.
    pub name: String,
    /// Its `/metrics` address.
    pub metrics: SocketAddr,
    /// Its log file.
    pub log: PathBuf,
    child: Child,
    exited: Option<ExitStatus>,
}

impl Role {
    /// Starts `exe --config config <args>` with `env` added, standard
    /// output and error appended to `log`.
    pub fn spawn(
        name: &str,
        exe: &Path,
        config: &Path,
        args: &[&str],
        env: &[(String, String)],
        log: PathBuf,
        metrics: SocketAddr,
    ) -> anyhow::Result<Self> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log)
            .with_context(|| format!("opening {}", log.display()))?;
        let err = file
            .try_clone()
            .with_context(|| format!("opening {}", log.display()))?;
        let mut cmd = Command::new(exe);
        cmd.arg("--config")
            .arg(config)
            .args(args)
            .env("CROSSROADS_TELEMETRY__METRICS_ADDR", metrics.to_string())
            .envs(env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::null())
            .stdout(file)
            .stderr(err);
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        let child = cmd
            .spawn()
            .with_context(|| format!("starting {name} ({})", exe.display()))?;
        Ok(Self {
            name: name.to_owned(),
            metrics,
            log,
            child,
            exited: None,
        })
    }

    /// How it exited, if it has.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        if self.exited.is_none() {
            self.exited = self.child.try_wait().ok().flatten();
        }
        self.exited
    }

    /// Asks it to stop (SIGTERM: the role finishes its work, e.g. a last
    /// checkpoint), waits up to `grace`, then kills it.
    pub async fn stop(&mut self, grace: Duration) -> Option<ExitStatus> {
        if self.exited().is_some() {
            return self.exited;
        }
        let _ = kill_process(Pid::from_child(&self.child), Signal::TERM);
        let start = Instant::now();
        while start.elapsed() < grace {
            if self.exited().is_some() {
                return self.exited;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        tracing::warn!(role = %self.name, "did not stop within {grace:?}; killing it");
        let _ = self.child.kill();
        self.exited = self.child.wait().ok();
        self.exited
    }

    /// The last `lines` lines of its log, for error messages.
    pub fn log_tail(&self, lines: usize) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let all: Vec<&str> = text.lines().collect();
        all[all.len().saturating_sub(lines)..].join("\n")
    }
}

impl Drop for Role {
    fn drop(&mut self) {
        if self.exited().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

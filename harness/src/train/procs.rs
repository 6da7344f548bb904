//! The role processes of a training run: this very binary started as
//! `crossroads replay`, `learner` and `actor`, each in its own process
//! group (so Ctrl-C reaches only `train`, which then stops them in order),
//! each logging into its own file under the run folder and inheriting what
//! every child of this program does (`crate::child`); the addresses they
//! are given, and waiting until one answers.

use std::net::{SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_common::Shutdown;
use rustix::process::{Pid, Signal, kill_process};

/// A free TCP port on loopback (bound, read, released; the role binds it
/// again a moment later).
pub fn free_port() -> anyhow::Result<SocketAddr> {
    let l = TcpListener::bind("127.0.0.1:0").context("finding a free port")?;
    l.local_addr().context("finding a free port")
}

/// One role process.
#[derive(Debug)]
pub struct RoleChild {
    /// `replay`, `learner`, `actor-3`.
    pub name: String,
    /// Its `/metrics` address.
    pub metrics: SocketAddr,
    /// Its log file.
    pub log: PathBuf,
    child: Child,
    exited: Option<ExitStatus>,
}

impl RoleChild {
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
        let mut cmd = crate::child::crossroads(exe);
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

impl Drop for RoleChild {
    fn drop(&mut self) {
        if self.exited().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The addresses of one session's roles.
pub struct Addresses {
    pub replay: SocketAddr,
    pub learner: SocketAddr,
    pub shm_prefix: String,
    /// `https` when the run's servers speak TLS, else `http`.
    pub scheme: &'static str,
}

impl Addresses {
    /// Free loopback ports for the replay and the learner, and iceoryx2
    /// service names unique to this run folder and process; `scheme` is
    /// the URLs' (`transport.tls`'s).
    pub fn pick(out: &Path, scheme: &'static str) -> anyhow::Result<Self> {
        let name = out
            .file_name()
            .map_or("run".into(), |n| n.to_string_lossy().into_owned());
        let name: String = name
            .chars()
            .map(|ch| if ch.is_ascii_alphanumeric() { ch } else { '-' })
            .collect();
        Ok(Self {
            replay: free_port()?,
            learner: free_port()?,
            shm_prefix: format!("crossroads/train-{name}-{}", std::process::id()),
            scheme,
        })
    }

    /// The replay's URL.
    pub fn replay_url(&self) -> String {
        format!("{}://{}", self.scheme, self.replay)
    }

    /// The learner's URL.
    pub fn learner_url(&self) -> String {
        format!("{}://{}", self.scheme, self.learner)
    }

    /// The variables every role gets (they override the file). Each role
    /// is this binary, which sets libgomp's passive wait policy itself
    /// (`main`), so the roles sharing these cores do not starve each other.
    pub fn env(&self) -> Vec<(String, String)> {
        let mut env = Vec::new();
        env.extend([
            ("CROSSROADS_REPLAY__LISTEN".into(), self.replay.to_string()),
            (
                "CROSSROADS_TRANSPORT__REPLAY_ENDPOINT".into(),
                self.replay_url(),
            ),
            (
                "CROSSROADS_LEARNER__LISTEN".into(),
                self.learner.to_string(),
            ),
            (
                "CROSSROADS_TRANSPORT__LEARNER_ENDPOINT".into(),
                self.learner_url(),
            ),
            (
                "CROSSROADS_TRANSPORT__SHM_PREFIX".into(),
                self.shm_prefix.clone(),
            ),
        ]);
        env
    }
}

/// Waits until `probe` answers, failing early when the role exits (with
/// the end of its log) or after two minutes. With `done_counts`, a clean
/// exit counts as ready: a resumed learner with few updates left can
/// finish its budget before the first probe (the session then sees it
/// ended and evaluates its last checkpoint).
pub async fn wait_ready<F, Fut>(
    role: &mut RoleChild,
    shutdown: &Shutdown,
    done_counts: bool,
    probe: F,
) -> anyhow::Result<()>
where
    F: Fn() -> Fut,
    Fut: Future<Output = Result<(), String>>,
{
    let start = Instant::now();
    loop {
        if let Some(status) = role.exited() {
            if done_counts && status.success() {
                return Ok(());
            }
            anyhow::bail!(
                "{} exited ({status}) before it was ready; the end of {}:\n{}",
                role.name,
                role.log.display(),
                role.log_tail(20)
            );
        }
        match probe().await {
            Ok(()) => return Ok(()),
            Err(e) if start.elapsed() > Duration::from_secs(120) => {
                anyhow::bail!("{} not ready after 2 minutes: {e}", role.name)
            }
            Err(_) => {}
        }
        if shutdown.is_triggered() {
            anyhow::bail!("stopped before {} was ready", role.name);
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// The error of a role that exited on its own, with the end of its log.
pub fn died(role: &RoleChild, status: ExitStatus) -> anyhow::Error {
    anyhow::anyhow!(
        "{} exited ({status}); the end of {}:\n{}",
        role.name,
        role.log.display(),
        role.log_tail(20)
    )
}

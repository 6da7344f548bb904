//! The role processes of a training run: this very binary started as
//! `crossroads replay`, `learner` and `actor`, each in its own process
//! group (so Ctrl-C reaches only `train`, which then stops them in order),
//! each logging into its own file under the run folder and inheriting what
//! every child of this program does (`crate::child`); the addresses they
//! bind and announce, and waiting until one answers.
//!
//! Every role binds port 0 and announces the address it got in a file
//! (`crate::role::announce`): a port picked here and bound there a moment
//! later could be taken in between by any other program on the host.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_common::Shutdown;
use rustix::process::{Pid, Signal, kill_process};

use crate::role::{ANNOUNCE_VAR, announced_path};

/// What a role binds: port 0 on loopback, the kernel picks the port.
const ANY_PORT: &str = "127.0.0.1:0";

/// How long a role may take to bind what it announces.
const ANNOUNCE_TIMEOUT: Duration = Duration::from_secs(120);

/// What every role of a session is started with.
#[derive(Debug, Clone, Copy)]
pub struct Launch<'a> {
    /// This program.
    pub exe: &'a Path,
    /// The run's `config.toml`.
    pub config: &'a Path,
    /// The run's `logs` folder.
    pub logs: &'a Path,
    /// Whether roles serve metrics (`telemetry.metrics`).
    pub metrics: bool,
}

/// One role process.
#[derive(Debug)]
pub struct RoleChild {
    /// `replay`, `learner`, `actor-3`.
    pub name: String,
    /// Its `/metrics` address, once announced (none when
    /// `telemetry.metrics` is off).
    pub metrics: Option<SocketAddr>,
    /// Whether it serves metrics (`telemetry.metrics`).
    metrics_on: bool,
    /// Its log file.
    pub log: PathBuf,
    /// Where it announces what it bound (`<logs>/<name>`, a suffix per
    /// address).
    announce: PathBuf,
    child: Child,
    exited: Option<ExitStatus>,
}

impl RoleChild {
    /// Starts `launch.exe --config launch.config <args>` with `env` added,
    /// standard output and error appended to `<launch.logs>/<name>.log`,
    /// its metrics on a port of its own choosing (`await_metrics` or
    /// `metrics_now` learns which).
    pub fn spawn(
        launch: &Launch<'_>,
        name: &str,
        args: &[&str],
        env: &[(String, String)],
    ) -> anyhow::Result<Self> {
        let Launch {
            exe,
            config,
            logs,
            metrics,
        } = *launch;
        let log = logs.join(format!("{name}.log"));
        let announce = logs.join(name);
        for what in ["metrics", "listen"] {
            let stale = announced_path(&announce, what);
            match std::fs::remove_file(&stale) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e).with_context(|| format!("removing {}", stale.display())),
            }
        }
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
            .env("CROSSROADS_TELEMETRY__METRICS_ADDR", ANY_PORT)
            .env(ANNOUNCE_VAR, &announce)
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
            metrics: None,
            metrics_on: metrics,
            log,
            announce,
            child,
            exited: None,
        })
    }

    /// Waits until it announces its metrics port, when it serves metrics.
    pub async fn await_metrics(&mut self, shutdown: &Shutdown) -> anyhow::Result<()> {
        if self.metrics_on {
            self.metrics = Some(self.announced("metrics", shutdown).await?);
        }
        Ok(())
    }

    /// Its metrics port if it has announced it by now (without waiting).
    pub fn metrics_now(&mut self) -> Option<SocketAddr> {
        if self.metrics.is_none() && self.metrics_on {
            self.metrics = self.read_announced("metrics").ok().flatten();
        }
        self.metrics
    }

    /// The address it has announced for `what` (`metrics`, `listen`), if
    /// it has.
    fn read_announced(&self, what: &str) -> anyhow::Result<Option<SocketAddr>> {
        let path = announced_path(&self.announce, what);
        match std::fs::read_to_string(&path) {
            Ok(text) => text.trim().parse().map(Some).with_context(|| {
                format!(
                    "{} announced {what} {text:?} in {}",
                    self.name,
                    path.display()
                )
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e).with_context(|| format!("reading {}", path.display())),
        }
    }

    /// The address it announces for `what` (`metrics`, `listen`), waiting
    /// for it; fails when it exits first (with the end of its log), on a
    /// signal, or after two minutes.
    pub async fn announced(
        &mut self,
        what: &str,
        shutdown: &Shutdown,
    ) -> anyhow::Result<SocketAddr> {
        let start = Instant::now();
        loop {
            if let Some(addr) = self.read_announced(what)? {
                return Ok(addr);
            }
            if let Some(status) = self.exited() {
                anyhow::bail!(
                    "{} exited ({status}) before it announced its {what} address; the end of {}:\n{}",
                    self.name,
                    self.log.display(),
                    self.log_tail(20)
                );
            }
            if start.elapsed() > ANNOUNCE_TIMEOUT {
                anyhow::bail!(
                    "{} did not announce its {what} address in {} within 2 minutes",
                    self.name,
                    announced_path(&self.announce, what).display()
                );
            }
            if shutdown.is_triggered() {
                anyhow::bail!("stopped before {} started", self.name);
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
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

/// The addresses of one session's roles: the replay's and learner's are
/// known once each has announced it.
pub struct Addresses {
    pub replay: Option<SocketAddr>,
    pub learner: Option<SocketAddr>,
    pub shm_prefix: String,
    /// `https` when the run's servers speak TLS, else `http`.
    pub scheme: &'static str,
}

impl Addresses {
    /// iceoryx2 service names unique to this run folder and process;
    /// `scheme` is the URLs' (`transport.tls`'s).
    pub fn new(out: &Path, scheme: &'static str) -> Self {
        let name = out
            .file_name()
            .map_or("run".into(), |n| n.to_string_lossy().into_owned());
        let name: String = name
            .chars()
            .map(|ch| if ch.is_ascii_alphanumeric() { ch } else { '-' })
            .collect();
        Self {
            replay: None,
            learner: None,
            shm_prefix: format!("crossroads/train-{name}-{}", std::process::id()),
            scheme,
        }
    }

    /// The replay's URL (empty before it is known).
    pub fn replay_url(&self) -> String {
        self.replay
            .map_or_else(String::new, |a| format!("{}://{a}", self.scheme))
    }

    /// The learner's URL (empty before it is known).
    pub fn learner_url(&self) -> String {
        self.learner
            .map_or_else(String::new, |a| format!("{}://{a}", self.scheme))
    }

    /// The variables the next role gets (they override the file): both
    /// servers listen on a port of their own choosing, the clients reach
    /// those known so far. Each role is this binary, which sets libgomp's
    /// passive wait policy itself (`main`), so the roles sharing these
    /// cores do not starve each other.
    pub fn env(&self) -> Vec<(String, String)> {
        let mut env = vec![
            ("CROSSROADS_REPLAY__LISTEN".into(), ANY_PORT.into()),
            ("CROSSROADS_LEARNER__LISTEN".into(), ANY_PORT.into()),
            (
                "CROSSROADS_TRANSPORT__SHM_PREFIX".into(),
                self.shm_prefix.clone(),
            ),
        ];
        if self.replay.is_some() {
            env.push((
                "CROSSROADS_TRANSPORT__REPLAY_ENDPOINT".into(),
                self.replay_url(),
            ));
        }
        if self.learner.is_some() {
            env.push((
                "CROSSROADS_TRANSPORT__LEARNER_ENDPOINT".into(),
                self.learner_url(),
            ));
        }
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

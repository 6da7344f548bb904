//! This program started again as a child process: the one place that
//! decides what a child inherits, and how a `crossroads train` child is
//! started, waited for and stopped.
//!
//! A child's configuration comes from its command line: the parent names
//! the file (`--config`), the built-in experiment (`--experiment`) and
//! the `--set`s it wants. So no child inherits [`LAYER_VARIABLES`]: an
//! inherited `CROSSROADS_EXPERIMENT` would add a layer under the file the
//! parent chose (`reproduce` writes each experiment to a file), and an
//! inherited `CROSSROADS_CONFIG` would stand in for a `--config` the
//! parent left out on purpose (`bench time-to-target` of the default
//! experiment). The `CROSSROADS_<SECTION>__<KEY>` variables pass on: they
//! are the user's overrides of every run.

use std::ffi::OsStr;
use std::fs::File;
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::Duration;

use anyhow::Context;
use crossroads_common::Shutdown;
use rustix::process::{Pid, Signal, kill_process};

/// The variables that name configuration layers, which a child never
/// inherits.
pub const LAYER_VARIABLES: [&str; 2] = ["CROSSROADS_CONFIG", "CROSSROADS_EXPERIMENT"];

/// `exe` (this program) as a command that inherits none of
/// [`LAYER_VARIABLES`].
pub fn crossroads(exe: &Path) -> Command {
    let mut cmd = Command::new(exe);
    for var in LAYER_VARIABLES {
        cmd.env_remove(var);
    }
    cmd
}

/// A shutdown signal fired by SIGINT or SIGTERM, for a synchronous command
/// that starts children, and the one-thread runtime that listens for the
/// signals: keep it alive as long as the signal is needed.
pub fn on_signals() -> anyhow::Result<(tokio::runtime::Runtime, Shutdown)> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let shutdown = {
        let _enter = runtime.enter();
        Shutdown::on_signals().context("installing the signal handlers")?
    };
    Ok((runtime, shutdown))
}

/// A `crossroads train` child (or any command of this program that stops
/// cleanly on SIGTERM), in this process group, so Ctrl-C at a terminal
/// reaches it too.
#[derive(Debug)]
pub struct TrainingChild {
    child: Child,
}

/// How a [`TrainingChild`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrainingExit {
    /// It exited on its own.
    Exited(ExitStatus),
    /// The parent's shutdown fired and the child stopped as asked (a
    /// training run can resume from where it stopped).
    Stopped(ExitStatus),
}

impl TrainingChild {
    /// Starts this program with `args`. With `log`, the child's standard
    /// output and error go there and its standard input is closed; without,
    /// it shares this process's (its progress bar shows).
    pub fn start(
        args: impl IntoIterator<Item = impl AsRef<OsStr>>,
        log: Option<File>,
    ) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("finding this program")?;
        let mut cmd = crossroads(&exe);
        cmd.args(args);
        if let Some(file) = log {
            cmd.stdout(file.try_clone().context("the log file")?)
                .stderr(file)
                .stdin(Stdio::null());
        }
        let child = cmd.spawn().context("starting crossroads train")?;
        Ok(Self { child })
    }

    /// Waits until the child exits. Once `shutdown` fires, passes SIGTERM
    /// on (Ctrl-C reached the child already, and a repeat within a second
    /// is the same request there; a SIGTERM sent to this process alone
    /// would not reach it) and waits for it to stop.
    pub fn wait(mut self, shutdown: &Shutdown) -> anyhow::Result<TrainingExit> {
        loop {
            if let Some(status) = self
                .child
                .try_wait()
                .context("waiting for crossroads train")?
            {
                return Ok(TrainingExit::Exited(status));
            }
            if shutdown.is_triggered() {
                let _ = kill_process(Pid::from_child(&self.child), Signal::TERM);
                let status = self.child.wait().context("waiting for crossroads train")?;
                return Ok(TrainingExit::Stopped(status));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

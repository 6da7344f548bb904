//! The `crossroads` binary, run with a clean environment.

use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::RoleProcess;

/// Prefix of the variables removed: every one the binary reads (config
/// file, experiment, config keys, token, learner URL, Python) and the
/// tests' own gates.
const PREFIX: &str = "CROSSROADS_";

/// The `crossroads` binary at a path the caller gives. Every command it
/// makes runs without the `CROSSROADS_*` variables of this process (a
/// config file, an experiment, a config key, a token, a gate), so a test
/// sees what it sets and nothing of the shell it runs in.
#[derive(Debug, Clone)]
pub struct Crossroads {
    bin: PathBuf,
    /// A program and its arguments that run the binary (`ip netns exec
    /// NAME`); empty to run it directly.
    under: Vec<OsString>,
}

impl Crossroads {
    /// The binary at `bin`: in the root package's tests
    /// `Crossroads::new(env!("CARGO_BIN_EXE_crossroads"))`.
    pub fn new(bin: impl Into<PathBuf>) -> Self {
        Self {
            bin: bin.into(),
            under: Vec::new(),
        }
    }

    /// The same binary started by `wrapper` (`["ip", "netns", "exec",
    /// NAME]`, say): its commands are `wrapper... bin args...`, with the
    /// environment cleaned the same way.
    pub fn under<S: AsRef<OsStr>>(mut self, wrapper: &[S]) -> Self {
        self.under = wrapper.iter().map(|s| s.as_ref().to_owned()).collect();
        self
    }

    /// The binary's path.
    pub fn bin(&self) -> &Path {
        &self.bin
    }

    /// A command running the binary with no argument yet and no
    /// `CROSSROADS_*` variable of this process's environment.
    pub fn command(&self) -> Command {
        let mut command = match self.under.split_first() {
            Some((program, args)) => {
                let mut c = Command::new(program);
                c.args(args).arg(&self.bin);
                c
            }
            None => Command::new(&self.bin),
        };
        for (key, _) in std::env::vars_os() {
            if key.to_str().is_some_and(|k| k.starts_with(PREFIX)) {
                command.env_remove(key);
            }
        }
        command
    }

    /// `crossroads args`, run to its end.
    pub fn output<S: AsRef<OsStr>>(&self, args: &[S]) -> Output {
        self.command().args(args).output().expect("run crossroads")
    }

    /// `crossroads --set telemetry.metrics=false args` as a
    /// [`RoleProcess`]: a role without metrics unless `args` turn them on
    /// (a later `--set` wins), its info-level log on a channel.
    pub fn spawn_role<S: AsRef<OsStr>>(&self, args: &[S]) -> RoleProcess {
        RoleProcess::spawn(
            self.command()
                .args(["--set", "telemetry.metrics=false"])
                .args(args),
        )
    }
}

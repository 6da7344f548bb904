//! The options every `crossroads` command takes: where the configuration
//! comes from (a file, a built-in experiment, `--set`), and the layers
//! they describe.

use std::path::PathBuf;

use clap::Args;
use crossroads_config::ConfigLoader;

/// Options every subcommand takes: where the configuration comes from.
#[derive(Debug, Clone, Args)]
pub struct GlobalArgs {
    /// TOML configuration file (one file describes a whole run; every role
    /// reads it). Environment variables CROSSROADS_<SECTION>__<KEY> override
    /// it, and --set overrides both.
    #[arg(
        long,
        short = 'c',
        global = true,
        env = "CROSSROADS_CONFIG",
        value_name = "FILE"
    )]
    pub config: Option<PathBuf>,

    /// Start from a built-in experiment of configs/experiments/ (ttg-left,
    /// sequential-right, ...): its settings lie under the file, the
    /// environment and --set. How a container of a scaled run picks the
    /// paper's tuned settings without a file.
    #[arg(
        long,
        global = true,
        env = "CROSSROADS_EXPERIMENT",
        value_name = "NAME",
        value_parser = experiment_name
    )]
    pub experiment: Option<String>,

    /// Override one configuration key, e.g. --set runtime.worker_threads=4.
    /// Repeatable; applied after the file and the environment.
    #[arg(long = "set", short = 's', global = true, value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

/// Every `--set KEY=VALUE` (also `--set=KEY=VALUE` and `-s KEY=VALUE`) of
/// a command line, in order, wherever it stands: clap keeps only the group
/// after the subcommand when a global flag appears on both sides of it.
/// Stops at `--`.
pub fn every_set(args: impl IntoIterator<Item = std::ffi::OsString>) -> Vec<String> {
    let mut sets = Vec::new();
    let mut args = args.into_iter().map(|a| a.to_string_lossy().into_owned());
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--" => break,
            "--set" | "-s" => sets.extend(args.next()),
            _ => {
                if let Some(v) = arg.strip_prefix("--set=") {
                    sets.push(v.to_owned());
                }
            }
        }
    }
    sets
}

impl GlobalArgs {
    /// The configuration layers these options describe.
    pub fn loader(&self) -> ConfigLoader {
        let mut loader = ConfigLoader::new();
        if let Some(e) = self
            .experiment
            .as_deref()
            .and_then(crate::experiments::named)
        {
            loader = loader.base(format!("built-in experiment {}", e.name), e.toml);
        }
        loader
            .file(self.config.as_ref())
            .sets(self.sets.iter().cloned())
    }
}

/// A built-in experiment's name, or an error listing them.
fn experiment_name(name: &str) -> Result<String, String> {
    match crate::experiments::named(name) {
        Some(e) => Ok(e.name.to_owned()),
        None => Err(format!(
            "no built-in experiment {name:?}; there are {}",
            crate::experiments::EXPERIMENTS
                .iter()
                .map(|e| e.name)
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// A flag that sets one configuration key: its clap id (the field's
/// name), the key, and how a parsed command line sets it. A command lists
/// its flags in one table, which both layers them ([`layer`]) and names
/// each key in its flag's help ([`with_keys`]), so a key is written once.
#[derive(Debug)]
pub struct KeyFlag<A> {
    id: &'static str,
    key: &'static str,
    setting: Setting<A>,
}

#[derive(Debug)]
enum Setting<A> {
    /// Layers the flag's value, when given, at the key ([`given`]).
    Value(fn(&A, &str, ConfigLoader) -> ConfigLoader),
    /// A switch: when it is on, the key gets this value.
    Switch(fn(&A) -> bool, bool),
}

impl<A> KeyFlag<A> {
    /// A flag whose value is the key's.
    pub const fn value(
        id: &'static str,
        key: &'static str,
        set: fn(&A, &str, ConfigLoader) -> ConfigLoader,
    ) -> Self {
        Self {
            id,
            key,
            setting: Setting::Value(set),
        }
    }

    /// A switch that sets the key to true.
    pub const fn on(id: &'static str, key: &'static str, given: fn(&A) -> bool) -> Self {
        Self {
            id,
            key,
            setting: Setting::Switch(given, true),
        }
    }

    /// A switch that sets the key to false (`--no-...`).
    pub const fn off(id: &'static str, key: &'static str, given: fn(&A) -> bool) -> Self {
        Self {
            id,
            key,
            setting: Setting::Switch(given, false),
        }
    }

    /// What the flag's help says of its key: `(key)`, or `(key = false)`
    /// for a switch that turns it off.
    fn named(&self) -> String {
        match self.setting {
            Setting::Switch(_, false) => format!("({} = false)", self.key),
            _ => format!("({})", self.key),
        }
    }
}

/// A [`KeyFlag`] for the field of the same name of a command's `Args`:
/// `key_flag!(envs => "actor.envs")` layers the field's value when given;
/// `key_flag!(on eval => "actor.eval")` and `key_flag!(off no_shm =>
/// "replay.shm_ingest")` are switches that set the key to true or false.
#[macro_export]
macro_rules! key_flag {
    (on $field:ident => $key:literal) => {
        $crate::global::KeyFlag::on(stringify!($field), $key, |a| a.$field)
    };
    (off $field:ident => $key:literal) => {
        $crate::global::KeyFlag::off(stringify!($field), $key, |a| a.$field)
    };
    ($field:ident => $key:literal) => {
        $crate::global::KeyFlag::value(stringify!($field), $key, |a, k, l| {
            $crate::global::given(l, k, &a.$field)
        })
    };
}

/// `value` at `key` over `loader`, when given.
pub fn given(
    loader: ConfigLoader,
    key: &str,
    value: &Option<impl serde::Serialize>,
) -> ConfigLoader {
    match value {
        Some(v) => loader.flag(key, v),
        None => loader,
    }
}

/// The flags of `table` that `args` gives, layered over `loader` in the
/// table's order.
pub fn layer<A>(args: &A, table: &[KeyFlag<A>], mut loader: ConfigLoader) -> ConfigLoader {
    for flag in table {
        loader = match flag.setting {
            Setting::Value(set) => set(args, flag.key, loader),
            Setting::Switch(on, value) if on(args) => loader.flag(flag.key, value),
            Setting::Switch(..) => loader,
        };
    }
    loader
}

/// `cmd` with each flag of `table` naming its key at the end of its help.
/// Panics if `table` names a flag `cmd` lacks (a test parses the command
/// line).
pub fn with_keys<A>(cmd: clap::Command, table: &[KeyFlag<A>]) -> clap::Command {
    if let Some(flag) = table
        .iter()
        .find(|f| !cmd.get_arguments().any(|a| a.get_id() == f.id))
    {
        panic!(
            "{} has no flag {} for {}",
            cmd.get_name(),
            flag.id,
            flag.key
        );
    }
    let ids: Vec<String> = cmd
        .get_arguments()
        .map(|a| a.get_id().to_string())
        .collect();
    // `mut_arg` moves the flag it edits to the end: every flag is edited in
    // turn, so the help keeps the declared order.
    ids.iter().fold(cmd, |cmd, id| {
        let Some(flag) = table.iter().find(|f| f.id == id.as_str()) else {
            return cmd.mut_arg(id, |arg| arg);
        };
        let named = flag.named();
        cmd.mut_arg(id, |arg| {
            let help = arg
                .get_help()
                .map_or_else(|| named.clone(), |h| format!("{h} {named}"));
            let long = arg.get_long_help().map(|h| format!("{h} {named}"));
            let arg = arg.help(help);
            match long {
                Some(long) => arg.long_help(long),
                None => arg,
            }
        })
    })
}

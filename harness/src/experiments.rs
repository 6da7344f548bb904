//! The paper's experiments as built-in configurations: the files of
//! `configs/experiments/`, compiled into the binary so `crossroads train`
//! and `crossroads reproduce` work from any folder.
//!
//! An experiment is a configuration layer under the file, the environment
//! and `--set` (`ConfigLoader::base`): any command takes one with
//! `--experiment NAME` (or `CROSSROADS_EXPERIMENT`), `crossroads train`
//! without a file starts from the one for its scenario and action set, and
//! `crossroads reproduce` trains them. `tests/it/experiments.rs` checks the
//! files.

/// One experiment: `<actions>-<scenario>` (a variant of one:
/// `<actions>-<scenario>+<variant>`) and its TOML text.
#[derive(Debug, Clone, Copy)]
pub struct Experiment {
    /// `<actions>-<scenario>` or `<actions>-<scenario>+<variant>`, the
    /// file's stem.
    pub name: &'static str,
    /// The configuration (a TOML document with `[sim]`, `[actor]`,
    /// `[replay]`, `[learner]` and `[train]`).
    pub toml: &'static str,
}

impl Experiment {
    /// The experiment a variant varies (`creep-occluded` for
    /// `creep-occluded+shield`); the name itself for any other.
    pub fn base(&self) -> &'static str {
        self.name
            .split_once('+')
            .map_or(self.name, |(base, _)| base)
    }
}

macro_rules! experiments {
    ($($name:literal),* $(,)?) => {
        &[$(Experiment {
            name: $name,
            toml: include_str!(concat!("../../configs/experiments/", $name, ".toml")),
        }),*]
    };
}

/// The experiment `crossroads train` trains without a file or flags
/// (DQN-TTG on left, what `make run` trains), and the base of `crossroads
/// doctor` and `bench time-to-target` without `--config` or
/// `--experiment`.
pub const DEFAULT_EXPERIMENT: &str = "ttg-left";

/// Every experiment of `configs/experiments/`.
pub const EXPERIMENTS: &[Experiment] = experiments![
    "ttg-right",
    "ttg-left",
    "ttg-left2",
    "ttg-forward",
    "ttg-challenge",
    "ttg-right+shield",
    "ttg-left+shield",
    "ttg-left2+shield",
    "ttg-forward+shield",
    "ttg-challenge+shield",
    "sequential-right",
    "sequential-left",
    "sequential-left2",
    "sequential-forward",
    "sequential-challenge",
    "ttg-occluded",
    "creep-occluded",
    "creep-occluded+shield",
    "sequential-occluded",
];

/// How many networks `crossroads reproduce` trains for the experiment
/// `name`, each from its own seed, to act on the mean of their Q-values:
/// 1, except on Left, where one network's rare mistakes (about 2 in 10,000
/// trials, each at a state that collides in every future; NOTES.md) are
/// twice the paper's collision rate and independently trained networks make
/// different ones.
pub fn members(name: &str) -> u32 {
    match name {
        "ttg-left" => 3,
        _ => 1,
    }
}

/// The run folder of member `k` (from 1) of the experiment `name`: the
/// experiment's own name for the first, `<name>-seed<k>` for the others.
pub fn member_run(name: &str, k: u32) -> String {
    if k <= 1 {
        name.to_owned()
    } else {
        format!("{name}-seed{k}")
    }
}

/// The experiment called `name` (`ttg-left`, say).
pub fn named(name: &str) -> Option<Experiment> {
    EXPERIMENTS.iter().copied().find(|e| e.name == name)
}

/// The experiment that trains `actions` on `scenario`, if the paper has
/// one (`scenario` is a built-in name; a file has none); never a variant.
pub fn find(actions: &str, scenario: &str) -> Option<Experiment> {
    named(&format!("{actions}-{scenario}"))
}

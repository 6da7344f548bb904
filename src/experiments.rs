//! The paper's experiments as built-in configurations: the files of
//! `configs/experiments/`, compiled into the binary so `crossroads train`
//! and `crossroads reproduce` work from any folder.

/// One experiment: `<actions>-<scenario>` and its TOML text.
#[derive(Debug, Clone, Copy)]
pub struct Experiment {
    /// `<actions>-<scenario>`, the file's stem.
    pub name: &'static str,
    /// The configuration (a TOML document with `[actor]`, `[replay]`,
    /// `[learner]` and `[train]`).
    pub toml: &'static str,
}

macro_rules! experiments {
    ($($name:literal),* $(,)?) => {
        &[$(Experiment {
            name: $name,
            toml: include_str!(concat!("../configs/experiments/", $name, ".toml")),
        }),*]
    };
}

/// Every experiment of `configs/experiments/`.
pub const EXPERIMENTS: &[Experiment] = experiments![
    "ttg-right",
    "ttg-left",
    "ttg-left2",
    "ttg-forward",
    "ttg-challenge",
    "sequential-right",
    "sequential-left",
    "sequential-left2",
    "sequential-forward",
    "sequential-challenge",
    "ttg-occluded",
    "creep-occluded",
    "sequential-occluded",
];

/// The experiment called `name` (`ttg-left`, say).
pub fn named(name: &str) -> Option<Experiment> {
    EXPERIMENTS.iter().copied().find(|e| e.name == name)
}

/// The experiment that trains `actions` on `scenario`, if the paper has
/// one (`scenario` is a built-in name; a file has none).
pub fn find(actions: &str, scenario: &str) -> Option<Experiment> {
    named(&format!("{actions}-{scenario}"))
}

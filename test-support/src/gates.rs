//! The environment variables that gate tests, read one way: a gate is on
//! when its variable is `1`.
//!
//! A test that is slow or needs a tool is `#[ignore = "why"]`, so plain
//! `cargo test` lists it as ignored with its reason; `cargo test --
//! --include-ignored` (as `make test` runs) runs it, and the test then asks
//! its gate here:
//!
//! - a slow test runs only with [`SLOW_TESTS`]`=1`
//!   ([`slow_tests_enabled`]), so `--include-ignored` for the tool-bound
//!   tests does not start the long trainings;
//! - a test whose tool is missing calls [`skip_unless_required`]: it fails
//!   when `CROSSROADS_REQUIRE_<TOOL>=1` ([`Need::variable`]) says the tool
//!   must be there, and otherwise says why it skips and returns.
//!
//! `make test` sets all of them but `CROSSROADS_REQUIRE_CUDA` (and
//! `CROSSROADS_REQUIRE_MOUNT` only as root), so there a missing tool fails
//! instead of skipping.

use std::io::Write;

/// Runs the slow end-to-end trainings.
pub const SLOW_TESTS: &str = "CROSSROADS_SLOW_TESTS";

/// Makes the fault suite the long one: every kill many more times.
pub const LONG_FAULTS: &str = "CROSSROADS_LONG_FAULTS";

/// Whether gate `variable` is on: set to `1`. Every gate is read here.
pub fn is_on(variable: &str) -> bool {
    std::env::var(variable).is_ok_and(|v| v == "1")
}

/// Whether the slow tests run: [`SLOW_TESTS`]`=1`, as `make test` sets.
/// Without it a slow test says why it skips and returns; a quick twin
/// covers the same path at a small budget.
pub fn slow_tests_enabled(test: &str) -> bool {
    if is_on(SLOW_TESTS) {
        return true;
    }
    say(&format!(
        "skipped: set {SLOW_TESTS}=1 to run {test} (a slow training)"
    ));
    false
}

/// What a tool-bound test needs, each with its `CROSSROADS_REQUIRE_*`
/// variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Need {
    /// Python with safetensors (and, for the deployment's schemas,
    /// kubernetes-validate).
    Python,
    /// Docker with Compose, prometheus and kubectl.
    Docker,
    /// SUMO in the repository's `.venv`.
    Sumo,
    /// Root: a tmpfs mount, network namespaces.
    Mount,
    /// A CUDA device and a CUDA libtorch.
    Cuda,
}

impl Need {
    /// The variable that, at `1`, makes this need a requirement.
    pub const fn variable(self) -> &'static str {
        match self {
            Self::Python => "CROSSROADS_REQUIRE_PYTHON",
            Self::Docker => "CROSSROADS_REQUIRE_DOCKER",
            Self::Sumo => "CROSSROADS_REQUIRE_SUMO",
            Self::Mount => "CROSSROADS_REQUIRE_MOUNT",
            Self::Cuda => "CROSSROADS_REQUIRE_CUDA",
        }
    }

    /// Whether it must be met here: its variable is `1`.
    pub fn is_required(self) -> bool {
        is_on(self.variable())
    }
}

/// For a test that finds `need` unmet (`why`: what is missing, and how to
/// get it): fails the test if `need` is required here, and otherwise says
/// that the test skips. The caller returns after it.
pub fn skip_unless_required(need: Need, why: &str) {
    assert!(
        !need.is_required(),
        "{why}; {}=1 requires it",
        need.variable()
    );
    say(&format!("skipped: {why}"));
}

/// A line straight to the process's standard error: libtest captures only
/// the print macros, so it shows in a passing run too.
fn say(line: &str) {
    let _ = writeln!(std::io::stderr(), "{line}");
}

//! `crossroads docs`: the documents generated from the code and the
//! committed report, so that they cannot drift from either.
//!
//! - `docs/reference/cli.md` from the clap definition ([`cli`]),
//! - `docs/reference/config.md` from the configuration schema and its
//!   defaults ([`config`]),
//! - the results block of `README.md` from `reports/paper/results.json`
//!   ([`results`]), between two marker lines; the rest of the README is
//!   written by hand.
//!
//! `crossroads docs` writes them; `crossroads docs --check` exits 1 naming
//! each one that differs (a test runs the same comparison).

mod cli;
mod config;
mod results;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;

use crate::cli::DocsArgs;

/// The report the README's results are generated from, relative to the
/// repository root.
pub const RESULTS: &str = "reports/paper/results.json";

/// One generated document: its path relative to the repository root and
/// the text it must hold.
#[derive(Debug, Clone, PartialEq)]
pub struct Generated {
    pub path: PathBuf,
    pub text: String,
}

/// Every generated document of the repository at `root`, as the code and
/// the committed report make it now.
pub fn generate(root: &Path) -> anyhow::Result<Vec<Generated>> {
    let readme = root.join("README.md");
    let old = std::fs::read_to_string(&readme)
        .with_context(|| format!("reading {}", readme.display()))?;
    let report = root.join(RESULTS);
    let json = std::fs::read_to_string(&report)
        .with_context(|| format!("reading {}", report.display()))?;
    let block = results::readme_block(&json)
        .with_context(|| format!("reading the results of {}", report.display()))?;
    Ok(vec![
        Generated {
            path: PathBuf::from("docs/reference/cli.md"),
            text: cli::reference(),
        },
        Generated {
            path: PathBuf::from("docs/reference/config.md"),
            text: config::reference()?,
        },
        Generated {
            path: PathBuf::from("README.md"),
            text: results::splice(&old, &block).context("README.md")?,
        },
    ])
}

/// The generated documents of `root` whose file differs from what the code
/// and the report make now (a missing file differs).
pub fn stale(root: &Path) -> anyhow::Result<Vec<Generated>> {
    Ok(generate(root)?
        .into_iter()
        .filter(|g| std::fs::read_to_string(root.join(&g.path)).ok().as_ref() != Some(&g.text))
        .collect())
}

/// Runs `crossroads docs`.
pub fn run(args: &DocsArgs) -> anyhow::Result<ExitCode> {
    let stale = stale(&args.root)?;
    if args.check {
        if stale.is_empty() {
            eprintln!("every generated document is up to date");
            return Ok(ExitCode::SUCCESS);
        }
        for g in &stale {
            eprintln!(
                "{} differs from what the code and {RESULTS} generate",
                g.path.display()
            );
        }
        eprintln!("run `crossroads docs` (or `make docs`) and commit the result");
        return Ok(ExitCode::from(1));
    }
    for g in &stale {
        let path = args.root.join(&g.path);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        crossroads_harness::train::write_atomic(&path, g.text.as_bytes())?;
        eprintln!("wrote {}", path.display());
    }
    if stale.is_empty() {
        eprintln!("every generated document is up to date");
    }
    Ok(ExitCode::SUCCESS)
}

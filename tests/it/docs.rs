//! The documents: what is generated from the code and the report matches
//! them, the front page and the code map keep their size, links stay
//! inside the repository and resolve, and the tracked tree keeps its
//! budget.

use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn generated_documents_match_the_code_and_the_report() {
    let stale = crossroads::commands::docs::stale(root()).expect("generate the documents");
    let names: Vec<String> = stale.iter().map(|g| g.path.display().to_string()).collect();
    assert!(
        names.is_empty(),
        "{} differ from what the code and reports/paper/results.json generate; \
         run `crossroads docs` (make docs) and commit the result",
        names.join(", ")
    );
}

#[test]
fn the_cli_reference_names_every_subcommand() {
    use clap::CommandFactory;
    let page = std::fs::read_to_string(root().join("docs/reference/cli.md")).expect("cli.md");
    for sub in crossroads::cli::Cli::command().get_subcommands() {
        let heading = format!("## `crossroads {}`", sub.get_name());
        assert!(page.contains(&heading), "cli.md has no {heading}");
    }
}

#[test]
fn the_config_reference_names_every_key_with_its_default() {
    let page = std::fs::read_to_string(root().join("docs/reference/config.md")).expect("config.md");
    let defaults: toml::Table =
        toml::Table::try_from(crossroads_config::Config::default()).expect("defaults");
    fn walk(page: &str, prefix: &str, table: &toml::Table) {
        for (key, value) in table {
            match value {
                toml::Value::Table(t) => {
                    let section = format!("{prefix}{key}");
                    assert!(
                        page.contains(&format!("## `[{section}]`")),
                        "config.md has no section [{section}]"
                    );
                    walk(page, &format!("{section}."), t);
                }
                other => {
                    let row = format!("| `{key}` |");
                    assert!(
                        page.contains(&row),
                        "config.md has no row for {prefix}{key}"
                    );
                    let shown = match other {
                        toml::Value::String(s) => format!("`{s:?}`"),
                        v => format!("`{v}`"),
                    };
                    assert!(
                        page.lines()
                            .filter(|l| l.starts_with(&row))
                            .any(|l| l.contains(&shown)),
                        "config.md does not give {prefix}{key} its default {shown}"
                    );
                }
            }
        }
    }
    walk(&page, "", &defaults);
}

#[test]
fn the_front_page_and_the_code_map_keep_their_size() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    let lines = readme.lines().count();
    assert!(
        lines <= 300,
        "README.md has {lines} lines; at most 300 (the guide is docs/)"
    );
    let arch = std::fs::read_to_string(root().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let words = arch.split_whitespace().count();
    assert!(
        words <= 2500,
        "ARCHITECTURE.md has {words} words; at most 2,500 (per-file detail goes into //! docs)"
    );
}

/// Every Markdown file a reader starts from: the front page, the code map
/// and the guide.
fn documents() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    let mut dirs = vec![root().join("docs")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).expect("docs/") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "md") {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// The targets of the Markdown links `[text](target)` of `text`.
fn links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(end) = rest.find(')') {
            out.push(rest[..end].to_owned());
        }
    }
    out
}

#[test]
fn every_link_of_the_documents_resolves_inside_the_repository() {
    let top = root().canonicalize().expect("root");
    for file in documents() {
        let text = std::fs::read_to_string(&file).expect("read");
        let dir = file.parent().expect("parent");
        for link in links(&text) {
            if link.starts_with("http://") || link.starts_with("https://") || link.starts_with('#')
            {
                continue;
            }
            let path = link.split('#').next().unwrap_or_default();
            let target = dir.join(path);
            let resolved = target
                .canonicalize()
                .unwrap_or_else(|_| panic!("{}: link {link} names no file", file.display()));
            assert!(
                resolved.starts_with(&top),
                "{}: link {link} leaves the repository",
                file.display()
            );
        }
        assert!(
            !text.contains("../shared"),
            "{} points to ../shared, which a user of this repository does not have",
            file.display()
        );
    }
}

/// The tracked tree stays small enough to clone: weights are committed
/// only behind a figure a document quotes (reports/README.md).
#[test]
fn the_tracked_tree_keeps_its_budget() {
    const BUDGET: u64 = 60_000_000;
    let out = std::process::Command::new("git")
        .current_dir(root())
        .args(["ls-files", "-z"])
        .output();
    let Some(out) = out.ok().filter(|o| o.status.success()) else {
        eprintln!("skipped: not a git checkout");
        return;
    };
    let total: u64 = out
        .stdout
        .split(|b| *b == 0)
        .filter(|p| !p.is_empty())
        .filter_map(|p| std::fs::metadata(root().join(String::from_utf8_lossy(p).as_ref())).ok())
        .map(|m| m.len())
        .sum();
    assert!(
        total < BUDGET,
        "git ls-files totals {:.1} MB; the budget is {:.0} MB (reports/README.md)",
        total as f64 / 1e6,
        BUDGET as f64 / 1e6
    );
}

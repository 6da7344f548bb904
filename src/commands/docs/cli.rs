//! `docs/reference/cli.md`: every subcommand, its usage and its options,
//! walked from the clap definition.

use std::fmt::Write as _;

use clap::Arg;

/// The CLI reference as Markdown.
pub fn reference() -> String {
    let mut root = crate::cli::command();
    root.build();
    let mut w = String::new();
    w.push_str(
        "# Command-line reference\n\n\
         Generated from the code by `crossroads docs`; do not edit (a test fails when \
         this page differs from what the code generates). `crossroads <command> --help` \
         prints the same text.\n\n",
    );
    w.push_str(&paragraphs(
        &root
            .get_long_about()
            .or(root.get_about())
            .map(ToString::to_string)
            .unwrap_or_default(),
    ));
    w.push_str("\n\n");
    let _ = writeln!(w, "```text\n{}\n```\n", usage(&mut root));
    w.push_str("Options every command takes:\n\n");
    for arg in root.get_arguments().filter(|a| shown(a)) {
        option(&mut w, arg);
    }
    w.push_str("\nCommands:\n\n");
    for sub in root.get_subcommands().filter(|s| s.get_name() != "help") {
        let _ = writeln!(
            w,
            "- [`crossroads {}`](#crossroads-{}): {}",
            sub.get_name(),
            sub.get_name(),
            first_line(sub)
        );
    }
    let subs: Vec<clap::Command> = root.get_subcommands().cloned().collect();
    for mut sub in subs {
        command(&mut w, &mut sub, 2);
    }
    w
}

fn command(w: &mut String, cmd: &mut clap::Command, depth: usize) {
    if cmd.get_name() == "help" || cmd.is_hide_set() {
        return;
    }
    let name = cmd.get_bin_name().unwrap_or(cmd.get_name()).to_owned();
    let _ = writeln!(w, "\n{} `{name}`\n", "#".repeat(depth));
    let about = cmd
        .get_long_about()
        .or(cmd.get_about())
        .map(ToString::to_string)
        .unwrap_or_default();
    if !about.is_empty() {
        let _ = writeln!(w, "{}\n", paragraphs(&about));
    }
    let _ = writeln!(w, "```text\n{}\n```\n", usage(cmd));
    let args: Vec<&Arg> = cmd
        .get_arguments()
        .filter(|a| shown(a) && !a.is_global_set())
        .collect();
    for arg in &args {
        option(w, arg);
    }
    let subs: Vec<clap::Command> = cmd.get_subcommands().cloned().collect();
    for mut sub in subs {
        command(w, &mut sub, depth + 1);
    }
}

/// The usage line without clap's "Usage: " prefix.
fn usage(cmd: &mut clap::Command) -> String {
    let text = cmd.render_usage().to_string();
    text.strip_prefix("Usage: ")
        .unwrap_or(&text)
        .trim()
        .to_owned()
}

fn shown(arg: &Arg) -> bool {
    !arg.is_hide_set() && !matches!(arg.get_id().as_str(), "help" | "version")
}

/// One option as a list item: its flag, value, help, default, possible
/// values and environment variable.
fn option(w: &mut String, arg: &Arg) {
    let values = arg
        .get_value_names()
        .map(|names| {
            names
                .iter()
                .map(|n| format!("<{n}>"))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_else(|| format!("<{}>", arg.get_id().as_str().to_uppercase()));
    let takes_value = arg.get_action().takes_values();
    let flag = if arg.is_positional() {
        values
    } else {
        let mut f = String::new();
        if let Some(s) = arg.get_short() {
            let _ = write!(f, "-{s}, ");
        }
        if let Some(l) = arg.get_long() {
            let _ = write!(f, "--{l}");
        }
        if takes_value {
            let _ = write!(f, " {values}");
        }
        f
    };
    let help = arg
        .get_long_help()
        .or(arg.get_help())
        .map(ToString::to_string)
        .unwrap_or_default();
    let mut text = sentence(&paragraphs(&help)).replace("\n\n", "\n\n  ");
    let defaults: Vec<String> = arg
        .get_default_values()
        .iter()
        .map(|v| v.to_string_lossy().into_owned())
        .collect();
    if takes_value && !defaults.is_empty() {
        let _ = write!(text, " Default: `{}`.", defaults.join(","));
    }
    let possible: Vec<String> = arg
        .get_possible_values()
        .iter()
        .filter(|p| !p.is_hide_set())
        .map(|p| match p.get_help() {
            Some(h) => format!(
                "`{}` ({})",
                p.get_name(),
                h.to_string().trim_end_matches('.')
            ),
            None => format!("`{}`", p.get_name()),
        })
        .collect();
    if takes_value && !possible.is_empty() {
        let _ = write!(text, " One of: {}.", possible.join(", "));
    }
    if let Some(env) = arg.get_env() {
        let _ = write!(text, " Environment: `{}`.", env.to_string_lossy());
    }
    if arg.is_required_set() {
        text.push_str(" Required.");
    }
    let _ = writeln!(w, "- `{flag}`: {}", text.trim());
}

/// Help text as Markdown paragraphs: clap's hard-wrapped lines joined,
/// blank lines kept, each ending in a full stop (clap drops the doc
/// comment's last one).
fn paragraphs(text: &str) -> String {
    text.split("\n\n")
        .map(|p| p.split_whitespace().collect::<Vec<_>>().join(" "))
        .filter(|p| !p.is_empty())
        .map(|p| sentence(&p))
        .collect::<Vec<_>>()
        .join("\n\n")
}

/// `text` ending in a full stop (or its own closing punctuation).
fn sentence(text: &str) -> String {
    if text.is_empty() || text.ends_with(['.', '!', '?', ':']) || text.ends_with(".)") {
        text.to_owned()
    } else {
        format!("{text}.")
    }
}

fn first_line(cmd: &clap::Command) -> String {
    cmd.get_about()
        .map(|a| paragraphs(&a.to_string()))
        .unwrap_or_default()
}

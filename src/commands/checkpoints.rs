//! `crossroads checkpoints`: the client of the learner's checkpoint API.

use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use crossroads_config::Config;
use crossroads_transport::auth::Token;
use crossroads_transport::convert::CheckpointSummary;
use crossroads_transport::{ClientSecurity, LearnerClient};

use crate::cli::{CheckpointsAction, CheckpointsArgs};

/// Runs one checkpoint command against the learner, with the TLS
/// settings and token of `config.transport` (`--token` overrides the
/// token).
pub fn run(config: &Config, args: &CheckpointsArgs) -> anyhow::Result<ExitCode> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let mut security = ClientSecurity::load(&config.transport)?;
    if let Some(token) = &args.token {
        security = security.with_token(Some(Token::new(token, "--token")?));
    }
    runtime.block_on(act(args, &security))?;
    Ok(ExitCode::SUCCESS)
}

fn json(c: &CheckpointSummary) -> serde_json::Value {
    serde_json::json!({
        "id": c.id,
        "update_step": c.update_step,
        "weights_version": c.weights_version,
        "created_unix_ms": c.created_unix_ms,
        "size_bytes": c.size_bytes,
        "scenario": c.scenario,
        "eval_metrics": c.eval_metrics,
        "best": c.best,
        "files": c.files,
    })
}

fn line(c: &CheckpointSummary) -> String {
    let eval: Vec<String> = c
        .eval_metrics
        .iter()
        .map(|(k, v)| format!("{k}={v:.4}"))
        .collect();
    format!(
        "{:<22} {:>12} {:>9} {:>10.1} {:<10} {:<4} {}",
        c.id,
        c.update_step,
        c.weights_version,
        c.size_bytes as f64 / (1 << 20) as f64,
        c.scenario,
        if c.best { "best" } else { "" },
        eval.join(" ")
    )
}

const HEADER: &str =
    "id                       update_step   version   size MiB scenario        evaluation";

async fn act(args: &CheckpointsArgs, security: &ClientSecurity) -> anyhow::Result<()> {
    let client = LearnerClient::new(
        &args.learner,
        security,
        Duration::from_secs(args.timeout.max(1)),
    )?;
    let at = &args.learner;
    match &args.action {
        CheckpointsAction::List => {
            let list = client
                .list()
                .await
                .with_context(|| format!("listing checkpoints of {at}"))?;
            if args.json {
                let v: Vec<_> = list.iter().map(json).collect();
                println!("{}", serde_json::Value::Array(v));
            } else if list.is_empty() {
                println!("no checkpoints");
            } else {
                println!("{HEADER}");
                for c in &list {
                    println!("{}", line(c));
                }
            }
        }
        CheckpointsAction::Pull { id, out } => {
            let (info, folder) = client
                .pull(id, out)
                .await
                .with_context(|| format!("pulling checkpoint {id:?} from {at}"))?;
            if args.json {
                let mut v = json(&info);
                v["path"] = serde_json::json!(folder);
                println!("{v}");
            } else {
                println!(
                    "pulled {} ({} files, {} bytes) into {}",
                    info.id,
                    info.files.len(),
                    info.size_bytes,
                    folder.display()
                );
            }
        }
        CheckpointsAction::Save => {
            let info = client
                .save()
                .await
                .with_context(|| format!("saving a checkpoint on {at}"))?;
            if args.json {
                println!("{}", json(&info));
            } else {
                println!("saved {} at update {}", info.id, info.update_step);
            }
        }
        CheckpointsAction::Restore { id } => {
            let (info, version) = client
                .restore(id)
                .await
                .with_context(|| format!("restoring checkpoint {id:?} on {at}"))?;
            if args.json {
                let mut v = json(&info);
                v["published_version"] = serde_json::json!(version);
                println!("{v}");
            } else {
                println!(
                    "restored {} (update {}); its weights are published as version {version}",
                    info.id, info.update_step
                );
            }
        }
        CheckpointsAction::Delete { id } => {
            client
                .delete(id)
                .await
                .with_context(|| format!("deleting checkpoint {id:?} on {at}"))?;
            if args.json {
                println!("{}", serde_json::json!({ "deleted": id }));
            } else {
                println!("deleted {id}");
            }
        }
    }
    Ok(())
}

//! The evaluations of a session: the learner's latest weights (or the
//! newest checkpoint once it stopped) run greedily on the run's seeded
//! trials in this process (behind `actor.shield` when the actors act
//! through it), appended to the curve, kept in `last/`,
//! reported to the learner; a new best or a met target re-measured on
//! `train.confirm_trials` and kept in `best/`; the weights that first
//! confirm the target are also kept in `reached/`, which a later best does
//! not replace.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use crossroads_sim::{EvalConfig, Policy, ShieldParams, ShieldedPolicy, evaluate};
use indicatif::ProgressBar;

use super::record::{Evaluation, Reached, write_atomic};
use super::session::Session;
use crate::network_policy::NetworkPolicy;

/// How long a failed fetch of the latest weights waits for the learner's
/// exit (its last checkpoint and its gRPC drain, at most 10 s).
const EXIT_WAIT: Duration = Duration::from_secs(15);

impl Session {
    /// Fetches the latest weights and evaluates them greedily on
    /// `trials` trials of the run's scenario; records (curve, `last/`) and
    /// reports the result. Weights that score above the best so far, or
    /// meet a target not yet reached, are re-measured on `confirm_trials`
    /// ([`Self::consider_best`]). Returns the evaluation, whether the
    /// target was reached by it, and how long the periodic evaluation took
    /// (fetching and `trials` trials, without a re-measure).
    pub async fn evaluate_latest(
        &mut self,
        trials: u64,
        bar: &ProgressBar,
    ) -> anyhow::Result<(Evaluation, bool, Duration)> {
        let began = Instant::now();
        let (version, safetensors) = match self.latest_from_learner().await? {
            Some(latest) => latest,
            None => self.newest_checkpoint()?,
        };
        let e = self.evaluate_bytes(&safetensors, version, trials).await?;
        let took = began.elapsed();
        self.record(&e, &safetensors)?;
        self.report(&e).await;
        let c = &self.run.config.train;
        let better = self
            .summary
            .best
            .as_ref()
            .is_none_or(|b| e.score() > b.score());
        let may_reach = self.summary.reached.is_none()
            && c.met(e.success_rate, e.collision_rate, e.mean_time_s);
        let reached = if better || may_reach {
            self.consider_best(&safetensors, &e, bar).await?
        } else {
            false
        };
        Ok((e, reached, took))
    }

    /// Tells the learner how `e`'s weights did, so its best checkpoint
    /// follows the same rule (`learner.best_metric`, `mean_return` by
    /// default).
    async fn report(&mut self, e: &Evaluation) {
        if self.learner.exited().is_some() {
            return;
        }
        let mut report = BTreeMap::new();
        report.insert("success_rate".to_owned(), e.success_rate);
        report.insert("collision_rate".to_owned(), e.collision_rate);
        report.insert("timeout_rate".to_owned(), e.timeout_rate);
        if let Some(r) = e.mean_return {
            report.insert("mean_return".to_owned(), r);
        }
        if let Some(t) = e.mean_time_s {
            report.insert("mean_time_s".to_owned(), t);
        }
        if let Err(err) = self
            .learner_client
            .report_evaluation(e.weights_version, report)
            .await
        {
            tracing::warn!(error = %err, "reporting the evaluation to the learner");
        }
    }

    /// The learner's latest weights and their version, or `None` once it
    /// has exited: its last checkpoint holds them. A learner that reached
    /// its budget stops answering while it writes that checkpoint, so a
    /// failed fetch waits ([`EXIT_WAIT`] at most) for the exit before it
    /// counts as an error (seen in CI: a resumed run with few updates left
    /// lost its final evaluation to that race).
    async fn latest_from_learner(&mut self) -> anyhow::Result<Option<(u64, Vec<u8>)>> {
        if self.learner.exited().is_some() {
            return Ok(None);
        }
        match self.learner_client.latest_weights().await {
            Ok(w) => Ok(Some((w.version, w.safetensors))),
            Err(e) => {
                let deadline = Instant::now() + EXIT_WAIT;
                while Instant::now() < deadline {
                    if self.learner.exited().is_some() {
                        return Ok(None);
                    }
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                Err(anyhow::Error::from(e).context("fetching the latest weights"))
            }
        }
    }

    /// The weights of the newest checkpoint on disk and their version (for
    /// the last evaluation when the learner has already stopped).
    fn newest_checkpoint(&self) -> anyhow::Result<(u64, Vec<u8>)> {
        let dir = self.run.out.join("checkpoints");
        let newest = std::fs::read_dir(&dir)
            .with_context(|| format!("reading {}", dir.display()))?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("ckpt-"))
            })
            .max()
            .with_context(|| format!("no checkpoint in {}", dir.display()))?;
        let file = newest.join("weights.safetensors");
        let bytes = std::fs::read(&file).with_context(|| format!("reading {}", file.display()))?;
        let (_, version) = crossroads_model::QNetwork::from_safetensors(&bytes)
            .with_context(|| format!("{} holds no network", file.display()))?;
        Ok((version, bytes))
    }

    async fn evaluate_bytes(
        &self,
        safetensors: &[u8],
        version: u64,
        trials: u64,
    ) -> anyhow::Result<Evaluation> {
        let network = NetworkPolicy::from_safetensors(safetensors, format!("dqn@v{version}"))
            .context("the learner's weights")?;
        // Behind the shield the actors act through (`actor.shield`).
        let policy: Box<dyn Policy> = match self.run.config.actor.shield.as_deref() {
            Some(spec) => Box::new(ShieldedPolicy::new(
                Box::new(network),
                ShieldParams::parse(spec).context("actor.shield")?,
            )),
            None => Box::new(network),
        };
        let scenario = Arc::clone(&self.run.scenario);
        let eval = EvalConfig::new(self.run.actions, trials, self.run.config.train.eval_seed);
        let report = tokio::task::spawn_blocking(move || {
            evaluate(&scenario, policy.as_ref(), &eval, &|_| {}).map_err(anyhow::Error::from)
        })
        .await
        .context("the evaluation thread")??;
        Ok(Evaluation {
            wall_seconds: self.wall(),
            updates: self.updates,
            env_steps: self.env_steps,
            transitions: self.transitions,
            weights_version: version,
            trials,
            success_rate: report.success_rate,
            collision_rate: report.collision_rate,
            timeout_rate: report.timeout_rate,
            mean_time_s: report.mean_time_s,
            mean_brake_s: report.mean_brake_s,
            loss: self.loss,
            mean_return: Some(report.mean_return),
        })
    }

    /// Appends to the curve, updates the summary and metrics, and keeps the
    /// weights in `last/`.
    fn record(&mut self, e: &Evaluation, safetensors: &[u8]) -> anyhow::Result<()> {
        self.curve.append(e)?;
        self.metrics.evaluated(e);
        keep(&self.run.out.join("last"), e, safetensors)?;
        self.summary.last = Some(e.clone());
        self.update_summary();
        self.summary.save(&self.run.out)
    }

    pub fn update_summary(&mut self) {
        self.summary.wall_seconds = self.wall();
        self.summary.updates = self.updates;
        self.summary.env_steps = self.env_steps;
        self.summary.transitions = self.transitions;
    }

    /// Re-measures the weights of periodic evaluation `e` on
    /// `confirm_trials` trials (10,000 by default: the periodic ones are
    /// small, and a best picked on them alone would be picked on noise);
    /// keeps them in `best/` when the re-measured score is the best so far,
    /// and records the target as reached when it meets it for the first
    /// time (the weights in `reached/`). Returns whether it did.
    async fn consider_best(
        &mut self,
        safetensors: &[u8],
        e: &Evaluation,
        bar: &ProgressBar,
    ) -> anyhow::Result<bool> {
        let c = self.run.config.train.clone();
        let confirmed = if c.confirm_trials > e.trials {
            let mut m = self
                .evaluate_bytes(safetensors, e.weights_version, c.confirm_trials)
                .await?;
            m.updates = e.updates;
            self.report(&m).await;
            m
        } else {
            e.clone()
        };
        let best = self
            .summary
            .best
            .as_ref()
            .is_none_or(|b| confirmed.score() > b.score());
        if best {
            keep(&self.run.out.join("best"), &confirmed, safetensors)?;
            self.summary.best = Some(confirmed.clone());
        }
        let reached = self.summary.reached.is_none()
            && c.met(
                confirmed.success_rate,
                confirmed.collision_rate,
                confirmed.mean_time_s,
            );
        bar.suspend(|| {
            tracing::info!(
                trials = confirmed.trials,
                mean_return = confirmed.mean_return,
                "re-measured: {}{}{}",
                confirmed.brief(),
                if best { " -> best" } else { "" },
                if reached { " -> target reached" } else { "" }
            );
        });
        if reached {
            keep(&self.run.out.join("reached"), &confirmed, safetensors)?;
            self.metrics.reached();
            self.summary.reached = Some(Reached {
                evaluation: confirmed,
            });
        }
        self.summary.save(&self.run.out)?;
        Ok(reached)
    }
}

/// Writes `safetensors` and `e` (as `evaluation.json`) into `dir`.
fn keep(dir: &Path, e: &Evaluation, safetensors: &[u8]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    write_atomic(&dir.join("weights.safetensors"), safetensors)?;
    write_atomic(
        &dir.join("evaluation.json"),
        serde_json::to_string_pretty(e)?.as_bytes(),
    )
}

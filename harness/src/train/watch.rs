//! The watch loop of a session: once a second it reads the learner's
//! status, the replay's info and the actors' metrics into the progress bar
//! and `crossroads_train_*` metrics, evaluates on schedule (at most
//! `train.eval_share` of the wall time), and says when and why the run
//! ends.

use std::time::{Duration, Instant};

use crossroads_common::Shutdown;
use indicatif::{ProgressBar, ProgressStyle};

use super::session::{End, Session};

impl Session {
    /// Watches until the run ends; evaluates on schedule.
    pub async fn watch(&mut self, shutdown: &Shutdown) -> anyhow::Result<End> {
        let c = self.run.config.clone();
        let budget = c.learner.max_updates;
        let bar = progress_bar(budget);
        // The first evaluation is of the weights the run starts from.
        let mut next_eval = 0;
        // Periodic evaluations take at most `eval_share` of the wall time:
        // the next one starts no earlier than this.
        let mut eval_gate = Instant::now();
        let mut rate = (Instant::now(), self.run.previous.env_steps);
        let mut steps_per_s = 0.0;
        let mut last_eval = "no evaluation yet".to_owned();
        let mut tick = tokio::time::interval(Duration::from_secs(1));
        // After a long evaluation, one tick, not a burst of missed ones.
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let end = loop {
            // Biased: a signal that came during an evaluation wins over the
            // tick that is due by then (unbiased, select! picked either, so
            // Ctrl-C could wait several evaluations of a minute each).
            tokio::select! {
                biased;
                () = shutdown.wait() => break End::Signal,
                _ = tick.tick() => {}
            }
            if self.check_roles()? {
                break End::Budget;
            }
            if let Ok(st) = self.learner_client.status().await {
                self.updates = st.update_step;
                self.loss = st.loss;
            }
            if let Ok(info) = self.replay_client.info().await {
                self.transitions = info.inserts_total;
            }
            let steps = self.run.previous.env_steps + self.actor_steps().await;
            if steps >= self.env_steps {
                self.env_steps = steps;
            }
            let dt = rate.0.elapsed().as_secs_f64();
            if dt >= 5.0 {
                steps_per_s = (self.env_steps.saturating_sub(rate.1)) as f64 / dt;
                rate = (Instant::now(), self.env_steps);
            }
            self.metrics
                .progress(self.updates, self.env_steps, steps_per_s);
            bar.set_position(self.updates);
            // Once the target is confirmed (on `confirm_trials` trials),
            // the bar says so first, with when.
            let target = self.summary.reached.as_ref().map_or(String::new(), |r| {
                format!(
                    "target confirmed at {:.1} min | ",
                    r.evaluation.wall_seconds / 60.0
                )
            });
            bar.set_message(format!(
                "{target}{steps_per_s:.0} env steps/s | {last_eval}"
            ));
            if self.updates >= next_eval && Instant::now() >= eval_gate {
                next_eval = self.updates + c.train.eval_every;
                let began = Instant::now();
                let evaluated = self.evaluate_latest(c.train.eval_trials, &bar).await;
                match evaluated {
                    Ok((e, reached, took)) => {
                        // Gated on the periodic evaluation's own time: a
                        // 10,000-trial re-measure of a new best is rare and
                        // must not push the next evaluation minutes away.
                        eval_gate = began + took.div_f64(c.train.eval_share);
                        last_eval = e.brief();
                        bar.suspend(|| {
                            tracing::info!(
                                updates = e.updates,
                                minutes = format!("{:.1}", e.wall_seconds / 60.0),
                                env_steps = e.env_steps,
                                "evaluation: {}",
                                e.brief()
                            );
                        });
                        if reached && c.train.stop_at_target {
                            break End::Target;
                        }
                    }
                    Err(e) => {
                        eval_gate = began + began.elapsed().div_f64(c.train.eval_share);
                        tracing::warn!(error = %format!("{e:#}"), "evaluation failed");
                    }
                }
            }
            if budget > 0 && self.updates >= budget {
                break End::Budget;
            }
            if c.train.max_minutes > 0.0
                && self.started.elapsed().as_secs_f64() >= 60.0 * c.train.max_minutes
            {
                break End::Minutes;
            }
        };
        bar.finish_and_clear();
        Ok(end)
    }
}

fn progress_bar(budget: u64) -> ProgressBar {
    let bar = if budget > 0 {
        ProgressBar::new(budget)
    } else {
        ProgressBar::new_spinner()
    };
    let template = if budget > 0 {
        "{spinner} [{elapsed_precise}] {wide_bar} {human_pos}/{human_len} updates ({per_sec}, ETA {eta}) {msg}"
    } else {
        "{spinner} [{elapsed_precise}] {human_pos} updates ({per_sec}) {msg}"
    };
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style);
    }
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

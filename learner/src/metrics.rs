//! `crossroads_learner_*`: what the learner exports to Prometheus.

use prometheus::{
    Gauge, Histogram, HistogramOpts, IntCounter, IntCounterVec, IntGauge, Opts, Registry,
};

/// The learner's metrics. Cheap to clone (handles to shared values).
#[derive(Debug, Clone)]
pub struct LearnerMetrics {
    /// Optimizer updates applied.
    pub updates: IntCounter,
    /// Loss of the latest update.
    pub loss: Gauge,
    /// Mean Q(s, a) over the latest batch's taken actions.
    pub q_mean: Gauge,
    /// Largest Q(s, a) in the latest batch.
    pub q_max: Gauge,
    /// Mean |TD error| of the latest batch.
    pub td_error: Gauge,
    /// Global gradient norm of the latest update, before clipping.
    pub grad_norm: Gauge,
    /// Time the training loop waited for a sampled batch.
    pub sample_wait: Histogram,
    /// Seconds waited for samples in total.
    pub sample_wait_total: prometheus::Counter,
    /// Seconds spent in updates in total.
    pub update_seconds_total: prometheus::Counter,
    /// Latest published weights version.
    pub weights_version: IntGauge,
    /// Weight publications.
    pub weights_published: IntCounter,
    /// Open gRPC weight subscriptions.
    pub weight_subscribers: IntGauge,
    /// Checkpoints written.
    pub checkpoints: IntCounter,
    /// Unix time of the latest checkpoint written or restored, seconds.
    pub checkpoint_time: Gauge,
    /// Seconds since the latest checkpoint (updated each second).
    pub checkpoint_age: Gauge,
    /// Sample and priority-update calls that failed, by operation.
    pub replay_errors: IntCounterVec,
    /// Priority updates dropped because the sender fell behind.
    pub priority_updates_dropped: IntCounter,
}

impl LearnerMetrics {
    /// Creates the metrics and registers them in `registry` when given.
    pub fn new(registry: Option<&Registry>) -> Result<Self, prometheus::Error> {
        let m = Self {
            updates: IntCounter::new(
                "crossroads_learner_updates_total",
                "Optimizer updates applied",
            )?,
            loss: Gauge::new("crossroads_learner_loss", "Loss of the latest update")?,
            q_mean: Gauge::new(
                "crossroads_learner_q_mean",
                "Mean Q(s, a) of the taken actions in the latest batch",
            )?,
            q_max: Gauge::new(
                "crossroads_learner_q_max",
                "Largest Q(s, a) of the taken actions in the latest batch",
            )?,
            td_error: Gauge::new(
                "crossroads_learner_td_error_abs_mean",
                "Mean absolute TD error of the latest batch",
            )?,
            grad_norm: Gauge::new(
                "crossroads_learner_grad_norm",
                "Global L2 norm of the latest gradient, before clipping",
            )?,
            sample_wait: Histogram::with_opts(
                HistogramOpts::new(
                    "crossroads_learner_sample_wait_seconds",
                    "Time the training loop waited for a sampled batch",
                )
                .buckets(vec![
                    1e-5, 1e-4, 5e-4, 1e-3, 5e-3, 0.01, 0.05, 0.1, 0.5, 1.0, 5.0,
                ]),
            )?,
            sample_wait_total: prometheus::Counter::new(
                "crossroads_learner_sample_wait_seconds_total",
                "Seconds the training loop waited for samples",
            )?,
            update_seconds_total: prometheus::Counter::new(
                "crossroads_learner_update_seconds_total",
                "Seconds the training loop spent in updates",
            )?,
            weights_version: IntGauge::new(
                "crossroads_learner_weights_version",
                "Latest published weights version",
            )?,
            weights_published: IntCounter::new(
                "crossroads_learner_weights_published_total",
                "Weight publications",
            )?,
            weight_subscribers: IntGauge::new(
                "crossroads_learner_weight_subscribers",
                "Open gRPC weight subscriptions",
            )?,
            checkpoints: IntCounter::new(
                "crossroads_learner_checkpoints_total",
                "Checkpoints written",
            )?,
            checkpoint_time: Gauge::new(
                "crossroads_learner_checkpoint_timestamp_seconds",
                "Unix time of the latest checkpoint written or restored",
            )?,
            checkpoint_age: Gauge::new(
                "crossroads_learner_checkpoint_age_seconds",
                "Seconds since the latest checkpoint was written or restored",
            )?,
            replay_errors: IntCounterVec::new(
                Opts::new(
                    "crossroads_learner_replay_errors_total",
                    "Failed calls to the replay server, by operation",
                ),
                &["op"],
            )?,
            priority_updates_dropped: IntCounter::new(
                "crossroads_learner_priority_updates_dropped_total",
                "Priority updates dropped because the sender fell behind",
            )?,
        };
        if let Some(r) = registry {
            r.register(Box::new(m.updates.clone()))?;
            r.register(Box::new(m.loss.clone()))?;
            r.register(Box::new(m.q_mean.clone()))?;
            r.register(Box::new(m.q_max.clone()))?;
            r.register(Box::new(m.td_error.clone()))?;
            r.register(Box::new(m.grad_norm.clone()))?;
            r.register(Box::new(m.sample_wait.clone()))?;
            r.register(Box::new(m.sample_wait_total.clone()))?;
            r.register(Box::new(m.update_seconds_total.clone()))?;
            r.register(Box::new(m.weights_version.clone()))?;
            r.register(Box::new(m.weights_published.clone()))?;
            r.register(Box::new(m.weight_subscribers.clone()))?;
            r.register(Box::new(m.checkpoints.clone()))?;
            r.register(Box::new(m.checkpoint_time.clone()))?;
            r.register(Box::new(m.checkpoint_age.clone()))?;
            r.register(Box::new(m.replay_errors.clone()))?;
            r.register(Box::new(m.priority_updates_dropped.clone()))?;
        }
        Ok(m)
    }

    /// Metrics registered nowhere (tests, benchmarks).
    pub fn unregistered() -> Self {
        // Creating metrics with valid constant names cannot fail.
        #[allow(clippy::expect_used)]
        Self::new(None).expect("metric definitions are valid")
    }

    /// Refreshes the checkpoint age from the latest checkpoint time.
    pub fn refresh_checkpoint_age(&self, now_unix_s: f64) {
        let t = self.checkpoint_time.get();
        if t > 0.0 {
            self.checkpoint_age.set((now_unix_s - t).max(0.0));
        }
    }
}

//! The rate limiter: when a table lets inserts and samples proceed.
//!
//! Two rules, after Reverb's `SampleToInsertRatio`:
//! - no sample before `min_size_to_sample` items were inserted;
//! - with a samples-per-insert ratio `r` > 0, the gap
//!   `d = inserts * r - samples` stays within `min_size * r ± tolerance`:
//!   a sample proceeds while `d - 1 >= lower`, an insert while
//!   `d + r <= upper`. A batch is admitted whole once its first item may
//!   go, so `d` can overshoot by one batch; requiring
//!   `tolerance >= max(1, r)` guarantees that when one side must wait the
//!   other can go, so the two never wait on each other forever.
//!
//! The limiter only answers questions and counts; waiting (with timeouts)
//! is the table's, done without holding any lock.

/// The limiter's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimiterConfig {
    /// Inserts before the first sample.
    pub min_size_to_sample: u64,
    /// Target samples per insert; 0 turns the ratio off.
    pub samples_per_insert: f64,
    /// Allowed drift of the ratio, in samples.
    pub tolerance: f64,
}

/// Counts of inserts and samples, and the answers derived from them. Cost
/// O(1) per call; not thread-safe (lives under the table's lock).
#[derive(Debug, Clone)]
pub struct RateLimiter {
    config: RateLimiterConfig,
    inserts: u64,
    samples: u64,
    insert_waits: u64,
    sample_waits: u64,
}

impl RateLimiter {
    /// A limiter that has seen nothing.
    pub fn new(config: RateLimiterConfig) -> Self {
        Self {
            config,
            inserts: 0,
            samples: 0,
            insert_waits: 0,
            sample_waits: 0,
        }
    }

    /// Its settings.
    pub fn config(&self) -> RateLimiterConfig {
        self.config
    }

    fn bounds(&self) -> (f64, f64) {
        let c = &self.config;
        let centre = c.min_size_to_sample as f64 * c.samples_per_insert;
        (centre - c.tolerance, centre + c.tolerance)
    }

    fn gap(&self) -> f64 {
        self.inserts as f64 * self.config.samples_per_insert - self.samples as f64
    }

    /// Whether an insert may proceed now.
    pub fn can_insert(&self) -> bool {
        let r = self.config.samples_per_insert;
        if r == 0.0 || self.inserts < self.config.min_size_to_sample {
            return true;
        }
        self.gap() + r <= self.bounds().1
    }

    /// Whether a sample may proceed now.
    pub fn can_sample(&self) -> bool {
        if self.inserts < self.config.min_size_to_sample.max(1) {
            return false;
        }
        self.config.samples_per_insert == 0.0 || self.gap() - 1.0 >= self.bounds().0
    }

    /// Records `n` inserted items.
    pub fn inserted(&mut self, n: u64) {
        self.inserts = self.inserts.saturating_add(n);
    }

    /// Records `n` sampled items.
    pub fn sampled(&mut self, n: u64) {
        self.samples = self.samples.saturating_add(n);
    }

    /// Records that an insert had to wait.
    pub fn insert_waited(&mut self) {
        self.insert_waits = self.insert_waits.saturating_add(1);
    }

    /// Records that a sample had to wait.
    pub fn sample_waited(&mut self) {
        self.sample_waits = self.sample_waits.saturating_add(1);
    }

    /// Items inserted and sampled so far.
    pub fn counts(&self) -> (u64, u64) {
        (self.inserts, self.samples)
    }

    /// Sets the counts (restoring a snapshot).
    pub fn set_counts(&mut self, inserts: u64, samples: u64) {
        self.inserts = inserts;
        self.samples = samples;
    }

    /// Inserts and samples that had to wait.
    pub fn waits(&self) -> (u64, u64) {
        (self.insert_waits, self.sample_waits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limiter(min: u64, r: f64, tol: f64) -> RateLimiter {
        RateLimiter::new(RateLimiterConfig {
            min_size_to_sample: min,
            samples_per_insert: r,
            tolerance: tol,
        })
    }

    #[test]
    fn min_size_gates_sampling_only() {
        let mut l = limiter(3, 0.0, 0.0);
        assert!(!l.can_sample());
        l.inserted(2);
        assert!(!l.can_sample() && l.can_insert());
        l.inserted(1);
        assert!(l.can_sample());
        l.sampled(1_000_000);
        assert!(l.can_sample() && l.can_insert(), "no ratio: never blocks");
    }

    #[test]
    fn ratio_holds_within_tolerance() {
        // Two samples per insert, drift of 4 samples either way, from 10.
        let mut l = limiter(10, 2.0, 4.0);
        l.inserted(10);
        // gap 20, bounds [16, 24].
        assert!(l.can_sample());
        l.sampled(4);
        assert!(!l.can_sample(), "gap 16: one more would go below 16");
        assert!(l.can_insert());
        l.inserted(1); // gap 18
        assert!(l.can_sample());
        l.inserted(3); // gap 24
        assert!(!l.can_insert(), "another insert would reach 26 > 24");
        assert!(l.can_sample());
        l.sampled(2); // gap 22
        assert!(l.can_insert());
    }

    #[test]
    fn one_side_can_always_go() {
        for (r, tol) in [(0.5, 1.0), (1.0, 1.0), (4.0, 4.0), (8.0, 20.0)] {
            let mut l = limiter(5, r, tol);
            l.inserted(5);
            for step in 0..1000u64 {
                assert!(l.can_insert() || l.can_sample(), "r {r} tol {tol}");
                // Batches of 7 samples or 3 inserts: overshoot included.
                if step % 3 == 0 && l.can_sample() {
                    l.sampled(7);
                } else if l.can_insert() {
                    l.inserted(3);
                } else {
                    l.sampled(7);
                }
            }
        }
    }
}

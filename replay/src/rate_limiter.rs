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
//! With a [`RatioRamp`] the ratio moves from an early one to `r` as samples
//! accumulate. The limiter only answers questions and counts; waiting
//! (with timeouts) is the table's, done without holding any lock.

/// The limiter's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateLimiterConfig {
    /// Inserts before the first sample.
    pub min_size_to_sample: u64,
    /// Target samples per insert; 0 turns the ratio off.
    pub samples_per_insert: f64,
    /// Allowed drift of the ratio, in samples.
    pub tolerance: f64,
    /// An early ratio that moves to `samples_per_insert`; none keeps
    /// `samples_per_insert` throughout.
    pub ramp: Option<RatioRamp>,
}

/// Samples per insert `early` up to `from` samples, moving linearly to the
/// limiter's `samples_per_insert` at `to` samples, and that ratio after:
/// fresh experience early, more reuse late.
///
/// With a ramp the limiter keeps the gap in inserts,
/// `g = inserts - I(samples)`, where `I(s)` is the inserts the schedule
/// asks for `s` samples ([`RatioRamp::inserts_for`]; `I(s) = s / r` for a
/// constant ratio), within `min_size ± tolerance / r(samples)`; for a
/// constant ratio that is the module's rule divided by `r`, and the same
/// reasoning keeps one side free to go.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RatioRamp {
    /// Samples per insert at the start (above 0).
    pub early: f64,
    /// Samples taken when the ratio starts to move.
    pub from: u64,
    /// Samples taken when it reaches `samples_per_insert` (at least `from`).
    pub to: u64,
}

impl RatioRamp {
    /// The ratio after `samples` samples, moving to `late`.
    pub fn ratio_at(&self, late: f64, samples: f64) -> f64 {
        let (from, to) = (self.from as f64, self.to as f64);
        if samples <= from {
            self.early
        } else if samples >= to {
            late
        } else {
            self.early + (late - self.early) * (samples - from) / (to - from)
        }
    }

    /// The inserts the schedule asks for `samples` samples: the integral of
    /// 1 / ratio over the samples taken.
    pub fn inserts_for(&self, late: f64, samples: f64) -> f64 {
        let (from, to) = (self.from as f64, self.to as f64);
        let early_part = samples.min(from) / self.early;
        if samples <= from {
            return early_part;
        }
        let s = samples.min(to);
        let slope = if to > from {
            (late - self.early) / (to - from)
        } else {
            0.0
        };
        let ramp_part = if slope.abs() < 1e-12 {
            (s - from) / self.early
        } else {
            (self.ratio_at(late, s) / self.early).ln() / slope
        };
        early_part + ramp_part + (samples - s).max(0.0) / late
    }
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

    /// The samples-per-insert ratio the limiter holds now (the ramp's
    /// current value where there is one).
    pub fn current_ratio(&self) -> f64 {
        let c = &self.config;
        match c.ramp {
            Some(ramp) if c.samples_per_insert > 0.0 => {
                ramp.ratio_at(c.samples_per_insert, self.samples as f64)
            }
            _ => c.samples_per_insert,
        }
    }

    /// With a ramp: the gap in inserts, `inserts - I(samples)`, after
    /// `extra_inserts` more inserts and `extra_samples` more samples, and
    /// its bounds `min_size ± tolerance / r(samples)`.
    fn ramp_gap(&self, ramp: &RatioRamp, extra_inserts: f64, extra_samples: f64) -> (f64, f64) {
        let c = &self.config;
        let r = c.samples_per_insert;
        let gap = self.inserts as f64 + extra_inserts
            - ramp.inserts_for(r, self.samples as f64 + extra_samples);
        (gap, c.tolerance / self.current_ratio())
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
        self.can_insert_after(0)
    }

    /// Whether an insert may proceed once `pending` items, admitted but
    /// not counted yet, are. A table admits a batch before its
    /// write-ahead-log record is durable and counts it once stored; the
    /// batches in between count against the ratio, so concurrent inserts
    /// overshoot it by one batch, as sequential ones do, not by one each.
    pub fn can_insert_after(&self, pending: u64) -> bool {
        let r = self.config.samples_per_insert;
        if r == 0.0 || self.inserts.saturating_add(pending) < self.config.min_size_to_sample {
            return true;
        }
        let pending = pending as f64;
        if let Some(ramp) = &self.config.ramp {
            let (gap, tolerance) = self.ramp_gap(ramp, pending + 1.0, 0.0);
            return gap <= self.config.min_size_to_sample as f64 + tolerance;
        }
        self.gap() + (pending + 1.0) * r <= self.bounds().1
    }

    /// Whether a sample may proceed now.
    pub fn can_sample(&self) -> bool {
        if self.inserts < self.config.min_size_to_sample.max(1) {
            return false;
        }
        if self.config.samples_per_insert == 0.0 {
            return true;
        }
        if let Some(ramp) = &self.config.ramp {
            let (gap, tolerance) = self.ramp_gap(ramp, 0.0, 1.0);
            return gap >= self.config.min_size_to_sample as f64 - tolerance;
        }
        self.gap() - 1.0 >= self.bounds().0
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
            ramp: None,
        })
    }

    fn ramped(min: u64, early: f64, late: f64, from: u64, to: u64, tol: f64) -> RateLimiter {
        RateLimiter::new(RateLimiterConfig {
            min_size_to_sample: min,
            samples_per_insert: late,
            tolerance: tol,
            ramp: Some(RatioRamp { early, from, to }),
        })
    }

    /// Drives `l` greedily (sample whenever allowed, else insert) and
    /// returns (inserts, samples) each time the samples pass a multiple of
    /// `every`.
    fn drive(l: &mut RateLimiter, until_samples: u64, every: u64) -> Vec<(u64, u64)> {
        let mut seen = Vec::new();
        let mut next = every;
        while l.counts().1 < until_samples {
            assert!(
                l.can_insert() || l.can_sample(),
                "deadlock at {:?}",
                l.counts()
            );
            if l.can_sample() {
                l.sampled(1);
            } else {
                l.inserted(1);
            }
            if l.counts().1 >= next {
                seen.push(l.counts());
                next += every;
            }
        }
        seen
    }

    #[test]
    fn a_ramp_holds_the_early_ratio_then_the_late_one() {
        // 0.5 samples per insert for the first 1,000 samples, moving to 4
        // by 3,000: fresh data early, reuse late.
        let mut l = ramped(10, 0.5, 4.0, 1_000, 3_000, 8.0);
        l.inserted(10);
        let seen = drive(&mut l, 10_000, 500);
        let ratio = |a: (u64, u64), b: (u64, u64)| (b.1 - a.1) as f64 / (b.0 - a.0) as f64;
        // Samples 0-1,000 (after the first 500): inserts grow 2 per sample.
        let early = ratio(seen[0], seen[1]);
        assert!((early - 0.5).abs() < 0.01, "early ratio {early}");
        // Past 3,000 samples: 4 samples per insert.
        let late = ratio(seen[8], seen[19]);
        assert!((late - 4.0).abs() < 0.05, "late ratio {late}");
        // Inside the ramp the ratio lies between the two.
        let mid = ratio(seen[2], seen[5]);
        assert!(mid > 0.6 && mid < 3.9, "ramp ratio {mid}");
        assert!((l.current_ratio() - 4.0).abs() < 1e-9);
    }

    #[test]
    fn a_ramp_without_change_is_the_constant_ratio() {
        let mut constant = limiter(5, 2.0, 4.0);
        let mut ramp = ramped(5, 2.0, 2.0, 100, 200, 4.0);
        constant.inserted(5);
        ramp.inserted(5);
        for step in 0..2_000u64 {
            assert_eq!(constant.can_sample(), ramp.can_sample(), "step {step}");
            assert_eq!(constant.can_insert(), ramp.can_insert(), "step {step}");
            for l in [&mut constant, &mut ramp] {
                if step % 2 == 0 && l.can_sample() {
                    l.sampled(1);
                } else if l.can_insert() {
                    l.inserted(1);
                } else {
                    l.sampled(1);
                }
            }
        }
    }

    #[test]
    fn inserts_for_integrates_the_inverse_ratio() {
        let ramp = RatioRamp {
            early: 0.5,
            from: 100,
            to: 300,
        };
        // Numerical integral of 1 / r over 0..s against the closed form.
        for s in [50.0, 100.0, 180.0, 300.0, 700.0] {
            let n = 100_000;
            let h = s / n as f64;
            let numeric: f64 = (0..n)
                .map(|i| h / ramp.ratio_at(4.0, (i as f64 + 0.5) * h))
                .sum();
            let closed = ramp.inserts_for(4.0, s);
            assert!(
                (numeric - closed).abs() < 1e-3,
                "s {s}: {numeric} vs {closed}"
            );
        }
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
    fn items_admitted_but_not_counted_yet_hold_back_inserts() {
        // Two samples per insert, drift of 4 samples either way, from 10.
        let mut l = limiter(10, 2.0, 4.0);
        l.inserted(10);
        // gap 20, bounds [16, 24]: one more item fits, two do not.
        assert!(l.can_insert() && l.can_insert_after(1));
        assert!(
            !l.can_insert_after(2),
            "two pending and one more would reach 26 > 24"
        );
        // Below the minimum size nothing holds inserts back.
        let fresh = limiter(10, 2.0, 4.0);
        assert!(fresh.can_insert_after(9));
        let mut ramp = ramped(10, 2.0, 2.0, 100, 200, 4.0);
        ramp.inserted(10);
        assert!(ramp.can_insert_after(1) && !ramp.can_insert_after(2));
    }

    #[test]
    fn one_side_can_always_go() {
        let cases = [(0.5, 1.0), (1.0, 1.0), (4.0, 4.0), (8.0, 20.0)]
            .into_iter()
            .map(|(r, tol)| limiter(5, r, tol))
            .chain([
                ramped(5, 0.5, 4.0, 100, 2_000, 4.0),
                ramped(5, 8.0, 0.25, 0, 500, 8.0),
            ]);
        for mut l in cases {
            let (r, tol) = (l.config().samples_per_insert, l.config().tolerance);
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

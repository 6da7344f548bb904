//! Running totals of episode ends, for evaluation reports.

use crossroads_sim::{EpisodeEnd, Outcome};

/// Success, collision and timeout counts with mean time and braking, as
/// the paper's tables report them. Cost: O(1) per episode.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EpisodeStats {
    /// Episodes that reached the goal.
    pub successes: u64,
    /// Episodes that ended in a collision.
    pub collisions: u64,
    /// Episodes that hit the step limit.
    pub timeouts: u64,
    success_time_s: f64,
    brake_time_s: f64,
}

impl EpisodeStats {
    /// Adds one episode.
    pub fn record(&mut self, end: &EpisodeEnd) {
        match end.outcome {
            Outcome::Success => {
                self.successes += 1;
                self.success_time_s += end.time_s;
            }
            Outcome::Collision => self.collisions += 1,
            Outcome::Timeout => self.timeouts += 1,
        }
        self.brake_time_s += end.brake_time_s;
    }

    /// Episodes recorded.
    pub fn episodes(&self) -> u64 {
        self.successes + self.collisions + self.timeouts
    }

    /// Fraction of episodes that succeeded (0 with none).
    pub fn success_rate(&self) -> f64 {
        ratio(self.successes as f64, self.episodes())
    }

    /// Fraction that collided.
    pub fn collision_rate(&self) -> f64 {
        ratio(self.collisions as f64, self.episodes())
    }

    /// Fraction that timed out.
    pub fn timeout_rate(&self) -> f64 {
        ratio(self.timeouts as f64, self.episodes())
    }

    /// Mean time to goal of the successes, seconds.
    pub fn mean_success_time_s(&self) -> f64 {
        ratio(self.success_time_s, self.successes)
    }

    /// Mean braking time of traffic per episode, seconds.
    pub fn mean_brake_time_s(&self) -> f64 {
        ratio(self.brake_time_s, self.episodes())
    }
}

fn ratio(sum: f64, n: u64) -> f64 {
    if n == 0 { 0.0 } else { sum / n as f64 }
}

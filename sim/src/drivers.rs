//! Who drives the traffic: a population of drivers from which each car's
//! driver is drawn as it enters its lane.
//!
//! A scenario's `[traffic]` table gives every car the same driver; a
//! [`DriverPopulation`] (a scenario's `[drivers]` table, or a preset by
//! name) draws, per car, the seconds before he reacts to an ego coming at
//! his lane (the rule of `sim/src/traffic.rs`), the braking he accepts to
//! give way (comfortable) and the hardest he can apply (emergency), his
//! time headway, his desired speed's spread and cap, and whether he
//! notices the ego at all. Each bound is uniform between its two ends, so
//! a population states its bounds plainly (what the shield may assume).
//! [`PRESETS`]: `sumo`, the scenario's own drivers (SUMO's defaults, which
//! the paper used), `human`, drivers as road-safety research measures them
//! (docs/drivers.md cites each value), and `mixed`, half of each.
//!
//! Draws come from a random stream of their own, seeded from the episode's
//! seed ([`Traffic::seed_drivers`](crate::Traffic::seed_drivers)): the same
//! seed gives the same drivers, and the `sumo` preset, which draws nothing,
//! leaves every episode exactly as it was.

use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::params::TrafficParams;

/// A closed range `[min, max]`, drawn uniformly; written `[min, max]` in
/// TOML (equal ends give every driver the same value).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "[f64; 2]", into = "[f64; 2]")]
pub struct Bounds {
    /// Least value.
    pub min: f64,
    /// Greatest value.
    pub max: f64,
}

impl From<[f64; 2]> for Bounds {
    fn from([min, max]: [f64; 2]) -> Self {
        Self { min, max }
    }
}

impl From<Bounds> for [f64; 2] {
    fn from(b: Bounds) -> Self {
        [b.min, b.max]
    }
}

impl Bounds {
    /// Both ends the same.
    pub const fn exactly(v: f64) -> Self {
        Self { min: v, max: v }
    }

    /// A uniform draw between the ends (no draw when they are equal).
    fn draw(self, rng: &mut impl Rng) -> f64 {
        if self.max > self.min {
            self.min + (self.max - self.min) * rng.random::<f64>()
        } else {
            self.min
        }
    }

    fn valid(self, positive: bool) -> bool {
        self.min.is_finite()
            && self.max.is_finite()
            && self.min <= self.max
            && if positive {
                self.min > 0.0
            } else {
                self.min >= 0.0
            }
    }
}

/// The drivers of a scenario's traffic. Each field left unset keeps the
/// scenario's `[traffic]` value for every car.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriverPopulation {
    /// Seconds from the moment an ego comes at (or into) the driver's lane
    /// to his first reaction to it (`traffic.reaction_delay_s`).
    pub reaction_s: Option<Bounds>,
    /// Hardest braking the driver accepts to give way to an ego pulling out
    /// ahead of him, m/s² (`traffic.yield_decel`).
    pub yield_decel: Option<Bounds>,
    /// Hardest braking he can apply, for an ego on the junction or in his
    /// lane, m/s² (`traffic.emergency_decel`).
    pub emergency_decel: Option<Bounds>,
    /// His desired time headway in car following, s (`traffic.headway`).
    pub headway: Option<Bounds>,
    /// Standard deviation of the speed factor (`traffic.speed_factor_dev`;
    /// the desired speed is the lane's limit times the factor).
    pub speed_factor_dev: Option<f64>,
    /// Upper clip of the speed factor (`traffic.speed_factor_max`): the
    /// fastest any driver wants to go, times the limit.
    pub speed_factor_max: Option<f64>,
    /// Share of drivers who do not notice an ego pulling out at all: they
    /// neither give way nor brake for it until it is in their lane ahead
    /// of them, where they follow it as any leader. In [0, 1].
    pub inattentive_share: f64,
    /// Share of drivers who are the scenario's own (`[traffic]`: SUMO's in
    /// the built-in scenarios) rather than drawn from the bounds above, so
    /// one population can hold both. In [0, 1]; 0 draws every driver.
    pub sumo_share: f64,
}

/// The names of the presets, for help and errors.
pub const PRESETS: [&str; 3] = ["sumo", "human", "mixed"];

impl DriverPopulation {
    /// A preset by name: `sumo`, `human` or `mixed`.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "sumo" => Some(Self::default()),
            "human" => Some(Self::human()),
            "mixed" => Some(Self::mixed()),
            _ => None,
        }
    }

    /// Half the drivers SUMO's (the scenario's own), half drawn as
    /// [`DriverPopulation::human`]: a population to train on, so a network
    /// meets both the drivers the paper simulated and those on real roads.
    /// Its bounds are the human ones (SUMO's driver lies inside each), so
    /// the shield assumes the same of it as of `human`.
    pub fn mixed() -> Self {
        Self {
            sumo_share: 0.5,
            ..Self::human()
        }
    }

    /// Drivers as road-safety research measures them (docs/drivers.md
    /// gives the source of each value): brake reaction 0.7-1.5 s (from an
    /// expected event to a surprise), giving way with 3-4.5 m/s², braking
    /// in an emergency with 3.4-9 m/s², headways 1-2 s, a speed factor
    /// spread of 0.15 up to 1.45 times the limit; everyone attentive (the
    /// inattentive share is a separate axis).
    pub fn human() -> Self {
        Self {
            reaction_s: Some(Bounds { min: 0.7, max: 1.5 }),
            yield_decel: Some(Bounds { min: 3.0, max: 4.5 }),
            emergency_decel: Some(Bounds { min: 3.4, max: 9.0 }),
            headway: Some(Bounds { min: 1.0, max: 2.0 }),
            speed_factor_dev: Some(0.15),
            speed_factor_max: Some(1.45),
            inattentive_share: 0.0,
            sumo_share: 0.0,
        }
    }

    /// A preset name, or the path of a TOML file holding a population (the
    /// keys of this struct at its top level).
    pub fn load(name_or_path: &str) -> Result<Self, SimError> {
        if let Some(p) = Self::preset(name_or_path) {
            return Ok(p);
        }
        let path = std::path::Path::new(name_or_path);
        if !(name_or_path.ends_with(".toml") || name_or_path.contains('/')) {
            return Err(SimError::invalid(
                &format!("drivers {name_or_path:?}"),
                format!(
                    "no such preset (there are {}) and not a .toml file",
                    PRESETS.join(", ")
                ),
            ));
        }
        let text = std::fs::read_to_string(path).map_err(|source| SimError::Io {
            path: path.to_owned(),
            source,
        })?;
        let what = format!("drivers {}", path.display());
        let population: Self = toml::from_str(&text).map_err(|e| SimError::Parse {
            what: what.clone(),
            source: Box::new(e),
        })?;
        population.check(&what)?;
        Ok(population)
    }

    /// Checks the bounds: positive brakings and headways, reactions of
    /// zero or more, speed factors that make sense, a share in [0, 1].
    pub fn check(&self, what: &str) -> Result<(), SimError> {
        let ok = self.reaction_s.is_none_or(|b| b.valid(false))
            && [self.yield_decel, self.emergency_decel, self.headway]
                .iter()
                .all(|b| b.is_none_or(|b| b.valid(true)))
            && self
                .speed_factor_dev
                .is_none_or(|d| d.is_finite() && d >= 0.0)
            && self
                .speed_factor_max
                .is_none_or(|m| m.is_finite() && m > 0.0)
            && (0.0..=1.0).contains(&self.inattentive_share)
            && (0.0..=1.0).contains(&self.sumo_share);
        if ok {
            Ok(())
        } else {
            Err(SimError::invalid(
                what,
                "driver bounds out of range: [min, max] with min <= max, brakings and \
                 headways above 0, reactions and speed factor spread at least 0, \
                 inattentive_share and sumo_share in [0, 1]",
            ))
        }
    }

    /// Whether every car gets the scenario's own driver (nothing to draw).
    pub fn is_uniform(&self) -> bool {
        self.reaction_s.is_none()
            && self.yield_decel.is_none()
            && self.emergency_decel.is_none()
            && self.headway.is_none()
            && self.inattentive_share == 0.0
    }

    /// The traffic parameters with this population's speed factor bounds.
    pub fn traffic(&self, p: &TrafficParams) -> TrafficParams {
        let mut p = *p;
        if let Some(d) = self.speed_factor_dev {
            p.speed_factor_dev = d;
        }
        if let Some(m) = self.speed_factor_max {
            p.speed_factor_max = m;
        }
        p
    }

    /// One car's driver, drawn from `rng`; `None` when the car gets the
    /// scenario's driver (every car, or its `sumo_share`).
    pub fn draw(&self, p: &TrafficParams, rng: &mut impl Rng) -> Option<Driver> {
        if self.is_uniform() {
            return None;
        }
        if self.sumo_share > 0.0 && rng.random::<f64>() < self.sumo_share {
            return None;
        }
        let mut pick = |b: Option<Bounds>, own: f64| b.map_or(own, |b| b.draw(rng));
        let reaction_s = pick(self.reaction_s, p.reaction_delay_s);
        let yield_decel = pick(self.yield_decel, p.yield_decel);
        let emergency_decel = pick(self.emergency_decel, p.emergency_decel);
        let headway = pick(self.headway, p.headway);
        let attentive =
            self.inattentive_share <= 0.0 || rng.random::<f64>() >= self.inattentive_share;
        Some(Driver {
            reaction_s,
            yield_decel: yield_decel.min(emergency_decel),
            emergency_decel,
            headway,
            attentive,
        })
    }
}

impl std::fmt::Display for DriverPopulation {
    /// One line: `sumo` when every car has the scenario's driver, else each
    /// bound that is drawn.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut parts = Vec::new();
        let mut range = |name: &str, b: Option<Bounds>, unit: &str| {
            if let Some(b) = b {
                parts.push(format!("{name} {}-{} {unit}", b.min, b.max));
            }
        };
        range("reaction", self.reaction_s, "s");
        range("give way <=", self.yield_decel, "m/s²");
        range("emergency", self.emergency_decel, "m/s²");
        range("headway", self.headway, "s");
        if let Some(d) = self.speed_factor_dev {
            parts.push(format!("speed factor sd {d}"));
        }
        if let Some(m) = self.speed_factor_max {
            parts.push(format!("speed factor <= {m}"));
        }
        if self.inattentive_share > 0.0 {
            parts.push(format!("inattentive {} %", 100.0 * self.inattentive_share));
        }
        if self.sumo_share > 0.0 && !parts.is_empty() {
            parts.push(format!("SUMO's drivers {} %", 100.0 * self.sumo_share));
        }
        if parts.is_empty() {
            f.write_str("sumo (every car the scenario's [traffic] driver)")
        } else {
            f.write_str(&parts.join(", "))
        }
    }
}

/// One car's driver.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Driver {
    /// Seconds before he reacts to an ego coming at his lane.
    pub reaction_s: f64,
    /// Hardest braking he accepts to give way, m/s².
    pub yield_decel: f64,
    /// Hardest braking he can apply, m/s².
    pub emergency_decel: f64,
    /// His desired time headway, s.
    pub headway: f64,
    /// Whether he notices an ego pulling out at all.
    pub attentive: bool,
}

impl Driver {
    /// The traffic parameters as this driver applies them.
    pub fn params(&self, p: &TrafficParams) -> TrafficParams {
        let mut p = *p;
        p.reaction_delay_s = self.reaction_s;
        p.yield_decel = self.yield_decel;
        p.emergency_decel = self.emergency_decel;
        p.decel = p.decel.min(self.emergency_decel);
        p.headway = self.headway;
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    fn draws(pop: &DriverPopulation, seed: u64, n: usize) -> Vec<Driver> {
        let p = TrafficParams::default();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        (0..n)
            .map(|_| pop.draw(&p, &mut rng).expect("a drawn driver"))
            .collect()
    }

    #[test]
    fn the_sumo_preset_draws_nothing_and_keeps_the_scenarios_drivers() {
        let sumo = DriverPopulation::preset("sumo").expect("sumo");
        assert!(sumo.is_uniform());
        let p = TrafficParams::default();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        assert_eq!(sumo.draw(&p, &mut rng), None);
        assert_eq!(sumo.traffic(&p), p);
    }

    #[test]
    fn human_drivers_fill_their_bounds_uniformly() {
        let human = DriverPopulation::human();
        let n = 20_000;
        let d = draws(&human, 7, n);
        let stats = |f: fn(&Driver) -> f64| {
            let v: Vec<f64> = d.iter().map(f).collect();
            let mean = v.iter().sum::<f64>() / n as f64;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
            let (lo, hi) = v
                .iter()
                .fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            (mean, var, lo, hi)
        };
        // Uniform on [a, b]: mean (a + b) / 2, variance (b - a)^2 / 12.
        for (name, f, b) in [
            (
                "reaction",
                (|d: &Driver| d.reaction_s) as fn(&Driver) -> f64,
                Bounds { min: 0.7, max: 1.5 },
            ),
            (
                "emergency",
                |d: &Driver| d.emergency_decel,
                Bounds { min: 3.4, max: 9.0 },
            ),
            (
                "headway",
                |d: &Driver| d.headway,
                Bounds { min: 1.0, max: 2.0 },
            ),
        ] {
            let (mean, var, lo, hi) = stats(f);
            let width = b.max - b.min;
            let se = (width * width / 12.0 / n as f64).sqrt();
            assert!(
                (mean - (b.min + b.max) / 2.0).abs() < 4.0 * se,
                "{name}: mean {mean} for {b:?}"
            );
            assert!(
                (var - width * width / 12.0).abs() < 0.05 * width * width / 12.0,
                "{name}: variance {var} for {b:?}"
            );
            assert!(
                lo >= b.min && hi <= b.max,
                "{name}: [{lo}, {hi}] outside {b:?}"
            );
        }
        assert!(
            d.iter()
                .all(|d| d.attentive && d.yield_decel <= d.emergency_decel)
        );
    }

    #[test]
    fn an_inattentive_share_is_drawn_at_its_rate() {
        let pop = DriverPopulation {
            inattentive_share: 0.1,
            ..DriverPopulation::human()
        };
        let n = 20_000;
        let inattentive = draws(&pop, 3, n).iter().filter(|d| !d.attentive).count();
        let rate = inattentive as f64 / n as f64;
        // Binomial standard error at 10 %: 0.21 points.
        assert!((rate - 0.1).abs() < 0.01, "{rate}");
    }

    #[test]
    fn a_mixed_population_keeps_sumos_driver_for_its_share() {
        let mixed = DriverPopulation::preset("mixed").expect("mixed");
        assert!(!mixed.is_uniform());
        let p = TrafficParams::default();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        let n = 20_000;
        let drawn: Vec<Option<Driver>> = (0..n).map(|_| mixed.draw(&p, &mut rng)).collect();
        let sumo = drawn.iter().filter(|d| d.is_none()).count();
        let rate = sumo as f64 / n as f64;
        // Binomial standard error at 50 %: 0.35 points.
        assert!((rate - 0.5).abs() < 0.015, "{rate}");
        assert!(
            drawn
                .iter()
                .flatten()
                .all(|d| (0.7..=1.5).contains(&d.reaction_s)),
            "the others are human"
        );
        assert!(mixed.to_string().contains("SUMO's drivers 50 %"), "{mixed}");
        let bad = DriverPopulation {
            sumo_share: 1.5,
            ..DriverPopulation::human()
        };
        let e = bad.check("drivers x").expect_err("refused").to_string();
        assert!(e.contains("sumo_share"), "{e}");
    }

    #[test]
    fn the_same_seed_draws_the_same_drivers() {
        let human = DriverPopulation::human();
        assert_eq!(draws(&human, 11, 100), draws(&human, 11, 100));
        assert_ne!(draws(&human, 11, 100), draws(&human, 12, 100));
    }

    #[test]
    fn a_population_file_loads_and_bad_bounds_are_named() {
        let dir = tempfile::tempdir().expect("temp dir");
        let good = dir.path().join("drivers.toml");
        std::fs::write(&good, "reaction_s = [0.5, 1.0]\ninattentive_share = 0.05\n")
            .expect("write");
        let pop = DriverPopulation::load(good.to_str().expect("utf-8")).expect("load");
        assert_eq!(pop.reaction_s, Some(Bounds { min: 0.5, max: 1.0 }));
        assert_eq!(pop.yield_decel, None);
        let bad = dir.path().join("bad.toml");
        std::fs::write(&bad, "reaction_s = [1.0, 0.5]\n").expect("write");
        let e = DriverPopulation::load(bad.to_str().expect("utf-8")).expect_err("refused");
        assert!(e.to_string().contains("min <= max"), "{e}");
        let e = DriverPopulation::load("humans").expect_err("refused");
        assert!(e.to_string().contains("sumo, human"), "{e}");
    }
}

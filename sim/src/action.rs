//! The three action sets of the paper and how their indices decode.

use serde::{Deserialize, Serialize};

use crate::error::SimError;

/// Durations, in steps, of the multi-step actions.
pub const DURATIONS: [u32; 4] = [1, 2, 4, 8];

/// An action set: how the network's output indices map to ego controls.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ActionSet {
    /// Time-to-Go, 5 actions: `0` go; `1..=4` wait 1, 2, 4, 8 steps.
    /// *Go* is final: the ego drives its whole path in that one transition.
    Ttg,
    /// Sequential, 12 actions: `3 * j + m` for duration `DURATIONS[j]` and
    /// mode `m`: `0` accelerate, `1` decelerate, `2` keep speed.
    Sequential,
    /// Creep-and-Go, 3 actions: `0` wait one step, `1` creep one step,
    /// `2` go (final, as in TTG).
    Creep,
}

/// What an action index means.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Control {
    /// Commit and drive to the end of the episode at full acceleration.
    Go,
    /// Stand (braking to a stop if moving) for this many steps.
    Wait(u32),
    /// Move towards creep speed, never past the creep limit.
    Creep,
    /// Constant acceleration command (m/s² as a multiple: `1` accelerate,
    /// `-1` decelerate, `0` keep) for this many steps.
    Accel(i8, u32),
}

/// What a rule-based policy wants to do, mapped onto any action set by
/// [`ActionSet::encode`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Intent {
    /// Stay (or come to a stop) before the conflict area.
    Wait,
    /// Move forward slowly to see more.
    Creep,
    /// Cross now.
    Go,
}

impl ActionSet {
    /// Every action set.
    pub const ALL: [Self; 3] = [Self::Ttg, Self::Sequential, Self::Creep];

    /// Number of actions (network outputs).
    pub fn num_actions(self) -> usize {
        match self {
            Self::Ttg => 5,
            Self::Sequential => 12,
            Self::Creep => 3,
        }
    }

    /// The index of a *go* that ends the episode (TTG, Creep); `None` where
    /// going is a sequence of accelerations (Sequential).
    pub fn absorbing_go(self) -> Option<usize> {
        match self {
            Self::Ttg => Some(0),
            Self::Creep => Some(2),
            Self::Sequential => None,
        }
    }

    /// The index of the final *go* that `policy` needs (it checks or tries
    /// one, `why`); an error naming both where the set has none.
    pub fn final_go_for(self, policy: &str, why: &str) -> Result<usize, SimError> {
        self.absorbing_go().ok_or_else(|| SimError::Unsupported {
            policy: format!("{policy} ({why}: ttg or creep actions)"),
            set: self.name(),
        })
    }

    /// Lower-case name, as parsed.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ttg => "ttg",
            Self::Sequential => "sequential",
            Self::Creep => "creep",
        }
    }

    /// Decodes an action index.
    pub fn decode(self, action: usize) -> Result<Control, SimError> {
        let out = || SimError::ActionOutOfRange {
            action,
            set: self.name(),
            count: self.num_actions(),
        };
        Ok(match self {
            Self::Ttg => match action {
                0 => Control::Go,
                1..=4 => Control::Wait(DURATIONS[action - 1]),
                _ => return Err(out()),
            },
            Self::Sequential => {
                if action >= 12 {
                    return Err(out());
                }
                let mode = match action % 3 {
                    0 => 1,
                    1 => -1,
                    _ => 0,
                };
                Control::Accel(mode, DURATIONS[action / 3])
            }
            Self::Creep => match action {
                0 => Control::Wait(1),
                1 => Control::Creep,
                2 => Control::Go,
                _ => return Err(out()),
            },
        })
    }

    /// The one-step action of this set that carries out `intent` for an ego
    /// moving at `v` (creep speed `creep_speed`). TTG has no creep and
    /// answers `None` for it.
    pub fn encode(self, intent: Intent, v: f64, creep_speed: f64) -> Option<usize> {
        match (self, intent) {
            (Self::Ttg, Intent::Go) => Some(0),
            (Self::Ttg, Intent::Wait) => Some(1),
            (Self::Ttg, Intent::Creep) => None,
            (Self::Creep, Intent::Wait) => Some(0),
            (Self::Creep, Intent::Creep) => Some(1),
            (Self::Creep, Intent::Go) => Some(2),
            (Self::Sequential, Intent::Go) => Some(0),
            (Self::Sequential, Intent::Wait) => Some(1),
            (Self::Sequential, Intent::Creep) => Some(if v < creep_speed - 0.2 {
                0
            } else if v > creep_speed + 0.2 {
                1
            } else {
                2
            }),
        }
    }
}

impl std::str::FromStr for ActionSet {
    type Err = SimError;
    fn from_str(s: &str) -> Result<Self, SimError> {
        Self::ALL
            .into_iter()
            .find(|a| a.name() == s)
            .ok_or_else(|| SimError::PolicySpec {
                spec: s.to_owned(),
                problem: "action set must be ttg, sequential or creep".to_owned(),
            })
    }
}

impl std::fmt::Display for ActionSet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoding() {
        assert_eq!(ActionSet::Ttg.decode(0).unwrap(), Control::Go);
        assert_eq!(ActionSet::Ttg.decode(4).unwrap(), Control::Wait(8));
        assert!(ActionSet::Ttg.decode(5).is_err());
        assert_eq!(
            ActionSet::Sequential.decode(0).unwrap(),
            Control::Accel(1, 1)
        );
        assert_eq!(
            ActionSet::Sequential.decode(4).unwrap(),
            Control::Accel(-1, 2)
        );
        assert_eq!(
            ActionSet::Sequential.decode(11).unwrap(),
            Control::Accel(0, 8)
        );
        assert!(ActionSet::Sequential.decode(12).is_err());
        assert_eq!(ActionSet::Creep.decode(1).unwrap(), Control::Creep);
        assert!(ActionSet::Creep.decode(3).is_err());
        assert_eq!(
            "sequential".parse::<ActionSet>().unwrap(),
            ActionSet::Sequential
        );
        assert!("x".parse::<ActionSet>().is_err());
        for set in ActionSet::ALL {
            for intent in [Intent::Wait, Intent::Go] {
                let a = set.encode(intent, 0.0, 1.0).unwrap();
                assert!(a < set.num_actions());
            }
        }
    }
}

//! `[sim]`: what every role of a run simulates and learns on, stated once:
//! the scenario, the action set and the observation the network reads.
//! Actors step this scenario with these actions; the learner builds its
//! network for this observation and these actions and records the scenario
//! in checkpoints.

use serde::{Deserialize, Serialize};

use crossroads_types::ObservationLayout;

use super::{ACTION_SETS, Checks};

/// What a run simulates.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Scenario: a built-in name (`right`, `left`, `left2`, `forward`,
    /// `challenge`, `occluded`, `occluded-<30|60|90>[-left|-right|-both]`)
    /// or a TOML file.
    pub scenario: String,
    /// Action set: `ttg` (5), `sequential` (12) or `creep` (3).
    pub action_set: String,
    /// Who drives the traffic: a preset (`sumo`: SUMO's drivers, the
    /// paper's; `human`: reaction 0.7-1.5 s and the rest as measured on
    /// roads, docs/drivers.md; `mixed`: half each) or a drivers TOML file. Unset: the
    /// scenario's own (its `[drivers]` table, else `sumo`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub drivers: Option<String>,
    /// Observation the network reads: `ttg`, `ttg-occlusion`, `sequential`
    /// or `sequential-occlusion`. Unset: the paper's pairing, derived when a
    /// role loads the scenario (the Sequential grid for Sequential actions,
    /// the TTG grid otherwise; occlusion channels when the scenario has
    /// occluders). Set, it must be that pairing: the actors produce it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observation: Option<String>,
    /// The layout of `observation`, as the simulator gives it: filled when
    /// a role resolves the observation at start, never read from a file,
    /// so that roles which do not link the simulator (the learner) build
    /// their network from it.
    #[serde(skip)]
    #[schemars(skip)]
    layout: Option<ObservationLayout>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            scenario: "left".to_owned(),
            action_set: "ttg".to_owned(),
            drivers: None,
            observation: None,
            layout: None,
        }
    }
}

impl SimConfig {
    /// Fills `observation` and its layout with `produced`, the layout the
    /// actors of this scenario and action set produce, or checks that the
    /// observation given is that one (by name).
    pub fn resolve_layout(&mut self, produced: ObservationLayout) -> Result<(), String> {
        match &self.observation {
            Some(given) if *given != produced.kind => Err(format!(
                "sim.observation = {given:?}, but scenario {:?} with {:?} actions produces \
                 {:?}; remove sim.observation (it is derived) or change the scenario \
                 or the action set",
                self.scenario, self.action_set, produced.kind
            )),
            _ => {
                self.observation = Some(produced.kind.clone());
                self.layout = Some(produced);
                Ok(())
            }
        }
    }

    /// The observation's name, once given or resolved (see
    /// [`Self::resolve_layout`]).
    pub fn observation(&self) -> Option<&str> {
        self.observation.as_deref()
    }

    /// The observation's layout, once resolved (see
    /// [`Self::resolve_layout`]).
    pub fn layout(&self) -> Option<&ObservationLayout> {
        self.layout.as_ref()
    }

    /// Range checks, each with its dotted key.
    pub fn validate(&self) -> Vec<(String, String)> {
        let mut problems = Checks::new("sim");
        problems.check(
            !self.scenario.is_empty(),
            "scenario",
            "must name a scenario".to_owned(),
        );
        problems.one_of("action_set", &self.action_set, &ACTION_SETS);
        // `observation` names a view of the simulator, which this crate does
        // not link: resolving it checks the name (crossroads_actor::resolve_observation).
        problems.into_vec()
    }
}

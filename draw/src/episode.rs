//! One trial of a policy recorded as scenes, one per simulation step.

use std::sync::Arc;

use crossroads_sim::{
    ActionSet, Control, Env, EnvConfig, Policy, PolicyRng, RenderView, Scenario, Scene,
    SceneOptions, ShieldCounters, ShieldParams, SimError, check_go, episode_seed, policy_seed,
    sense,
};
use rand::SeedableRng;

/// Which episode to record and how to look at it.
#[derive(Debug, Clone, Copy)]
pub struct EpisodeView {
    /// Base seed; the episode is trial `trial` of an evaluation with it.
    pub seed: u64,
    /// Which trial of the seed's sequence.
    pub trial: u64,
    /// Overlay the observation grid the action set's network sees.
    pub grid: bool,
    /// Pixels per metre [default: the view's, wide for grids and
    /// occlusion scenarios].
    pub scale: Option<f64>,
}

/// An episode as scenes, one per simulation step (the first before any
/// step).
#[derive(Debug)]
pub struct EpisodeScenes {
    /// The scenes in order.
    pub scenes: Vec<Scene>,
    /// The index of the scene at which the policy chose *go*.
    pub go_at: Option<usize>,
    /// The policy, the outcome, time, traffic braking and the shield's
    /// vetoes, in a line.
    pub summary: String,
}

/// Plays trial `view.trial` of seed `view.seed` (the same episode as
/// `crossroads eval` plays) with `policy` driving `actions`, and records a
/// scene after every step. With `shield` (the assumptions and counters of
/// the shield `policy` is behind), each scene before the ego commits also
/// shows what the shield assumed, and the car it feared when it vetoed.
pub fn record_episode(
    scenario: &Arc<Scenario>,
    policy: &dyn Policy,
    shield: Option<(&ShieldParams, &ShieldCounters)>,
    actions: ActionSet,
    view: EpisodeView,
) -> Result<EpisodeScenes, SimError> {
    let config = EnvConfig::for_actions(actions);
    let options = SceneOptions {
        grid: view.grid.then_some(config.observation),
    };
    let mut env = Env::new(Arc::clone(scenario), config);
    env.reset(episode_seed(view.seed, view.trial));
    let mut rng = [PolicyRng::seed_from_u64(policy_seed(view.seed, view.trial))];
    let mut render = if view.grid || !env.occluders().is_empty() {
        RenderView::wide()
    } else {
        RenderView::default()
    };
    if let Some(scale) = view.scale {
        render.scale = scale;
    }

    let mut scenes = vec![Scene::of(&env, &render, &options)];
    let mut go_at = None;
    let mut sensed = Vec::new();
    let mut vetoes = 0;
    while !env.is_done() {
        let mut action = [0];
        let before = shield.map(|(_, c)| c.stats().vetoes);
        policy.act(std::slice::from_ref(&env), &mut rng, &mut action)?;
        // Before the ego commits, draw what the shield assumed, and the car
        // it feared when it vetoed this decision.
        if let (Some((params, counters)), Some(before)) = (shield, before)
            && !env.ego().committed
        {
            sense(&env, params, &mut sensed);
            let vetoed = counters.stats().vetoes > before;
            let threat = if vetoed {
                vetoes += 1;
                check_go(&env, &sensed, params)
            } else {
                None
            };
            if let Some(scene) = scenes.last_mut() {
                scene.mark_shield(&env, &render, &sensed, threat.as_ref());
            }
        }
        if go_at.is_none() && actions.decode(action[0])? == Control::Go {
            go_at = Some(scenes.len() - 1);
        }
        env.step_with(action[0], |e| scenes.push(Scene::of(e, &render, &options)))?;
    }
    let m = env.metrics();
    let outcome = env
        .outcome()
        .map_or_else(|| "running".to_owned(), |o| format!("{o:?}").to_lowercase());
    let mut summary = format!(
        "{} {outcome} after {:.1} s (traffic braking {:.1} s)",
        policy.name(),
        m.time_s,
        m.brake_time_s
    );
    if shield.is_some() {
        summary += &format!(", the shield vetoed {vetoes} go decision(s)");
    }
    Ok(EpisodeScenes {
        scenes,
        go_at,
        summary,
    })
}

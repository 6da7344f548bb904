//! The actor's core: batches of valid n-step transitions, one forward pass
//! per lane and step, two lanes acting like one, the epsilon ladder from
//! the config, greedy evaluation.

use crossroads_actor::{ActorSettings, EpisodeStats, Mode, resolve_index};
use crossroads_common::Shutdown;
use crossroads_config::{ActorConfig, ConfigLoader, SimConfig};
use crossroads_sim::Outcome;
use crossroads_transport::grpc::ReplayClient;

use crate::util::{actor, actor_config, actor_on, batches, replay_config, transport};

#[test]
fn training_fills_valid_batches_with_one_forward_pass_per_lane_and_step() {
    let config = actor_config(4, 32);
    let (mut a, mut values) = actor(&config, 0);
    let out = batches(&mut a, &mut values, 3);
    for b in &out {
        b.validate().expect("valid batch");
        assert_eq!(b.len(), 32);
        assert_eq!(b.num_actions, 5);
        assert_eq!(b.layout.kind, "ttg");
        assert!(b.observations.len() < 2 * b.len(), "observations shared");
        assert!(b.columns.discounts.iter().all(|d| *d == 0.0 || *d <= 0.99));
        assert!(
            b.columns
                .priorities
                .iter()
                .all(|p| p.is_finite() && *p >= 0.0)
        );
    }
    assert!(
        out.iter()
            .flat_map(|b| &b.columns.discounts)
            .any(|d| *d == 0.0),
        "episode ends are terminal"
    );
    // A single actor's 4 environments are the 4 rungs of the ladder; the
    // gauge is their mean.
    let eps = a.metrics().epsilon.get();
    let mean = (0..4)
        .map(|e| 0.4f64.powf(1.0 + 7.0 * f64::from(e) / 3.0))
        .sum::<f64>()
        / 4.0;
    assert!(
        (eps - mean).abs() < 1e-12,
        "a single actor of 4 environments explores with a mean {mean}, got {eps}"
    );
    // 3 batches of 32 from 4 environments need at least 24 steps, of one
    // forward pass per lane (2) each.
    let forward = values.calls;
    assert!(forward >= 48, "{forward} forward passes for 2 lanes of 2");
}

/// Pipelined, the environments are two lanes of one forward pass each per
/// step (plus the second lane's first decision); not pipelined, one pass
/// for all. Either way every environment acts once per step on its own
/// seeds and random streams, so a greedy actor ends the same episodes.
#[test]
fn two_lanes_act_like_one_on_each_environments_seeds() {
    let run = |pipeline: bool, envs: usize| {
        let mut config = actor_config(envs, 8);
        config.eval = true;
        config.pipeline = pipeline;
        let (mut a, mut values) = actor(&config, 0);
        let mut ended = Vec::new();
        for _ in 0..300 {
            let summary = a.step(&mut values).expect("step");
            assert_eq!(summary.decisions, envs as u64);
            ended.extend(
                summary
                    .episodes
                    .iter()
                    .map(|e| (e.seed, e.steps, e.outcome)),
            );
        }
        ended.sort_by_key(|e| (e.0, e.1));
        (a.lanes(), values.calls, ended)
    };
    let (lanes, calls, pipelined) = run(true, 5);
    assert_eq!((lanes, calls), (2, 2 * 300 + 1));
    let (lanes, calls, one_lane) = run(false, 5);
    assert_eq!((lanes, calls), (1, 300));
    assert!(!pipelined.is_empty(), "episodes end");
    assert_eq!(pipelined, one_lane);
    assert_eq!(run(true, 1).0, 1, "one environment is one lane");
}

#[test]
fn the_same_seed_gives_the_same_batches() {
    let config = actor_config(3, 16);
    let run = || {
        let (mut a, mut v) = actor(&config, 0);
        batches(&mut a, &mut v, 2)
    };
    assert_eq!(run(), run());
}

#[test]
fn evaluation_is_greedy_and_pushes_nothing() {
    let mut config = actor_config(4, 8);
    config.eval = true;
    let (mut a, mut values) = actor(&config, 0);
    assert_eq!(a.settings().mode, Mode::Greedy);
    let mut ended = 0;
    let mut stats = EpisodeStats::default();
    for _ in 0..400 {
        let summary = a.step(&mut values).expect("step");
        ended += summary.episodes.len();
        summary.episodes.iter().for_each(|e| stats.record(e));
        assert!(a.take_batch().is_none());
    }
    assert_eq!(stats.episodes(), ended as u64);
    let rates = stats.success_rate() + stats.collision_rate() + stats.timeout_rate();
    assert!((rates - 1.0).abs() < 1e-9, "{stats:?}");
    assert!(stats.successes == 0 || stats.mean_success_time_s() > 0.0);
    assert!(a.flush_batch().is_none());
    assert!(ended > 0, "episodes end");
    let m = a.metrics();
    let counted: u64 = [Outcome::Success, Outcome::Collision, Outcome::Timeout]
        .into_iter()
        .map(|o| m.episodes("eval", o))
        .sum();
    assert_eq!(counted, ended as u64);
    assert_eq!(m.epsilon.get(), 0.0);
}

#[test]
fn the_ladder_comes_from_index_and_count() {
    let mut config = ActorConfig {
        count: 8,
        ..ActorConfig::default()
    };
    // Rungs over actors x envs: environment e of actor i is rung
    // i * envs + e of count * envs.
    let eps = |c: &ActorConfig, i, e| {
        ActorSettings::from_config(&SimConfig::default(), c, i)
            .expect("settings")
            .mode
            .epsilon_of(e)
    };
    let rungs = f64::from(8 * config.envs as u32 - 1);
    let ladder = |g: f64| 0.4f64.powf(1.0 + 7.0 * g / rungs);
    assert!((eps(&config, 0, 0) - 0.4).abs() < 1e-12);
    assert!((eps(&config, 1, 0) - ladder(config.envs as f64)).abs() < 1e-12);
    assert!((eps(&config, 1, 3) - ladder(config.envs as f64 + 3.0)).abs() < 1e-12);
    assert!((eps(&config, 7, config.envs - 1) - 0.4f64.powi(8)).abs() < 1e-15);
    assert!(ActorSettings::from_config(&SimConfig::default(), &config, 8).is_err());
    config.count = 1;
    config.envs = 1;
    assert_eq!(eps(&config, 0, 0), 0.4);
    let a = ActorSettings::from_config(
        &SimConfig::default(),
        &ActorConfig {
            count: 8,
            ..config.clone()
        },
        1,
    )
    .expect("settings");
    let b = ActorSettings::from_config(
        &SimConfig::default(),
        &ActorConfig { count: 8, ..config },
        2,
    )
    .expect("settings");
    assert_ne!(a.seed, b.seed, "each actor its own seed");
}

/// Without a configured index a training actor asks the replay server,
/// which hands indices out in order of first request, stable per name.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_index_comes_from_the_config_or_the_replay_server() {
    let nowhere = transport("http://127.0.0.1:1", "unused");
    let never = Shutdown::new();
    assert_eq!(
        resolve_index(Some(3), 8, false, &nowhere, &never)
            .await
            .ok(),
        Some(Some(3))
    );
    assert_eq!(
        resolve_index(None, 8, true, &nowhere, &never).await.ok(),
        Some(Some(0)),
        "evaluators take no place"
    );
    let stopped = Shutdown::new();
    stopped.trigger();
    assert_eq!(
        resolve_index(None, 8, false, &nowhere, &stopped).await.ok(),
        Some(None),
        "stopped before the replay server gave an index"
    );

    let servers = Shutdown::new();
    let replay =
        crossroads_replay::start(&replay_config("127.0.0.1:0", None), None, servers.clone())
            .await
            .expect("replay");
    let connection = transport(&format!("http://{}", replay.local_addr()), "unused");
    let client = ReplayClient::new(&connection, "t").expect("client");
    assert_eq!(client.join_actor("other-0").await.expect("join").index, 0);
    assert_eq!(client.join_actor("other-1").await.expect("join").index, 1);
    // This host takes the next place, modulo the count, and keeps it.
    assert_eq!(
        resolve_index(None, 8, false, &connection, &never)
            .await
            .ok(),
        Some(Some(2))
    );
    assert_eq!(
        resolve_index(None, 2, false, &connection, &never)
            .await
            .ok(),
        Some(Some(0))
    );
    let again = client.join_actor("other-1").await.expect("join");
    assert_eq!((again.index, again.joined), (1, 3));
    let bad = client
        .join_actor("not a name")
        .await
        .expect_err("a bad name");
    assert_eq!(bad.code(), Some(tonic::Code::InvalidArgument));
    assert!(bad.to_string().contains("name: ' '"), "{bad}");
    servers.trigger();
    replay.join().await.expect("replay stops");
}

#[test]
fn the_index_and_count_come_from_the_config_or_the_environment() {
    let config = ConfigLoader::new()
        .without_env()
        .sets(["actor.index=2", "actor.count=4", "actor.transport=shm"])
        .load()
        .expect("config");
    assert_eq!((config.actor.index, config.actor.count), (Some(2), 4));
    assert_eq!(
        config.actor.transport,
        crossroads_config::ActorTransport::Shm
    );
    let err = ConfigLoader::new()
        .without_env()
        .sets(["actor.index=4", "actor.count=4"])
        .load()
        .expect_err("index out of range");
    assert_eq!(err.problems()[0].key, "actor.index");
    let err = ConfigLoader::new()
        .without_env()
        .sets(["actor.gamma=1.5"])
        .load()
        .expect_err("gamma");
    assert_eq!(err.problems()[0].key, "actor.gamma");
}

/// The Q-network of the learner drives an actor for every observation kind
/// and action set: its input is exactly what the environments write, and
/// the batches name the kind the learner checks.
#[test]
fn the_q_network_drives_actors_of_every_kind() {
    use crossroads_model::{NetworkSpec, QNetwork, TrunkKind};
    for (scenario, action_set, kind) in [
        ("left", "ttg", "ttg"),
        ("left", "sequential", "sequential"),
        ("occluded-60", "creep", "ttg-occlusion"),
        ("occluded-60", "sequential", "sequential-occlusion"),
    ] {
        let mut sim = SimConfig::default();
        sim.scenario = scenario.to_owned();
        sim.action_set = action_set.to_owned();
        crossroads_actor::resolve_observation(&mut sim).expect("resolves");
        assert_eq!(
            sim.observation(),
            Some(kind),
            "{scenario} with {action_set}"
        );
        let (mut a, _) = actor_on(&sim, &actor_config(3, 16), 0);
        let layout = sim.layout().expect("resolved").clone();
        assert_eq!(
            crossroads_sim::observation_layout(kind).expect("a view"),
            layout
        );
        let spec =
            NetworkSpec::new(layout.clone(), action_set, TrunkKind::Mlp, vec![32]).expect("spec");
        let mut net = QNetwork::new(spec, 7).expect("network");
        let mut got = Vec::new();
        for _ in 0..2_000 {
            a.step(&mut net).expect("step with the network");
            if let Some(b) = a.take_batch() {
                got.push(b);
                break;
            }
        }
        let b = got.pop().unwrap_or_else(|| panic!("no batch for {kind}"));
        b.validate().expect("valid batch");
        assert_eq!(b.layout, layout);
        assert_eq!(b.num_actions as i64, net.spec().num_actions);
        assert!(b.columns.priorities.iter().all(|p| p.is_finite()), "{kind}");
    }
}

/// A stated observation the simulator has no view of is refused, naming
/// the key and the views there are.
#[test]
fn an_unknown_observation_is_refused_naming_the_views() {
    let mut sim = SimConfig::default();
    sim.observation = Some("birdseye".to_owned());
    let e = crossroads_actor::resolve_observation(&mut sim)
        .expect_err("no such view")
        .to_string();
    assert!(
        e.contains("sim.observation") && e.contains("birdseye") && e.contains("ttg-occlusion"),
        "{e}"
    );
    assert_eq!(sim.layout(), None);
}

/// The share of exploring Creep episodes (epsilon 0.4) on occluded that
/// creep to the creep limit before they end, under a greedy choice of
/// `greedy` (a Q row) and uniform or absorbing-go exploration.
fn creep_limit_share(greedy: [f32; 3], absorbing: bool) -> f64 {
    use crossroads_actor::{AbsorbingGo, EpsilonGreedy, Ladder};
    use crossroads_sim::{ActionSet, Env, EnvConfig, Scenario};
    let scenario = std::sync::Arc::new(Scenario::load("occluded").expect("built-in scenario"));
    let limit = scenario.spec().ego.creep_limit_s;
    let step_limit = scenario.spec().step_limit;
    let mut env = Env::new(
        std::sync::Arc::clone(&scenario),
        EnvConfig::for_actions(ActionSet::Creep),
    );
    let mode = Mode::Explore {
        ladder: Ladder::constant(0.4, 1),
    };
    let mut explorer = EpsilonGreedy::new(mode, 1, 11);
    if absorbing {
        explorer = explorer.with_absorbing_go(AbsorbingGo {
            action: 2,
            step_limit,
        });
    }
    let episodes = 200;
    let mut reached = 0;
    for seed in 0..episodes {
        env.reset(seed);
        let mut at_limit = false;
        while !env.is_done() {
            let mut a = [0];
            explorer.choose(&greedy, 3, &[env.steps()], &[env.ego().v], &mut a);
            env.step(a[0]).expect("valid action");
            at_limit |= env.ego().s >= limit - 0.05 && !env.ego().committed;
        }
        reached += usize::from(at_limit);
    }
    reached as f64 / episodes as f64
}

#[test]
fn exploring_creep_episodes_reach_the_creep_limit() {
    // Uniform exploration: a random go (13 % of decisions) ends most
    // episodes before the ego has crept the 2.5 m to the limit, whether the
    // greedy choice is to wait or to creep.
    let wait = [1.0, 0.0, 0.0];
    let creep = [0.0, 1.0, 0.0];
    let uniform = (
        creep_limit_share(wait, false),
        creep_limit_share(creep, false),
    );
    assert!(
        uniform.0 < 0.05 && uniform.1 < 0.4,
        "uniform exploration reaches the limit in {uniform:?} of episodes"
    );
    // Go explored once per episode at a uniform step: most episodes get
    // there (and then wait at the limit, where the gaps are judged).
    let once = (
        creep_limit_share(wait, true),
        creep_limit_share(creep, true),
    );
    eprintln!(
        "share of exploring episodes at the creep limit (greedy wait, greedy creep): uniform {uniform:?}, go once {once:?}"
    );
    assert!(
        once.0 > 0.7 && once.1 > 0.8,
        "absorbing-go exploration reaches the limit in {once:?} of episodes"
    );
}

/// Shares of 400 exploring Sequential episodes on `occluded` (epsilon
/// 0.4; greedy: decelerate, the stalled network's choice) that reached the
/// goal, and that collided, with uniform random accelerations or with
/// intents held 10 decisions on average.
fn sequential_exploring_outcomes(intents: bool) -> (f64, f64) {
    use crossroads_actor::{EpsilonGreedy, Intents, Ladder};
    use crossroads_sim::{ActionSet, Env, EnvConfig, Outcome, Scenario};
    let scenario = std::sync::Arc::new(Scenario::load("occluded").expect("built-in scenario"));
    let creep_speed = scenario.spec().ego.params.creep_speed;
    let mut env = Env::new(
        std::sync::Arc::clone(&scenario),
        EnvConfig::for_actions(ActionSet::Sequential),
    );
    let mode = Mode::Explore {
        ladder: Ladder::constant(0.4, 1),
    };
    let mut explorer = EpsilonGreedy::new(mode, 1, 11);
    if intents {
        explorer = explorer.with_intents(Intents {
            set: ActionSet::Sequential,
            creep_speed,
            mean_hold: 10.0,
        });
    }
    let mut greedy = [0.0f32; 12];
    greedy[1] = 1.0;
    let episodes = 400;
    let (mut reached, mut collided) = (0, 0);
    for seed in 0..episodes {
        env.reset(seed);
        while !env.is_done() {
            let mut a = [0];
            explorer.choose(&greedy, 12, &[env.steps()], &[env.ego().v], &mut a);
            env.step(a[0]).expect("valid action");
        }
        reached += usize::from(env.outcome() == Some(Outcome::Success));
        collided += usize::from(env.outcome() == Some(Outcome::Collision));
    }
    let n = episodes as f64;
    (reached as f64 / n, collided as f64 / n)
}

#[test]
fn exploring_sequential_episodes_reach_the_goal_with_intents() {
    // Where the stalled network's greedy choice is to brake, uniform
    // random accelerations rarely string together the seconds of
    // accelerating a crossing takes, and drift the ego into the lanes
    // instead: 3.5 % of exploring episodes see the goal's reward, 96.5 %
    // collide. Held intents (a go held to the episode's end, as an
    // absorbing go) see it five times as often (17.5 %).
    let uniform = sequential_exploring_outcomes(false);
    let held = sequential_exploring_outcomes(true);
    eprintln!(
        "exploring Sequential episodes (reached the goal, collided): uniform {uniform:?}, intents {held:?}"
    );
    assert!(
        held.0 > 3.0 * uniform.0 && held.0 > uniform.0 + 0.1,
        "uniform {uniform:?}, intents {held:?}"
    );
}

#[test]
fn intents_that_cannot_creep_are_refused_by_name() {
    let mut config = actor_config(4, 64);
    config.explore_intents = true;
    let e = ActorSettings::from_config(&SimConfig::default(), &config, 0)
        .expect_err("ttg cannot creep")
        .to_string();
    assert!(
        e.contains("actor.explore_intents") && e.contains("ttg"),
        "{e}"
    );
    config.intent_hold = 0.5;
    let problems = config.validate();
    assert!(
        problems.iter().any(|(key, _)| key == "actor.intent_hold"),
        "{problems:?}"
    );
}

/// Steps `a` for `steps` steps and tallies the episodes that end.
fn tally(
    a: &mut crossroads_actor::Actor,
    values: &mut crate::util::LinearValues,
    steps: usize,
) -> EpisodeStats {
    let mut stats = EpisodeStats::default();
    for _ in 0..steps {
        let summary = a.step(values).expect("step");
        summary.episodes.iter().for_each(|e| stats.record(e));
        while a.take_batch().is_some() {}
    }
    stats
}

/// `actor.early_demo_envs`: the demonstrating environments drive by the
/// rule (TTC at 1.5 s, which never collides on left) for the first
/// `early_demo_steps` steps, then by the network like the rest (this
/// linear network waits out every episode).
#[test]
fn demonstrating_environments_follow_the_rule_then_the_network() {
    let mut plain = actor_config(4, 64);
    plain.epsilon_base = 0.0;
    let (mut a, mut values) = actor(&plain, 0);
    let network = tally(&mut a, &mut values, 1_500);
    assert!(
        network.successes == 0 && network.timeouts > 0,
        "the linear network waits on its own: {network:?}"
    );
    let mut config = plain.clone();
    config.early_demo_envs = 4;
    config.early_demo_steps = 1_500;
    config.demo_policy = Some("ttc:1.5".to_owned());
    let (mut a, mut values) = actor(&config, 0);
    assert!(a.settings().demonstrations.is_some());
    let shown = tally(&mut a, &mut values, 1_500);
    eprintln!("network alone {network:?}; demonstrating {shown:?}");
    assert!(
        shown.collisions == 0 && shown.successes > 100,
        "the rule drives: {shown:?}"
    );
    // Episodes the rule had started finish; then the network drives.
    tally(&mut a, &mut values, 200);
    let after = tally(&mut a, &mut values, 1_500);
    assert!(
        after.successes == 0 && after.timeouts > 0,
        "the network drives again: {after:?}"
    );
    // Evaluating actors never demonstrate.
    config.eval = true;
    let settings = ActorSettings::from_config(&SimConfig::default(), &config, 0).expect("settings");
    assert!(settings.demonstrations.is_none());
}

#[test]
fn a_demonstration_rule_that_cannot_drive_is_refused_by_name() {
    let mut config = actor_config(4, 64);
    config.early_demo_envs = 2;
    config.early_demo_steps = 100;
    for (rule, expected) in [
        ("ttc-creep:3", "actor.demo_policy"),
        ("random", "demonstrates nothing"),
        ("ttc:x", "actor.demo_policy"),
    ] {
        config.demo_policy = Some(rule.to_owned());
        let e = ActorSettings::from_config(&SimConfig::default(), &config, 0)
            .expect_err(rule)
            .to_string();
        assert!(e.contains(expected), "{rule}: {e}");
    }
    config.demo_policy = None;
    let problems = config.validate();
    assert!(
        problems.iter().any(|(key, _)| key == "actor.demo_policy"),
        "{problems:?}"
    );
    config.demo_policy = Some("ttc:1.5".to_owned());
    config.early_demo_envs = 5;
    let problems = config.validate();
    assert!(
        problems
            .iter()
            .any(|(key, _)| key == "actor.early_demo_envs"),
        "{problems:?}"
    );
}

/// `actor.shield`: a network that always wants to go acts through the
/// shield. No episode collides; every veto is counted and its *go* stored
/// beside the executed wait as a transition of its own, which bootstraps
/// (a real *go* ends the episode) and earns the wait's reward less
/// `actor.veto_cost`. Without the shield the same network collides.
#[test]
fn a_shield_in_the_loop_replaces_vetoed_gos_and_stores_them_with_their_cost() {
    let run = |shield: Option<&str>| {
        let mut config = actor_config(4, 64);
        config.epsilon_base = 0.0;
        config.shield = shield.map(str::to_owned);
        config.veto_cost = 0.5;
        let (mut a, mut values) = actor(&config, 0);
        // Go (action 0) first everywhere.
        values.bias = vec![1.0, 0.0, 0.0, 0.0, 0.0];
        values.scale = vec![0.0; 5];
        let mut stats = EpisodeStats::default();
        let mut kept_gos = Vec::new();
        for _ in 0..600 {
            let summary = a.step(&mut values).expect("step");
            summary.episodes.iter().for_each(|e| stats.record(e));
            while let Some(b) = a.take_batch() {
                let c = &b.columns;
                for k in 0..c.actions.len() {
                    if c.actions[k] == 0 && c.discounts[k] > 0.0 {
                        kept_gos.push((c.rewards[k], c.priorities[k]));
                    }
                }
            }
        }
        (stats, a.metrics().shield_vetoes.get(), kept_gos)
    };
    let (bare, vetoes, kept) = run(None);
    assert!(bare.collisions > 0, "going at once collides: {bare:?}");
    assert_eq!((vetoes, kept.len()), (0, 0));

    let (shielded, vetoes, kept) = run(Some("default"));
    eprintln!(
        "shielded {shielded:?}, {vetoes} vetoes, {} kept",
        kept.len()
    );
    assert_eq!(shielded.collisions, 0, "{shielded:?}");
    assert!(shielded.successes > 0, "{shielded:?}");
    assert!(vetoes > 0);
    assert!(!kept.is_empty() && kept.len() as u64 <= vetoes);
    for (reward, priority) in kept {
        // One step of waiting earns the step reward, -0.01.
        assert!((reward - (-0.01 - 0.5)).abs() < 1e-5, "{reward}");
        // |Q(wait) - cost - Q(go)| = |0 - 0.5 - 1|.
        assert!((priority - 1.5).abs() < 1e-5, "{priority}");
    }
}

/// `actor.go_forks`: a network that never goes still has its Q(go)
/// labelled. Every decision forks its environment, runs the *go* to its
/// end there and stores it from the decision's observation with the fork's
/// return, ending the episode (discount 0): successes and collisions both,
/// each counted. Without forks the same network stores no *go*.
#[test]
fn go_forks_label_the_go_a_waiting_network_never_takes() {
    let run = |share: f64| {
        let mut config = actor_config(4, 64);
        config.epsilon_base = 0.0;
        config.go_forks = share;
        let (mut a, mut values) = actor(&config, 0);
        // Wait (action 1) first everywhere: the network never goes.
        values.bias = vec![0.0, 1.0, 0.0, 0.0, 0.0];
        values.scale = vec![0.0; 5];
        let mut gos = Vec::new();
        let mut decisions = 0;
        for _ in 0..300 {
            decisions += a.step(&mut values).expect("step").decisions;
            while let Some(b) = a.take_batch() {
                let c = &b.columns;
                for k in 0..c.actions.len() {
                    if c.actions[k] == 0 {
                        gos.push((c.rewards[k], c.discounts[k], c.priorities[k]));
                    }
                }
            }
        }
        (gos, a.metrics().go_forks.get(), decisions)
    };
    let (gos, forked, _) = run(0.0);
    assert_eq!((gos.len(), forked), (0, 0));

    let (gos, forked, decisions) = run(1.0);
    eprintln!(
        "{} forked gos stored of {forked} run in {decisions} decisions",
        gos.len()
    );
    // A decision forks before its step: the last one's forks are run, its
    // step not yet taken (up to one per environment).
    assert!(
        forked > 0 && forked <= decisions + 4,
        "{forked} > {decisions} + 4"
    );
    // Stored in batches of 64: all but the last partial batch.
    assert!(gos.len() as u64 <= forked && gos.len() as u64 + 64 > forked);
    let successes = gos.iter().filter(|(r, _, _)| *r > 0.0).count();
    let collisions = gos.iter().filter(|(r, _, _)| *r < -1.0).count();
    assert!(
        successes > 0 && collisions > 0,
        "{successes} successes, {collisions} collisions"
    );
    for (reward, discount, priority) in gos {
        assert_eq!(discount, 0.0);
        // |return - Q(go)| with Q(go) = 0.
        assert!(
            (priority - reward.abs()).abs() < 1e-5,
            "{reward} {priority}"
        );
    }
}

/// Why an actor of `config` with Sequential actions is refused.
fn refusal_on_sequential(config: &ActorConfig) -> String {
    let mut sequential = SimConfig::default();
    sequential.action_set = "sequential".to_owned();
    ActorSettings::from_config(&sequential, config, 0)
        .expect_err("sequential")
        .to_string()
}

#[test]
fn go_forks_that_cannot_fork_are_refused_by_name() {
    let mut config = actor_config(4, 64);
    config.go_forks = 0.1;
    let e = refusal_on_sequential(&config);
    assert!(
        e.contains("actor.go_forks") && e.contains("sequential"),
        "{e}"
    );
    config.go_forks = 1.5;
    let problems = config.validate();
    assert!(
        problems.iter().any(|(key, _)| key == "actor.go_forks"),
        "{problems:?}"
    );
}

#[test]
fn a_shield_that_cannot_check_is_refused_by_name() {
    let mut config = actor_config(4, 64);
    config.shield = Some("wings=2".to_owned());
    let e = ActorSettings::from_config(&SimConfig::default(), &config, 0)
        .expect_err("unknown key")
        .to_string();
    assert!(e.contains("actor.shield") && e.contains("wings"), "{e}");
    config.shield = Some("default".to_owned());
    let e = refusal_on_sequential(&config);
    assert!(
        e.contains("actor.shield") && e.contains("sequential"),
        "{e}"
    );
    config.veto_cost = -1.0;
    let problems = config.validate();
    assert!(
        problems.iter().any(|(key, _)| key == "actor.veto_cost"),
        "{problems:?}"
    );
}

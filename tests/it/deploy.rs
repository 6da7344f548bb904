//! deploy/ as an operator uses it: the image built from the local base,
//! `docker compose up` training through real containers, Debian's
//! Prometheus scraping them with deploy/prometheus.yml, the dashboards'
//! metric names, and the Kubernetes manifests rendered by kustomize and
//! checked against the Kubernetes schemas.
//!
//! Docker, debootstrap, prometheus/promtool and kubectl come from
//! scripts/setup-deploy.sh (run by `make test`); the schema validator from
//! scripts/requirements-test.txt. The tests that need them are ignored
//! unless asked for (`cargo test -- --include-ignored`, as `make test`
//! runs them); asked for without the tools, they fail naming what is
//! missing if CROSSROADS_REQUIRE_DOCKER=1 (as `make test` sets), and
//! otherwise say so and return. The dashboards' check needs nothing and
//! always runs.

use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use crossroads_harness::train::sum_metric;
use crossroads_test_support::gates::{self, Need};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Whether `program args` runs and exits 0; when it does not, fails the
/// test if the deploy tools are required, else prints why it is skipped.
fn have(program: &str, args: &[&str]) -> bool {
    let ok = Command::new(program)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        gates::skip_unless_required(
            Need::Docker,
            &format!(
                "`{program} {}` is not available; scripts/setup-deploy.sh installs the deploy tools",
                args.join(" ")
            ),
        );
    }
    ok
}

fn run(cmd: &mut Command) -> Output {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    assert!(
        out.status.success(),
        "{cmd:?}: {}\n{}{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn text(out: &Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

// ---------------------------------------------------------------------------
// Dashboards

/// Every `crossroads_*` name in a string literal of the workspace's sources
/// (tests excluded): the metrics the code registers.
fn exported_metric_names() -> BTreeSet<String> {
    let re = regex::Regex::new(r#""(crossroads_[a-z0-9_]+)""#).expect("regex");
    let mut names = BTreeSet::new();
    for dir in [
        "src",
        "actor/src",
        "replay/src",
        "learner/src",
        "common/src",
    ] {
        let mut stack = vec![repo().join(dir)];
        while let Some(d) = stack.pop() {
            for entry in std::fs::read_dir(&d).expect("read source dir").flatten() {
                let path = entry.path();
                if path.is_dir() {
                    stack.push(path);
                } else if path.extension().is_some_and(|e| e == "rs") {
                    let code = std::fs::read_to_string(&path).expect("read source");
                    names.extend(re.captures_iter(&code).map(|c| c[1].to_owned()));
                }
            }
        }
    }
    names
}

fn exprs(value: &serde_json::Value, out: &mut Vec<String>) {
    match value {
        serde_json::Value::Object(map) => {
            for (k, v) in map {
                match (k.as_str(), v) {
                    ("expr" | "query", serde_json::Value::String(s)) => out.push(s.clone()),
                    _ => exprs(v, out),
                }
            }
        }
        serde_json::Value::Array(items) => items.iter().for_each(|v| exprs(v, out)),
        _ => {}
    }
}

/// The metric names a PromQL expression refers to, histogram suffixes
/// folded into their histogram's name when the code exports that.
fn referenced(expr: &str, exported: &BTreeSet<String>) -> Vec<String> {
    let re = regex::Regex::new(r"crossroads_[a-z0-9_]+").expect("regex");
    re.find_iter(expr)
        .map(|m| {
            let name = m.as_str();
            ["_bucket", "_sum", "_count"]
                .iter()
                .find_map(|s| {
                    name.strip_suffix(s)
                        .filter(|base| exported.contains(*base) && !exported.contains(name))
                })
                .unwrap_or(name)
                .to_owned()
        })
        .collect()
}

/// Every dashboard file with its PromQL queries.
fn dashboard_queries() -> Vec<(PathBuf, Vec<String>)> {
    let dir = repo().join("deploy/grafana/dashboards");
    let mut out = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("dashboards").flatten() {
        let path = entry.path();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).expect("read"))
                .unwrap_or_else(|e| panic!("{}: not JSON: {e}", path.display()));
        let mut found = Vec::new();
        exprs(&json, &mut found);
        out.push((path, found));
    }
    out.sort();
    out
}

#[test]
fn dashboards_reference_only_metrics_the_code_exports() {
    let exported = exported_metric_names();
    for known in [
        "crossroads_replay_size_items",
        "crossroads_learner_updates_total",
        "crossroads_actor_weights_version",
    ] {
        assert!(exported.contains(known), "the scan finds {known}");
    }
    let mut dashboards = 0;
    let mut used = BTreeSet::new();
    for (path, found) in dashboard_queries() {
        assert!(!found.is_empty(), "{} has no queries", path.display());
        for expr in found {
            for name in referenced(&expr, &exported) {
                assert!(
                    exported.contains(&name),
                    "{}: {name} (in {expr:?}) is not a metric the code exports",
                    path.display()
                );
                used.insert(name);
            }
        }
        dashboards += 1;
    }
    assert_eq!(dashboards, 4, "training, throughput, replay, weights");
    // The issue's panels: progress, throughput, replay, weights, errors.
    for needed in [
        "crossroads_actor_episodes_total",
        "crossroads_actor_env_steps_total",
        "crossroads_replay_inserts_total",
        "crossroads_replay_samples_total",
        "crossroads_learner_updates_total",
        "crossroads_replay_size_items",
        "crossroads_replay_rate_limiter_waits_total",
        "crossroads_actor_weights_version",
        "crossroads_actor_weights_staleness_seconds",
        "crossroads_replay_rejections_total",
    ] {
        assert!(used.contains(needed), "no dashboard shows {needed}");
    }
    // And the check itself catches a name the code does not export.
    assert_eq!(
        referenced("rate(crossroads_actor_nonsense_total[1m])", &exported),
        ["crossroads_actor_nonsense_total"]
    );
    assert!(!exported.contains("crossroads_actor_nonsense_total"));
}

// ---------------------------------------------------------------------------
// Kubernetes

fn validator() -> PathBuf {
    repo().join(".venv/bin/kubernetes-validate")
}

#[test]
#[ignore = "needs kubectl and kubernetes-validate (scripts/setup-deploy.sh, scripts/setup-python.sh): \
            CROSSROADS_REQUIRE_DOCKER=1 cargo test -- --include-ignored"]
fn kubernetes_manifests_render_with_kustomize_and_match_the_schemas() {
    if !have("kubectl", &["version", "--client"]) {
        return;
    }
    if !validator().exists() {
        gates::skip_unless_required(
            Need::Docker,
            &format!(
                "{} is missing; scripts/setup-python.sh installs it",
                validator().display()
            ),
        );
        return;
    }
    let k8s = repo().join("deploy/k8s");
    let rendered = text(&run(Command::new("kubectl").arg("kustomize").arg(&k8s)));
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("rendered.yaml");
    std::fs::write(&file, &rendered).expect("write");
    let out = run(Command::new(validator())
        .args(["--strict", "--no-warn"])
        .arg(&file));
    let report = format!("{}{}", text(&out), String::from_utf8_lossy(&out.stderr));
    let kinds: BTreeMap<&str, usize> = ["configmap/", "service/", "statefulset/", "deployment/"]
        .into_iter()
        .map(|k| (k, report.matches(&format!("resource {k}")).count()))
        .collect();
    assert_eq!(
        kinds,
        BTreeMap::from([
            ("configmap/", 1),
            ("deployment/", 2),
            ("service/", 2),
            ("statefulset/", 2)
        ]),
        "{report}"
    );
    assert!(!report.contains("failed"), "{report}");

    // Replay and learner keep their state on persistent volumes; pods are
    // annotated for Prometheus; actors scale as a Deployment whose replica
    // count is the ladder's N in the config.
    assert_eq!(rendered.matches("volumeClaimTemplates:").count(), 2);
    assert_eq!(
        rendered.matches("prometheus.io/scrape: \"true\"").count(),
        4
    );
    let replicas = rendered
        .split("\n---\n")
        .find(|d| d.contains("name: crossroads-actor\n") && d.contains("kind: Deployment"))
        .and_then(|d| d.lines().find_map(|l| l.trim().strip_prefix("replicas: ")))
        .expect("the actor Deployment's replicas")
        .to_owned();
    let config = repo().join("deploy/k8s/config.toml");
    let shown = text(&run(crate::crossroads()
        .command()
        .arg("--config")
        .arg(&config)
        .args(["--experiment", "ttg-left", "config", "show"])));
    let shown: toml::Value = toml::from_str(&shown).expect("TOML");
    assert_eq!(
        shown["actor"]["count"].as_integer().map(|n| n.to_string()),
        Some(replicas),
        "config.toml's [actor] count equals the actor replicas"
    );

    // The validator is not a rubber stamp: a misspelt field fails.
    let broken = rendered.replacen("containerPort:", "containerPrt:", 1);
    std::fs::write(&file, broken).expect("write");
    let out = Command::new(validator())
        .args(["--strict", "--no-warn"])
        .arg(&file)
        .output()
        .expect("validator");
    assert!(!out.status.success(), "a misspelt field passes");
}

// ---------------------------------------------------------------------------
// Compose

/// `docker compose` when the plugin is there, else `docker-compose`.
fn compose_program() -> Option<Vec<String>> {
    let works = |p: &[&str]| {
        Command::new(p[0])
            .args(&p[1..])
            .arg("version")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    [&["docker", "compose"][..], &["docker-compose"][..]]
        .into_iter()
        .find(|p| works(p))
        .map(|p| p.iter().map(|s| (*s).to_owned()).collect())
}

/// One compose project of this test; `down -v` when dropped, so a failing
/// test leaves nothing running.
struct Project {
    program: Vec<String>,
    name: String,
    files: Vec<PathBuf>,
    env: Vec<(String, String)>,
}

impl Project {
    fn command(&self, args: &[&str]) -> Command {
        let mut c = Command::new(&self.program[0]);
        c.args(&self.program[1..]).arg("-p").arg(&self.name);
        for f in &self.files {
            c.arg("-f").arg(f);
        }
        c.args(args).current_dir(repo());
        for (k, v) in &self.env {
            c.env(k, v);
        }
        c
    }

    /// Containers of the project by service: (id, address on its network).
    fn containers(&self) -> BTreeMap<String, Vec<(String, String)>> {
        let ids = text(&run(Command::new("docker").args([
            "ps",
            "-q",
            "--filter",
            &format!("label=com.docker.compose.project={}", self.name),
        ])));
        let mut by_service: BTreeMap<String, Vec<(String, String)>> = BTreeMap::new();
        for id in ids.split_whitespace() {
            let line = text(&run(Command::new("docker").args([
                "inspect",
                "-f",
                "{{index .Config.Labels \"com.docker.compose.service\"}} \
                 {{range .NetworkSettings.Networks}}{{.IPAddress}}{{end}}",
                id,
            ])));
            let mut parts = line.split_whitespace();
            if let (Some(service), Some(ip)) = (parts.next(), parts.next()) {
                by_service
                    .entry(service.to_owned())
                    .or_default()
                    .push((id.to_owned(), ip.to_owned()));
            }
        }
        by_service
    }

    fn leftovers(&self) -> String {
        let label = format!("label=com.docker.compose.project={}", self.name);
        let containers = text(&run(
            Command::new("docker").args(["ps", "-aq", "--filter", &label])
        ));
        let volumes = text(&run(
            Command::new("docker").args(["volume", "ls", "-q", "--filter", &label])
        ));
        let networks = text(&run(
            Command::new("docker").args(["network", "ls", "-q", "--filter", &label])
        ));
        format!("{containers}{volumes}{networks}")
    }
}

impl Drop for Project {
    fn drop(&mut self) {
        let _ = self.command(&["down", "-v", "--timeout", "20"]).output();
    }
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime")
}

/// The sum of `name`'s samples in a scrape, when it has any.
fn sample(text: &str, name: &str) -> Option<f64> {
    text.contains(name).then(|| sum_metric(text, name))
}

fn scrape(rt: &tokio::runtime::Runtime, ip: &str) -> String {
    let addr: SocketAddr = format!("{ip}:9100").parse().expect("address");
    rt.block_on(crossroads_common::metrics::scrape(
        addr,
        Duration::from_secs(5),
    ))
    .unwrap_or_default()
}

/// Polls `probe` until it returns `Some`, at most `limit`.
fn wait_for<T>(what: &str, limit: Duration, mut probe: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    loop {
        if let Some(v) = probe() {
            eprintln!(
                "deploy: {what} after {:.0} s",
                start.elapsed().as_secs_f64()
            );
            return v;
        }
        assert!(start.elapsed() < limit, "no {what} within {limit:?}");
        std::thread::sleep(Duration::from_secs(2));
    }
}

/// deploy/prometheus.yml with the compose names replaced by the
/// containers' addresses (Prometheus runs on the host, outside the compose
/// network's DNS) and the evaluator's job left out (it is in the
/// monitoring profile, not started here).
fn prometheus_config(replay: &str, learner: &str, actors: &[String]) -> String {
    let original = std::fs::read_to_string(repo().join("deploy/prometheus.yml")).expect("read");
    let dns_sd = "    dns_sd_configs:\n      - names: ['actor']\n        type: A\n        port: 9100\n        refresh_interval: 15s\n";
    let evaluator_at = original
        .find("  # The greedy evaluator")
        .expect("evaluator job");
    let mut config = original[..evaluator_at].to_owned();
    for (from, to) in [
        ("'replay:9100'", format!("'{replay}:9100'")),
        ("'learner:9100'", format!("'{learner}:9100'")),
        (
            dns_sd,
            format!(
                "    static_configs:\n      - targets: [{}]\n",
                actors
                    .iter()
                    .map(|ip| format!("'{ip}:9100'"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ),
    ] {
        assert!(config.contains(from), "deploy/prometheus.yml has {from:?}");
        config = config.replace(from, &to);
    }
    config
}

fn start_prometheus(config: &Path, data: &Path, port: u16) -> Child {
    Command::new("prometheus")
        .arg(format!("--config.file={}", config.display()))
        .arg(format!("--storage.tsdb.path={}", data.display()))
        .arg(format!("--web.listen-address=127.0.0.1:{port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("start prometheus")
}

/// (job, health) of every active target Prometheus reports.
fn targets(rt: &tokio::runtime::Runtime, port: u16) -> Vec<(String, String)> {
    let addr: SocketAddr = ([127, 0, 0, 1], port).into();
    let Ok(body) = rt.block_on(crossroads_common::metrics::get(
        addr,
        "/api/v1/targets?state=active",
        Duration::from_secs(5),
    )) else {
        return Vec::new();
    };
    let json: serde_json::Value = serde_json::from_str(&body).unwrap_or_default();
    json["data"]["activeTargets"]
        .as_array()
        .map(|ts| {
            ts.iter()
                .map(|t| {
                    (
                        t["labels"]["job"].as_str().unwrap_or("").to_owned(),
                        t["health"].as_str().unwrap_or("").to_owned(),
                    )
                })
                .collect()
        })
        .unwrap_or_default()
}

/// Runs `query` on Prometheus: `Err` with its message when Prometheus
/// refuses it, else whether the result holds any series.
fn query(rt: &tokio::runtime::Runtime, port: u16, query: &str) -> Result<bool, String> {
    use percent_encoding::{NON_ALPHANUMERIC, utf8_percent_encode};
    let addr: SocketAddr = ([127, 0, 0, 1], port).into();
    let path = format!(
        "/api/v1/query?query={}",
        utf8_percent_encode(query, NON_ALPHANUMERIC)
    );
    let body = rt.block_on(crossroads_common::metrics::get(
        addr,
        &path,
        Duration::from_secs(10),
    ))?;
    let json: serde_json::Value = serde_json::from_str(&body).map_err(|e| e.to_string())?;
    if json["status"] != "success" {
        return Err(body);
    }
    Ok(json["data"]["result"]
        .as_array()
        .is_some_and(|r| !r.is_empty()))
}

#[test]
#[ignore = "needs Docker with Compose and prometheus (scripts/setup-deploy.sh): \
            CROSSROADS_REQUIRE_DOCKER=1 cargo test -- --include-ignored"]
fn compose_trains_through_real_containers_and_prometheus_scrapes_them() {
    if !have("docker", &["info"]) || !have("prometheus", &["--version"]) {
        return;
    }
    let Some(program) = compose_program() else {
        gates::skip_unless_required(
            Need::Docker,
            "neither `docker compose` nor `docker-compose` works",
        );
        return;
    };
    // promtool accepts the shipped Prometheus config as it is.
    run(Command::new("promtool")
        .args(["check", "config", "--syntax-only"])
        .arg(repo().join("deploy/prometheus.yml")));

    // The image, from the local base and this test build's binary.
    let tag = format!("crossroads:test-{}", std::process::id());
    run(Command::new(repo().join("deploy/build-image.sh"))
        .arg(&tag)
        .env("CROSSROADS_BIN", crate::crossroads().bin()));
    let _image = RemoveImage(tag.clone());

    // Every role in the image runs with the load-time settings the binary
    // gives itself where the user set none (libgomp's idle threads asleep,
    // glibc keeping its heap): `doctor` inside a container sees what it
    // sees on the host with both variables unset.
    let json = |out: Output| -> serde_json::Value {
        serde_json::from_slice(&out.stdout).expect("doctor JSON")
    };
    let inside = json(run(
        Command::new("docker").args(["run", "--rm", &tag, "doctor", "--json"])
    ));
    let host = json(run(crate::crossroads()
        .command()
        .args(["doctor", "--json"])
        .env_remove("OMP_WAIT_POLICY")
        .env_remove("GLIBC_TUNABLES")));
    assert_eq!(inside["openmp_wait_policy"], "passive", "{inside}");
    for key in ["openmp_wait_policy", "glibc_tunables"] {
        assert_eq!(inside[key], host[key], "{key}: {inside} against {host}");
    }

    // Small settings so a debug build trains within a minute on 2 cores.
    let dir = tempfile::tempdir().expect("temp dir");
    let overrides = dir.path().join("test.yaml");
    std::fs::write(
        &overrides,
        "x-small: &small\n  CROSSROADS_RUNTIME__COMPUTE_THREADS: \"1\"\n  \
         CROSSROADS_LEARNER__TRUNK: \"mlp\"\n  CROSSROADS_LEARNER__HIDDEN: \"[64, 64]\"\n  \
         CROSSROADS_LEARNER__BATCH_SIZE: \"32\"\n  \
         CROSSROADS_ACTOR__ENVS: \"4\"\n  CROSSROADS_REPLAY__SAMPLES_PER_INSERT: \"1.0\"\n\
         services:\n  replay: {environment: *small}\n  learner: {environment: *small}\n  \
         actor: {environment: *small}\n",
    )
    .expect("write override");
    let learner_port = free_port();
    let project = Project {
        program,
        name: format!("crossroads-test-{}", std::process::id()),
        files: vec![repo().join("deploy/compose.yaml"), overrides],
        env: vec![
            ("CROSSROADS_IMAGE".into(), tag.clone()),
            ("ACTORS".into(), "2".into()),
            ("MIN_SIZE_TO_SAMPLE".into(), "500".into()),
            ("LEARNER_PORT".into(), learner_port.to_string()),
        ],
    };
    run(&mut project.command(&["up", "-d", "--scale", "actor=2"]));

    let rt = runtime();
    let containers = wait_for("four running containers", Duration::from_secs(120), || {
        let c = project.containers();
        let count = |s: &str| c.get(s).map_or(0, Vec::len);
        (count("replay") == 1 && count("learner") == 1 && count("actor") == 2).then_some(c)
    });
    let ip = |s: &str| containers[s][0].1.clone();
    let actors: Vec<String> = containers["actor"]
        .iter()
        .map(|(_, ip)| ip.clone())
        .collect();

    // Training through the containers: the replay fills, the learner
    // updates, both actors act on newer weights, on their own epsilons.
    let size = |rt: &tokio::runtime::Runtime| {
        sample(&scrape(rt, &ip("replay")), "crossroads_replay_size_items")
    };
    let first_size = wait_for("a filling replay", Duration::from_secs(180), || {
        size(&rt).filter(|&s| s > 0.0)
    });
    let updates = |rt: &tokio::runtime::Runtime| {
        sample(
            &scrape(rt, &ip("learner")),
            "crossroads_learner_updates_total",
        )
    };
    let first_updates = wait_for("learner updates", Duration::from_secs(180), || {
        updates(&rt).filter(|&u| u > 0.0)
    });
    let versions = wait_for(
        "weights v3+ at both actors",
        Duration::from_secs(180),
        || {
            let v: Vec<f64> = actors
                .iter()
                .filter_map(|a| sample(&scrape(&rt, a), "crossroads_actor_weights_version"))
                .collect();
            (v.len() == 2 && v.iter().all(|&v| v >= 3.0)).then_some(v)
        },
    );
    let later_updates = wait_for("more learner updates", Duration::from_secs(120), || {
        updates(&rt).filter(|&u| u > first_updates)
    });
    let later_size = wait_for("a larger replay", Duration::from_secs(120), || {
        size(&rt).filter(|&s| s > first_size)
    });
    let mut epsilons: Vec<f64> = actors
        .iter()
        .filter_map(|a| sample(&scrape(&rt, a), "crossroads_actor_epsilon"))
        .collect();
    epsilons.sort_by(f64::total_cmp);
    // The ladder runs over 2 actors x 4 environments; the gauge is the
    // mean of an actor's 4 rungs (actor 1 holds rungs 4..8).
    let rung = |g: i32| 0.4_f64.powf(1.0 + 7.0 * f64::from(g) / 7.0);
    let mean = |first: i32| (first..first + 4).map(rung).sum::<f64>() / 4.0;
    let ladder = [mean(4), mean(0)];
    assert!(
        epsilons.len() == 2
            && epsilons
                .iter()
                .zip(ladder)
                .all(|(e, l)| (e - l).abs() < 1e-9),
        "the two actors take indices 0 and 1 of the ladder ({ladder:?}): {epsilons:?}"
    );
    eprintln!(
        "deploy: replay {first_size} -> {later_size} items, learner {first_updates} -> \
         {later_updates} updates, actors on weights {versions:?}, epsilons {epsilons:?}"
    );

    // A checkpoint through the gRPC API from outside the containers.
    let learner_url = format!("http://127.0.0.1:{learner_port}");
    let saved = text(&run(crate::crossroads().command().args([
        "checkpoints",
        "--learner",
        &learner_url,
        "--json",
        "save",
    ])));
    let saved: serde_json::Value = serde_json::from_str(&saved).expect("save prints JSON");
    let id = saved["id"].as_str().expect("checkpoint id").to_owned();
    let listed = text(&run(crate::crossroads().command().args([
        "checkpoints",
        "--learner",
        &learner_url,
        "list",
    ])));
    assert!(
        listed.contains(&id),
        "list names the saved checkpoint {id}: {listed}"
    );
    let pulled_dir = dir.path().join("pulled");
    let pulled = text(&run(crate::crossroads()
        .command()
        .args([
            "checkpoints",
            "--learner",
            &learner_url,
            "--json",
            "pull",
            &id,
            "--out",
        ])
        .arg(&pulled_dir)));
    let pulled: serde_json::Value = serde_json::from_str(&pulled).expect("pull prints JSON");
    let folder = PathBuf::from(pulled["path"].as_str().expect("path"));
    let files = std::fs::read_dir(&folder).expect("pulled folder").count();
    assert!(files >= 2, "{} holds {files} files", folder.display());
    let eval = text(&run(crate::crossroads()
        .command()
        .args(["eval", "--scenario", "left", "--trials", "50", "--policy"])
        .arg(&folder)));
    assert!(
        eval.contains("success"),
        "the pulled checkpoint evaluates: {eval}"
    );

    // Debian's Prometheus with deploy/prometheus.yml, targets adjusted:
    // every role is up.
    let config = dir.path().join("prometheus.yml");
    std::fs::write(
        &config,
        prometheus_config(&ip("replay"), &ip("learner"), &actors),
    )
    .expect("write prometheus.yml");
    run(Command::new("promtool")
        .args(["check", "config"])
        .arg(&config));
    let port = free_port();
    let mut prometheus = start_prometheus(&config, &dir.path().join("tsdb"), port);
    let checked = std::panic::catch_unwind(|| {
        let up = wait_for("every target up", Duration::from_secs(60), || {
            let t = targets(&rt, port);
            (t.len() == 4 && t.iter().all(|(_, h)| h == "up")).then_some(t)
        });
        // Every dashboard query runs on the real Prometheus; the training
        // ones find data once a few scrapes are in (the evaluator's, in the
        // monitoring profile, have none here).
        wait_for("a minute of scrapes", Duration::from_secs(90), || {
            query(
                &rt,
                port,
                "count_over_time(crossroads_learner_updates_total[2m]) >= 4",
            )
            .ok()
            .filter(|&some| some)
        });
        let mut empty = Vec::new();
        let mut total = 0;
        for (path, exprs) in dashboard_queries() {
            for expr in exprs {
                total += 1;
                match query(&rt, port, &expr) {
                    Ok(true) => {}
                    Ok(false) => empty.push(expr),
                    Err(e) => panic!("{}: Prometheus refuses {expr:?}: {e}", path.display()),
                }
            }
        }
        (up, total, empty)
    });
    let _ = prometheus.kill();
    let _ = prometheus.wait();
    let (up, total, empty) = checked.unwrap_or_else(|e| std::panic::resume_unwind(e));
    let jobs: BTreeSet<&str> = up.iter().map(|(j, _)| j.as_str()).collect();
    assert_eq!(jobs, BTreeSet::from(["actor", "learner", "replay"]));
    eprintln!(
        "deploy: {total} dashboard queries run, {} with data; empty: {empty:#?}",
        total - empty.len()
    );
    for core in [
        "crossroads_learner_updates_total",
        "crossroads_replay_size_items",
        "crossroads_actor_env_steps_total",
        "crossroads_actor_weights_version",
    ] {
        assert!(
            !empty.iter().any(|e| e.contains(core)),
            "a dashboard query on {core} has no data: {empty:#?}"
        );
    }

    // Down with volumes: nothing of the project is left.
    run(&mut project.command(&["down", "-v", "--timeout", "20"]));
    assert_eq!(
        project.leftovers(),
        "",
        "containers, volumes or networks left"
    );

    // The same image and settings with TLS and a token.
    compose_trains_with_tls_and_a_token(project.program.clone(), &tag, &project.files[1], &rt);
}

/// `deploy/make-certs.sh`, then `docker compose -f compose.yaml -f
/// compose.tls.yaml up` (plus the test's `small` settings): the roles
/// train over mutual TLS with the token, the checkpoint CLI on the host
/// reaches the learner with the same files, and is refused without the
/// token or without TLS.
fn compose_trains_with_tls_and_a_token(
    program: Vec<String>,
    tag: &str,
    small: &Path,
    rt: &tokio::runtime::Runtime,
) {
    use std::os::unix::fs::PermissionsExt;
    let certs = make_certs();
    // The containers' user (uid 10001) reads the bind-mounted folder.
    std::fs::set_permissions(certs.path(), std::fs::Permissions::from_mode(0o755))
        .expect("chmod the certificates' folder");
    let learner_port = free_port();
    let project = Project {
        program,
        name: format!("crossroads-tls-test-{}", std::process::id()),
        files: vec![
            repo().join("deploy/compose.yaml"),
            repo().join("deploy/compose.tls.yaml"),
            small.to_path_buf(),
        ],
        env: vec![
            ("CROSSROADS_IMAGE".into(), tag.to_owned()),
            ("ACTORS".into(), "1".into()),
            ("MIN_SIZE_TO_SAMPLE".into(), "500".into()),
            ("LEARNER_PORT".into(), learner_port.to_string()),
            ("CERTS".into(), certs.path().display().to_string()),
        ],
    };
    run(&mut project.command(&["up", "-d"]));
    let containers = wait_for("three running containers", Duration::from_secs(120), || {
        let c = project.containers();
        let count = |s: &str| c.get(s).map_or(0, Vec::len);
        (count("replay") == 1 && count("learner") == 1 && count("actor") == 1).then_some(c)
    });
    let ip = |s: &str| containers[s][0].1.clone();
    // Metrics stay plain HTTP: the actor inserts over TLS and follows
    // weights the learner trained on them.
    let version = wait_for(
        "weights v2+ at the actor over TLS",
        Duration::from_secs(240),
        || {
            sample(
                &scrape(rt, &ip("actor")),
                "crossroads_actor_weights_version",
            )
            .filter(|&v| v >= 2.0)
        },
    );
    let inserted = sample(
        &scrape(rt, &ip("replay")),
        "crossroads_replay_inserts_total",
    );

    let url = format!("https://localhost:{learner_port}");
    let file = |f: &str| certs.path().join(f);
    let with = |c: &mut Command, token: bool| {
        c.env("CROSSROADS_TRANSPORT__TLS__CA_FILE", file("ca.pem"))
            .env(
                "CROSSROADS_TRANSPORT__TLS__CLIENT_CERT_FILE",
                file("client.pem"),
            )
            .env(
                "CROSSROADS_TRANSPORT__TLS__CLIENT_KEY_FILE",
                file("client.key"),
            )
            .env_remove("CROSSROADS_TOKEN");
        if token {
            c.env("CROSSROADS_TRANSPORT__AUTH__TOKEN_FILE", file("token"));
        }
    };
    let save = |tls: bool, token: bool, url: &str| {
        let mut c = crate::crossroads().command();
        c.args(["checkpoints", "--learner", url, "--json", "save"]);
        if tls {
            with(&mut c, token);
        }
        c.output().expect("run crossroads checkpoints")
    };
    let saved = save(true, true, &url);
    assert!(
        saved.status.success(),
        "save over TLS with the token: {}",
        String::from_utf8_lossy(&saved.stderr)
    );
    let saved: serde_json::Value = serde_json::from_str(&text(&saved)).expect("save prints JSON");
    assert!(saved["id"].is_string(), "{saved}");
    let refused = save(true, false, &url);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("authorization"),
        "save without the token is refused, naming what is missing: {err}"
    );
    let plain = save(false, false, &format!("http://localhost:{learner_port}"));
    assert!(!plain.status.success(), "plain HTTP to the TLS port fails");
    eprintln!(
        "deploy (TLS + token): the actor on weights v{version}, the replay took {inserted:?} \
         transitions; the CLI saved {} over mutual TLS; without the token: {}",
        saved["id"],
        err.lines().last().unwrap_or_default()
    );
    run(&mut project.command(&["down", "-v", "--timeout", "20"]));
    assert_eq!(
        project.leftovers(),
        "",
        "containers, volumes or networks left"
    );
}

struct RemoveImage(String);

impl Drop for RemoveImage {
    fn drop(&mut self) {
        let _ = Command::new("docker").args(["rmi", "-f", &self.0]).output();
    }
}

// ---------------------------------------------------------------------------
// TLS and tokens

/// The certificates `deploy/make-certs.sh` writes into a temporary folder.
fn make_certs() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("temp dir");
    run(Command::new(repo().join("deploy/make-certs.sh")).arg(dir.path()));
    dir
}

/// The TLS override over compose.yaml resolves for every role (monitoring
/// profile included): https endpoints, the files mounted read-only where
/// the settings point, and nothing else changed.
#[test]
#[ignore = "needs docker compose (scripts/setup-deploy.sh): \
            CROSSROADS_REQUIRE_DOCKER=1 cargo test -- --include-ignored"]
fn compose_tls_override_mounts_the_certificates_into_every_role() {
    let Some(program) = compose_program() else {
        gates::skip_unless_required(
            Need::Docker,
            "neither `docker compose` nor `docker-compose` works",
        );
        return;
    };
    let certs = make_certs();
    let out = run(Command::new(&program[0])
        .args(&program[1..])
        .arg("-f")
        .arg(repo().join("deploy/compose.yaml"))
        .arg("-f")
        .arg(repo().join("deploy/compose.tls.yaml"))
        .args(["--profile", "monitoring", "config"])
        .env("CERTS", certs.path())
        .env_remove("COMPOSE_FILE"));
    let config = text(&out);
    for role in ["replay", "learner", "actor", "evaluator"] {
        // The service's block: from its name at two spaces' indent to the
        // next name there (both compose generations print that layout).
        let head = format!("\n  {role}:\n");
        let start = config
            .find(&head)
            .unwrap_or_else(|| panic!("no {role}: {config}"));
        let rest = &config[start + head.len()..];
        let end = rest
            .match_indices('\n')
            .map(|(i, _)| i + 1)
            .find(|&i| {
                let line = &rest[i..];
                line.starts_with("  ") && !line.starts_with("   ") || !line.starts_with(' ')
            })
            .unwrap_or(rest.len());
        let service = &rest[..end];
        assert!(
            service.contains("CROSSROADS_TRANSPORT__REPLAY_ENDPOINT: https://replay:50051")
                && service
                    .contains("CROSSROADS_TRANSPORT__LEARNER_ENDPOINT: https://learner:50052"),
            "{role}: {service}"
        );
        for (key, file) in [
            ("TLS__CERT_FILE", "server.pem"),
            ("TLS__KEY_FILE", "server.key"),
            ("TLS__CLIENT_CA_FILE", "ca.pem"),
            ("TLS__CA_FILE", "ca.pem"),
            ("TLS__CLIENT_CERT_FILE", "client.pem"),
            ("TLS__CLIENT_KEY_FILE", "client.key"),
            ("AUTH__TOKEN_FILE", "token"),
        ] {
            let line = format!("CROSSROADS_TRANSPORT__{key}: /run/crossroads/tls/{file}");
            assert!(service.contains(&line), "{role}: no {line:?} in {service}");
            assert!(certs.path().join(file).is_file(), "{file} not made");
        }
        let source = certs.path().display().to_string();
        assert!(
            service.contains(&format!("{source}:/run/crossroads/tls:ro"))
                || (service.contains(&format!("source: {source}"))
                    && service.contains("target: /run/crossroads/tls")
                    && service.contains("read_only: true")),
            "{role}: the certificates are not mounted read-only: {service}"
        );
    }
}

/// The TLS overlay renders with kustomize, matches the schemas (with the
/// example Secret), and mounts the Secret and the settings into every
/// workload.
#[test]
#[ignore = "needs kubectl and kubernetes-validate (scripts/setup-deploy.sh, scripts/setup-python.sh): \
            CROSSROADS_REQUIRE_DOCKER=1 cargo test -- --include-ignored"]
fn kubernetes_tls_overlay_mounts_the_secret_into_every_workload() {
    if !have("kubectl", &["version", "--client"]) {
        return;
    }
    let overlay = repo().join("deploy/k8s-tls");
    let rendered = text(&run(Command::new("kubectl").arg("kustomize").arg(&overlay)));
    let workloads: Vec<&str> = rendered
        .split("\n---\n")
        .filter(|d| d.contains("kind: Deployment") || d.contains("kind: StatefulSet"))
        .collect();
    assert_eq!(workloads.len(), 4, "{rendered}");
    let env_map = rendered
        .split("\n---\n")
        .find(|d| d.contains("name: crossroads-tls-env"))
        .expect("the settings' ConfigMap");
    let env_name = env_map
        .lines()
        .find_map(|l| l.trim().strip_prefix("name: crossroads-tls-env"))
        .map(|suffix| format!("crossroads-tls-env{suffix}"))
        .expect("its name");
    assert!(
        env_map.contains("CROSSROADS_TRANSPORT__REPLAY_ENDPOINT: https://crossroads-replay:50051")
    );
    assert!(env_map.contains("CROSSROADS_TRANSPORT__AUTH__TOKEN_FILE: /etc/crossroads/tls/token"));
    for w in &workloads {
        assert!(w.contains("secretName: crossroads-tls"), "{w}");
        assert!(w.contains("mountPath: /etc/crossroads/tls"), "{w}");
        assert!(w.contains(&format!("name: {env_name}")), "{w}");
        assert!(w.contains("fsGroup: 10001"), "{w}");
    }
    if !validator().exists() {
        gates::skip_unless_required(
            Need::Docker,
            &format!(
                "{} is missing; scripts/setup-python.sh installs it",
                validator().display()
            ),
        );
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let file = dir.path().join("rendered.yaml");
    let secret = std::fs::read_to_string(overlay.join("secret.example.yaml")).expect("secret");
    std::fs::write(&file, format!("{rendered}\n---\n{secret}")).expect("write");
    let out = run(Command::new(validator())
        .args(["--strict", "--no-warn"])
        .arg(&file));
    let report = format!("{}{}", text(&out), String::from_utf8_lossy(&out.stderr));
    assert!(!report.contains("failed"), "{report}");
    assert!(report.contains("secret/crossroads-tls"), "{report}");
}

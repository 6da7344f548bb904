//! What a training run leaves behind and shows: the learning curve
//! (`curve.csv`, `curve.png`), the summary (`summary.json`), the best
//! evaluated weights (`best/`) and the `crossroads_train_*` metrics.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use crossroads_draw::plot::{Panel, Series, grid};
use prometheus::{Gauge, IntCounter, IntGauge, Registry};
use serde::{Deserialize, Serialize};

/// One greedy evaluation of one weights version.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Wall-clock seconds since the run began (across resumes).
    pub wall_seconds: f64,
    /// Learner updates.
    pub updates: u64,
    /// Simulation steps of all actors (across resumes).
    pub env_steps: u64,
    /// Transitions the replay stored.
    pub transitions: u64,
    /// The weights evaluated.
    pub weights_version: u64,
    /// Trials run.
    pub trials: u64,
    /// Fractions of the trials.
    pub success_rate: f64,
    /// Fractions of the trials.
    pub collision_rate: f64,
    /// Fractions of the trials.
    pub timeout_rate: f64,
    /// Mean time to goal of successful trials, seconds.
    pub mean_time_s: Option<f64>,
    /// Mean braking of traffic per trial, seconds.
    pub mean_brake_s: f64,
    /// The learner's loss at the time.
    pub loss: f64,
    /// Mean undiscounted return per trial under the scenario's rewards;
    /// `None` in curves written before it was recorded.
    #[serde(default)]
    pub mean_return: Option<f64>,
}

impl Evaluation {
    /// Higher is better: the mean undiscounted return per trial, the task's
    /// own objective (+1 success, -10 collision, -0.01 a step, so a timeout
    /// costs its whole episode of step rewards); used to keep the best
    /// weights. A network that never goes scores the full timeout cost,
    /// not 0: an earlier rule (success - 10 x collisions) scored a timeout
    /// as nothing and kept never-going networks over every one that tried.
    pub fn score(&self) -> f64 {
        self.mean_return.unwrap_or(f64::NEG_INFINITY)
    }

    /// A short line for the progress bar and the log.
    pub fn brief(&self) -> String {
        format!(
            "v{} {:.2}% ok {:.2}% coll {}",
            self.weights_version,
            100.0 * self.success_rate,
            100.0 * self.collision_rate,
            self.mean_time_s
                .map_or("-".to_owned(), |t| format!("{t:.2} s"))
        )
    }
}

/// When and where the target was first confirmed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Reached {
    /// The confirming evaluation (`confirm_trials` trials).
    pub evaluation: Evaluation,
}

/// Where a run stands, as `summary.json` records it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RunStatus {
    /// A session is training it.
    #[default]
    Running,
    /// It ended at its update or time budget.
    Finished,
    /// It stopped at the target (`train.stop_at_target`).
    Target,
    /// Ctrl-C or SIGTERM stopped it; `--resume` continues it.
    Stopped,
    /// A role failed; the logs say why.
    Failed,
}

impl RunStatus {
    /// Whether the run ended as planned (budget or target), so its weights
    /// are final.
    pub fn is_complete(self) -> bool {
        matches!(self, RunStatus::Finished | RunStatus::Target)
    }
}

impl std::fmt::Display for RunStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            RunStatus::Running => "running",
            RunStatus::Finished => "finished",
            RunStatus::Target => "target",
            RunStatus::Stopped => "stopped",
            RunStatus::Failed => "failed",
        })
    }
}

/// `summary.json`: the state of a run, rewritten after every evaluation
/// and at the end; `--resume` continues its clocks.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Scenario trained on.
    pub scenario: String,
    /// Action set.
    pub action_set: String,
    /// Observation the network reads.
    pub observation: String,
    /// Actor processes.
    pub actors: u32,
    /// Where the run stands.
    pub status: RunStatus,
    /// Wall-clock seconds over all sessions.
    pub wall_seconds: f64,
    /// Learner updates.
    pub updates: u64,
    /// Simulation steps over all sessions.
    pub env_steps: u64,
    /// Transitions stored by the replay (this session's server; restored
    /// snapshots included).
    pub transitions: u64,
    /// The latest evaluation.
    pub last: Option<Evaluation>,
    /// The best periodic evaluation (its weights are in `best/`).
    pub best: Option<Evaluation>,
    /// The first confirmed target, if any.
    pub reached: Option<Reached>,
    /// Machine the run used, for the record.
    pub machine: String,
}

impl Summary {
    /// Reads `summary.json` of `dir`, if there is one.
    pub fn load(dir: &Path) -> anyhow::Result<Option<Self>> {
        let path = dir.join("summary.json");
        if !path.exists() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        serde_json::from_str(&text)
            .map(Some)
            .with_context(|| format!("{} is not a run summary", path.display()))
    }

    /// Writes `summary.json` of `dir` (temporary file, then rename).
    pub fn save(&self, dir: &Path) -> anyhow::Result<()> {
        write_atomic(
            &dir.join("summary.json"),
            serde_json::to_string_pretty(self)?.as_bytes(),
        )
    }
}

/// Writes `bytes` to `path` through a temporary file and a rename, so a
/// reader never sees half a file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))
}

/// The learning curve, one CSV row per evaluation.
#[derive(Debug)]
pub struct Curve {
    path: PathBuf,
}

const HEADER: &str = "wall_seconds,updates,env_steps,transitions,weights_version,trials,success_rate,collision_rate,timeout_rate,mean_time_s,mean_brake_s,loss,mean_return";

impl Curve {
    /// `curve.csv` of `dir`, created with its header when missing.
    pub fn open(dir: &Path) -> anyhow::Result<Self> {
        let path = dir.join("curve.csv");
        if !path.exists() {
            std::fs::write(&path, format!("{HEADER}\n"))
                .with_context(|| format!("writing {}", path.display()))?;
        }
        Ok(Self { path })
    }

    /// Appends one evaluation.
    pub fn append(&self, e: &Evaluation) -> anyhow::Result<()> {
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(&self.path)
            .with_context(|| format!("opening {}", self.path.display()))?;
        writeln!(
            f,
            "{:.1},{},{},{},{},{},{:.6},{:.6},{:.6},{},{:.4},{:.6},{}",
            e.wall_seconds,
            e.updates,
            e.env_steps,
            e.transitions,
            e.weights_version,
            e.trials,
            e.success_rate,
            e.collision_rate,
            e.timeout_rate,
            e.mean_time_s.map_or(String::new(), |t| format!("{t:.4}")),
            e.mean_brake_s,
            e.loss,
            e.mean_return.map_or(String::new(), |r| format!("{r:.6}"))
        )
        .with_context(|| format!("writing {}", self.path.display()))
    }

    /// Every row so far.
    pub fn read(&self) -> anyhow::Result<Vec<Evaluation>> {
        read_curve(&self.path)
    }
}

/// Reads a `curve.csv`.
pub fn read_curve(path: &Path) -> anyhow::Result<Vec<Evaluation>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let bad = || anyhow::anyhow!("{} line {}: not a curve row", path.display(), i + 1);
        // 12 columns: a curve from before mean_return was recorded.
        if f.len() != 12 && f.len() != 13 {
            return Err(bad());
        }
        let num = |j: usize| f[j].parse::<f64>().map_err(|_| bad());
        let int = |j: usize| f[j].parse::<u64>().map_err(|_| bad());
        out.push(Evaluation {
            wall_seconds: num(0)?,
            updates: int(1)?,
            env_steps: int(2)?,
            transitions: int(3)?,
            weights_version: int(4)?,
            trials: int(5)?,
            success_rate: num(6)?,
            collision_rate: num(7)?,
            timeout_rate: num(8)?,
            mean_time_s: if f[9].is_empty() { None } else { Some(num(9)?) },
            mean_brake_s: num(10)?,
            loss: num(11)?,
            mean_return: match f.get(12) {
                Some(v) if !v.is_empty() => Some(num(12)?),
                _ => None,
            },
        });
    }
    Ok(out)
}

/// `curve.png`: greedy success, collision and timeout rates (%) against
/// wall-clock minutes, and beside them the collision rate on a
/// logarithmic axis, where 0.01-1 % can be read (0 drawn at its floor).
pub fn plot_curve(path: &Path, title: &str, rows: &[Evaluation]) -> anyhow::Result<()> {
    let collisions = Panel {
        title: "collisions (log scale; 0 % drawn at the bottom)".to_owned(),
        x_label: "wall-clock minutes".to_owned(),
        y_label: "% of greedy evaluation trials".to_owned(),
        series: vec![Series {
            label: "collision".to_owned(),
            points: rows
                .iter()
                .map(|e| (e.wall_seconds / 60.0, 100.0 * e.collision_rate))
                .collect(),
            line: true,
        }],
        log_y: true,
    };
    grid(path, None, 2, &[curve_panel(title, rows), collisions])?;
    Ok(())
}

/// The learning curve of `rows` as one panel: greedy success, collision
/// and timeout rates (%) against wall-clock minutes.
pub fn curve_panel(title: &str, rows: &[Evaluation]) -> Panel {
    let series = |label: &str, f: &dyn Fn(&Evaluation) -> f64| Series {
        label: label.to_owned(),
        points: rows
            .iter()
            .map(|e| (e.wall_seconds / 60.0, 100.0 * f(e)))
            .collect(),
        line: true,
    };
    Panel {
        title: title.to_owned(),
        x_label: "wall-clock minutes".to_owned(),
        y_label: "% of greedy evaluation trials".to_owned(),
        // In this order the palette draws collisions red, success green,
        // timeouts yellow.
        series: vec![
            series("collision", &|e| e.collision_rate),
            series("success", &|e| e.success_rate),
            series("timeout", &|e| e.timeout_rate),
        ],
        log_y: false,
    }
}

/// The `crossroads_train_*` metrics of the `train` process.
#[derive(Debug, Clone)]
pub struct TrainMetrics {
    updates: IntGauge,
    env_steps: IntGauge,
    env_steps_rate: Gauge,
    evaluations: IntCounter,
    success: Gauge,
    collision: Gauge,
    timeout: Gauge,
    mean_time: Gauge,
    version: IntGauge,
    reached: IntGauge,
}

impl TrainMetrics {
    /// Registered in `registry`.
    pub fn new(registry: &Registry) -> anyhow::Result<Self> {
        let gauge = |name: &str, help: &str| -> anyhow::Result<Gauge> {
            let g = Gauge::new(name, help)?;
            registry.register(Box::new(g.clone()))?;
            Ok(g)
        };
        let int = |name: &str, help: &str| -> anyhow::Result<IntGauge> {
            let g = IntGauge::new(name, help)?;
            registry.register(Box::new(g.clone()))?;
            Ok(g)
        };
        let evaluations = IntCounter::new(
            "crossroads_train_evaluations_total",
            "Greedy evaluations run by crossroads train",
        )?;
        registry.register(Box::new(evaluations.clone()))?;
        Ok(Self {
            updates: int("crossroads_train_updates", "Learner updates")?,
            env_steps: int(
                "crossroads_train_env_steps",
                "Simulation steps of all actors",
            )?,
            env_steps_rate: gauge(
                "crossroads_train_env_steps_per_second",
                "Simulation steps per second of all actors",
            )?,
            evaluations,
            success: gauge(
                "crossroads_train_eval_success_ratio",
                "Success rate of the latest greedy evaluation",
            )?,
            collision: gauge(
                "crossroads_train_eval_collision_ratio",
                "Collision rate of the latest greedy evaluation",
            )?,
            timeout: gauge(
                "crossroads_train_eval_timeout_ratio",
                "Timeout rate of the latest greedy evaluation",
            )?,
            mean_time: gauge(
                "crossroads_train_eval_mean_time_seconds",
                "Mean time to goal of the latest greedy evaluation (successful trials)",
            )?,
            version: int(
                "crossroads_train_eval_weights_version",
                "Weights version of the latest greedy evaluation",
            )?,
            reached: int(
                "crossroads_train_target_reached",
                "1 once the target was confirmed",
            )?,
        })
    }

    /// Progress.
    pub fn progress(&self, updates: u64, env_steps: u64, env_steps_per_s: f64) {
        self.updates.set(updates as i64);
        self.env_steps.set(env_steps as i64);
        self.env_steps_rate.set(env_steps_per_s);
    }

    /// An evaluation.
    pub fn evaluated(&self, e: &Evaluation) {
        self.evaluations.inc();
        self.success.set(e.success_rate);
        self.collision.set(e.collision_rate);
        self.timeout.set(e.timeout_rate);
        self.mean_time.set(e.mean_time_s.unwrap_or(f64::NAN));
        self.version.set(e.weights_version as i64);
    }

    /// The target was confirmed.
    pub fn reached(&self) {
        self.reached.set(1);
    }
}

//! `reproduce`'s "Safety across drivers": every Table I scenario under
//! driver populations that differ from the `human` preset in one bound,
//! the drivers' reaction time or the share of inattentive drivers, for TTC
//! tuned for `human` drivers, DQN-TTG, DQN-TTG behind the shield and the
//! shield alone, both assuming the `human` bounds. Written to
//! `<out>/drivers/` (README.md, drivers.csv, results.json and a figure per
//! bound), apart from the paper's tables.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Context;
use crossroads_common::Shutdown;
use crossroads_draw::plot::{self, Panel, Series};
use crossroads_sim::{
    ActionSet, Bounds, DriverPopulation, Scenario, ShieldParams, TuneReport, tune_ttc,
};
use serde::Serialize;

use super::paper::SCENARIOS;
use super::report::title;
use super::{Plan, ReportCell, behind_shield, evaluate_network, evaluate_policy};
use crate::experiments;
use crate::progress;
use crate::train::write_atomic;

/// How far the shield's sensor reaches here, m: every built-in lane starts
/// 150 m from the junction's centre, so it sees each lane whole, as the
/// TTC rule does. With the grid's 104 m, a car just past it at the fastest
/// `human` speed leaves no gap on Left, Left2 and Challenge
/// (reports/drivers).
const SENSOR_RANGE_M: f64 = 150.0;

/// Drivers' reaction times swept, s: SUMO's 0.2 to the `human` preset's
/// slowest (1.5), and one past it.
pub const REACTIONS: [f64; 6] = [0.2, 0.5, 0.8, 1.1, 1.5, 2.0];

/// Shares of inattentive drivers swept (none is the `human` preset).
pub const INATTENTIVE: [f64; 4] = [0.0, 0.025, 0.05, 0.1];

/// Which bound of the `human` preset a row changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Every driver reacts after exactly `value` seconds.
    Reaction,
    /// A share `value` of the drivers never notices the ego.
    Inattentive,
}

impl Axis {
    fn name(self) -> &'static str {
        match self {
            Self::Reaction => "reaction",
            Self::Inattentive => "inattentive",
        }
    }

    /// The `human` preset with this bound at `value`.
    fn population(self, value: f64) -> DriverPopulation {
        let human = DriverPopulation::human();
        match self {
            Self::Reaction => DriverPopulation {
                reaction_s: Some(Bounds::exactly(value)),
                ..human
            },
            Self::Inattentive => DriverPopulation {
                inattentive_share: value,
                ..human
            },
        }
    }

    fn values(self) -> &'static [f64] {
        match self {
            Self::Reaction => &REACTIONS,
            Self::Inattentive => &INATTENTIVE,
        }
    }
}

/// One scenario under one population.
#[derive(Debug, Clone, Serialize)]
pub struct DriversRow {
    pub scenario: String,
    pub axis: Axis,
    pub value: f64,
    /// The population, as `eval` prints it.
    pub drivers: String,
    /// TTC's threshold, tuned for `human` drivers.
    pub ttc_threshold: Option<f64>,
    pub ttc: Option<ReportCell>,
    pub ttg: Option<ReportCell>,
    /// DQN-TTG behind the shield assuming the `human` bounds.
    pub shielded: Option<ReportCell>,
    /// TTC at 0 s behind the same shield.
    pub shield_alone: Option<ReportCell>,
}

/// Everything the section measured.
#[derive(Debug, Clone, Default, Serialize)]
pub struct DriversResults {
    pub trials: u64,
    pub seed: u64,
    pub quick: bool,
    pub machine: String,
    pub started: String,
    /// TTC sweeps under `human` drivers, one per scenario.
    pub sweeps: Vec<TuneReport>,
    pub rows: Vec<DriversRow>,
}

/// The runs this section evaluates.
pub fn experiments() -> impl Iterator<Item = String> {
    SCENARIOS.iter().map(|s| format!("ttg-{s}"))
}

/// Measures the section.
pub fn evaluate(
    plan: &Plan,
    shutdown: &Shutdown,
    started: String,
) -> anyhow::Result<DriversResults> {
    let stop = || -> anyhow::Result<()> {
        anyhow::ensure!(!shutdown.is_triggered(), "stopped during the evaluations");
        Ok(())
    };
    let human = DriverPopulation::human();
    let assume = ShieldParams {
        range_m: Some(SENSOR_RANGE_M),
        ..ShieldParams::default()
    }
    .assuming(&human);
    let mut r = DriversResults {
        trials: plan.trials,
        seed: plan.seed,
        quick: plan.quick,
        machine: crate::train::machine(),
        started,
        ..DriversResults::default()
    };
    for s in SCENARIOS {
        stop()?;
        let load = |drivers: DriverPopulation| -> anyhow::Result<Arc<Scenario>> {
            Ok(Arc::new(
                Scenario::load(s)
                    .and_then(|sc| sc.with_drivers(drivers))
                    .with_context(|| format!("scenario {s}"))?,
            ))
        };
        // TTC tuned for human drivers by the paper's rule.
        let thresholds = plan.thresholds(false);
        let bar = progress::bar(plan.trials * thresholds.len() as u64, "trials");
        bar.set_message(format!("TTC sweep on {s}, human drivers"));
        let sweep = tune_ttc(
            &load(human.clone())?,
            ActionSet::Ttg,
            false,
            &thresholds,
            plan.trials,
            plan.seed,
            &|n| bar.inc(n),
        )?;
        bar.finish_and_clear();
        let threshold = sweep.best.as_ref().map(|b| b.threshold);
        eprintln!(
            "  TTC on {s}, human drivers: {}",
            threshold.map_or("no threshold without collisions".to_owned(), |t| format!(
                "{t:.2} s"
            ))
        );
        r.sweeps.push(sweep);
        let experiment = format!("ttg-{s}");
        let dirs: Vec<PathBuf> = (1..=plan.members(&experiment))
            .map(|k| plan.run_dir(&experiments::member_run(&experiment, k)))
            .collect();
        let networks = plan.dqn && dirs.iter().all(|d| d.exists());
        for axis in [Axis::Reaction, Axis::Inattentive] {
            for &value in axis.values() {
                stop()?;
                let drivers = axis.population(value);
                let sc = load(drivers.clone())?;
                let ttc = match threshold {
                    Some(t) => {
                        let policy = crossroads_sim::parse_policy(&format!("ttc:{t}"))?;
                        let name = policy.name();
                        Some(evaluate_policy(
                            plan,
                            &name,
                            &sc,
                            ActionSet::Ttg,
                            policy.as_ref(),
                            None,
                        )?)
                    }
                    None => None,
                };
                let (ttg, shielded) = if networks {
                    (
                        evaluate_network(plan, &dirs, &sc, ActionSet::Ttg, None)?,
                        evaluate_network(plan, &dirs, &sc, ActionSet::Ttg, Some(assume))?,
                    )
                } else {
                    (None, None)
                };
                let (policy, counters) =
                    behind_shield(crossroads_sim::parse_policy("ttc:0")?, assume);
                let name = policy.name();
                let shield_alone = Some(evaluate_policy(
                    plan,
                    &name,
                    &sc,
                    ActionSet::Ttg,
                    policy.as_ref(),
                    counters,
                )?);
                r.rows.push(DriversRow {
                    scenario: s.to_owned(),
                    axis,
                    value,
                    drivers: drivers.to_string(),
                    ttc_threshold: threshold,
                    ttc,
                    ttg,
                    shielded,
                    shield_alone,
                });
            }
        }
    }
    Ok(r)
}

/// The policies of a row, with their column names.
fn columns(row: &DriversRow) -> [(&'static str, Option<&ReportCell>); 4] {
    [
        ("TTC", row.ttc.as_ref()),
        ("DQN-TTG", row.ttg.as_ref()),
        ("DQN-TTG + shield", row.shielded.as_ref()),
        ("shield alone", row.shield_alone.as_ref()),
    ]
}

/// Writes README.md, drivers.csv, results.json and the figures into
/// `dir`; returns their paths.
pub fn write(dir: &Path, r: &DriversResults) -> anyhow::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> anyhow::Result<()> {
        let path = dir.join(name);
        write_atomic(&path, text.as_bytes())?;
        written.push(path);
        Ok(())
    };
    put("drivers.csv", csv(r))?;
    put(
        "results.json",
        serde_json::to_string_pretty(r).context("results as JSON")?,
    )?;
    put("README.md", markdown(r))?;
    for axis in [Axis::Reaction, Axis::Inattentive] {
        let path = dir.join(format!("fig-{}.png", axis.name()));
        figure(&path, r, axis)?;
        written.push(path);
    }
    Ok(written)
}

fn csv(r: &DriversResults) -> String {
    let mut w = String::from(
        "scenario,axis,value,policy,threshold_s,trials,success_%,collision_%,timeout_%,time_s\n",
    );
    for row in &r.rows {
        for (name, cell) in columns(row) {
            let Some(c) = cell else { continue };
            let threshold = if name == "TTC" {
                row.ttc_threshold.map_or(String::new(), |t| t.to_string())
            } else {
                String::new()
            };
            let _ = writeln!(
                w,
                "{},{},{},{},{threshold},{},{},{},{},{}",
                row.scenario,
                row.axis.name(),
                row.value,
                name.to_lowercase().replace(' ', ""),
                c.trials,
                c.success,
                c.collision,
                c.timeout,
                c.time.map_or(String::new(), |t| t.to_string())
            );
        }
    }
    w
}

/// `collision % · success % · time s` of a cell.
fn cell_md(c: Option<&ReportCell>) -> String {
    c.map_or("–".to_owned(), |c| {
        format!(
            "{:.2} · {:.1} · {}",
            c.collision,
            c.success,
            c.time.map_or("–".to_owned(), |t| format!("{t:.2}"))
        )
    })
}

fn markdown(r: &DriversResults) -> String {
    let human = DriverPopulation::human();
    let mut md = String::new();
    let w = &mut md;
    let _ = writeln!(w, "# Safety across drivers\n");
    if r.quick {
        let _ = writeln!(
            w,
            "> **--quick smoke run**: tiny networks, {} trials per cell. The numbers \
             below show that the pipeline works, not what the policies reach.\n",
            r.trials
        );
    }
    let _ = writeln!(
        w,
        "Generated by `crossroads reproduce` ({}, {}); {} trials per cell, seed {}, \
         the same trials for every policy of a row. The drivers are the `human` preset \
         ({human}) with one bound changed: every driver's reaction time, or the share \
         of drivers who never notice the ego. TTC runs at the threshold tuned for \
         `human` drivers by the paper's rule (the lowest with no collision on the same \
         trials); the shield, alone (`ttc:0` behind it) or behind DQN-TTG (each \
         scenario's `ttg-<scenario>` run, trained on `sumo` drivers), assumes the \
         `human` bounds and sees each lane whole, as the TTC rule does (`--shield \
         assume=human,range_m=150`): a reaction of 2.0 s and any inattentive driver \
         lie outside what it assumes. A cell is collision % · \
         success % · mean time of the successful trials, s. See docs/drivers.md for \
         what the presets are and what \"zero collisions\" means.\n",
        r.started, r.machine, r.trials, r.seed
    );
    for (axis, heading, unit) in [
        (Axis::Reaction, "Reaction time", "reaction, s"),
        (Axis::Inattentive, "Inattentive drivers", "inattentive, %"),
    ] {
        let _ = writeln!(
            w,
            "## {heading}\n\n![collision rate against {unit}](fig-{}.png)\n",
            axis.name()
        );
        let _ = writeln!(
            w,
            "| scenario | {unit} | TTC (threshold) | DQN-TTG | DQN-TTG + shield | shield alone |\n\
             | --- | ---: | --- | --- | --- | --- |"
        );
        for row in r.rows.iter().filter(|row| row.axis == axis) {
            let value = match axis {
                Axis::Reaction => format!("{:.1}", row.value),
                Axis::Inattentive => format!("{:.1}", 100.0 * row.value),
            };
            let ttc = match row.ttc_threshold {
                Some(t) => format!("{} ({t:.2} s)", cell_md(row.ttc.as_ref())),
                None => "no threshold without collisions".to_owned(),
            };
            let _ = writeln!(
                w,
                "| {} | {value} | {ttc} | {} | {} | {} |",
                title(&row.scenario),
                cell_md(row.ttg.as_ref()),
                cell_md(row.shielded.as_ref()),
                cell_md(row.shield_alone.as_ref()),
            );
        }
        let _ = writeln!(w);
    }
    md
}

/// Collision rate against the axis's value, a panel per scenario, a line
/// per policy.
fn figure(path: &Path, r: &DriversResults, axis: Axis) -> anyhow::Result<()> {
    let scale = match axis {
        Axis::Reaction => 1.0,
        Axis::Inattentive => 100.0,
    };
    let x_label = match axis {
        Axis::Reaction => "drivers' reaction time, s",
        Axis::Inattentive => "inattentive drivers, %",
    };
    let panels: Vec<Panel> = SCENARIOS
        .iter()
        .map(|&s| {
            let rows: Vec<&DriversRow> = r
                .rows
                .iter()
                .filter(|row| row.scenario == s && row.axis == axis)
                .collect();
            let series = (0..4)
                .filter_map(|i| {
                    let points: Vec<(f64, f64)> = rows
                        .iter()
                        .filter_map(|row| {
                            columns(row)[i].1.map(|c| (scale * row.value, c.collision))
                        })
                        .collect();
                    (!points.is_empty()).then(|| Series {
                        label: rows.first().map_or("", |row| columns(row)[i].0).to_owned(),
                        points,
                        line: true,
                    })
                })
                .collect();
            Panel {
                title: title(s),
                x_label: x_label.to_owned(),
                y_label: "collisions, % of trials".to_owned(),
                series,
                log_y: false,
            }
        })
        .collect();
    let heading = match axis {
        Axis::Reaction => {
            "Collision rate against the drivers' reaction time (human drivers otherwise)"
        }
        Axis::Inattentive => {
            "Collision rate against the share of inattentive drivers (human drivers otherwise)"
        }
    };
    plot::grid(path, Some(heading), 3, &panels)?;
    Ok(())
}

//! The report of `crossroads reproduce`: README.md (tables with the
//! paper's numbers beside ours, shortfalls, training cost), CSV per table,
//! results.json, fig3.png and curves.png.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use crossroads_draw::plot::{self, Panel, Series};

use super::paper::{self, FIG3_SCENARIOS, SCENARIOS};
use super::table::{Comparison, ComparisonRow, Entry, Method, num, pair};
use super::{Part, Plan, ReportCell, Results};
use crate::train::{curve_panel, write_atomic};

/// Writes every file of the report; returns their paths.
pub fn write(out: &Path, plan: &Plan, r: &Results) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> anyhow::Result<()> {
        let path = out.join(name);
        write_atomic(&path, text.as_bytes())?;
        written.push(path);
        Ok(())
    };
    let table1 = plan.wants(Part::Table1).then(|| table1(r));
    let table2 = plan.wants(Part::Table2).then(|| table2(r));
    if let Some(t) = &table1 {
        put("table1.csv", t.to_csv())?;
    }
    if let Some(t) = &table2 {
        put("table2.csv", t.to_csv())?;
    }
    if plan.wants(Part::Table3) {
        put("table3.csv", table3_csv(r))?;
    }
    put("training.csv", training_csv(r))?;
    put(
        "results.json",
        serde_json::to_string_pretty(r).context("results as JSON")?,
    )?;
    put(
        "README.md",
        markdown(plan, r, table1.as_ref(), table2.as_ref()),
    )?;
    if plan.wants(Part::Fig3) {
        let path = out.join("fig3.png");
        fig3(&path, r)?;
        written.push(path);
    }
    let panels: Vec<Panel> = r
        .runs
        .iter()
        .filter(|run| !run.curve.is_empty())
        .map(|run| curve_panel(&run.experiment, &run.curve))
        .collect();
    if !panels.is_empty() {
        let path = out.join("curves.png");
        plot::grid(
            &path,
            Some("Learning curves: greedy evaluations during training"),
            3,
            &panels,
        )?;
        written.push(path);
    }
    Ok(written)
}

/// What the call's minutes include: which runs it trained.
fn trained(r: &Results) -> String {
    match r.trained.len() {
        0 if r.runs.is_empty() => "no network trained".to_owned(),
        0 => "evaluation only: every run was reused, its own training time is in the training section".to_owned(),
        n => format!(
            "training {n} of {} runs included; the others were reused",
            r.runs.len()
        ),
    }
}

pub(super) fn title(s: &str) -> String {
    let mut c = s.chars();
    c.next().map_or(String::new(), |f| {
        f.to_uppercase().collect::<String>() + c.as_str()
    })
}

/// A method's entry: our metrics of `cell` in the tables' order (success
/// %, collision %, time s, brake s) and the paper's, if it has the method.
fn entry(cell: &Option<ReportCell>, paper: Option<Vec<f64>>) -> Entry {
    let c = cell.as_ref();
    Entry {
        ours: [
            c.map(|c| c.success),
            c.map(|c| c.collision),
            c.and_then(|c| c.time),
            c.map(|c| c.brake_light_s),
        ],
        paper,
    }
}

const fn method(csv: &'static str, heading: Option<&'static str>) -> Method {
    Method { csv, heading }
}

/// Table I: TTC, DQN-Sequential and DQN-TTG beside the paper's, and
/// DQN-TTG behind the shield, for each of the paper's scenarios measured.
fn table1(r: &Results) -> Comparison {
    let rows = r
        .table1
        .iter()
        .filter_map(|row| {
            let i = SCENARIOS.iter().position(|s| *s == row.scenario)?;
            let paper = |m: usize| {
                let p = &paper::TABLE1[i][m];
                Some(vec![p.success, p.collision, p.time, p.brake])
            };
            Some(ComparisonRow {
                key: row.scenario.clone(),
                label: title(&row.scenario),
                entries: vec![
                    entry(&row.ttc, paper(0)),
                    entry(&row.sequential, paper(1)),
                    entry(&row.ttg, paper(2)),
                    entry(&row.shielded, None),
                ],
            })
        })
        .collect();
    Comparison {
        key_csv: "scenario",
        key_heading: "scenario",
        methods: vec![
            method("ttc", Some("TTC")),
            method("dqn-sequential", Some("DQN-Sequential")),
            method("dqn-ttg", Some("DQN-TTG")),
            method("dqn-ttg+shield", Some("DQN-TTG + shield")),
        ],
        metrics: 4,
        rows,
    }
}

/// Table II: TTC with creep and the DQNs beside the paper's, then the
/// shield and the oracle (the last three in the CSV only), per occluder
/// length.
fn table2(r: &Results) -> Comparison {
    let rows = r
        .table2
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let paper = |m: usize| {
                let p = &paper::TABLE2[i][m];
                Some(vec![p.success, p.collision, p.time])
            };
            ComparisonRow {
                key: row.length_m.to_string(),
                label: format!("{} m", row.length_m),
                entries: vec![
                    entry(&row.ttc_creep, paper(0)),
                    entry(&row.ttg, paper(1)),
                    entry(&row.creep, paper(2)),
                    entry(&row.sequential, paper(3)),
                    entry(&row.shielded, None),
                    entry(&row.shield_alone, None),
                    entry(&row.see_through, None),
                    entry(&row.oracle, None),
                ],
            }
        })
        .collect();
    Comparison {
        key_csv: "occlusion_m",
        key_heading: "occlusion",
        methods: vec![
            method("ttc-creep", Some("TTC with creep")),
            method("dqn-ttg", Some("DQN-TTG")),
            method("dqn-creep", Some("DQN-Creep")),
            method("dqn-sequential", Some("DQN-Sequential")),
            method("dqn-creep+shield", Some("DQN-Creep + shield")),
            method("shield-alone", None),
            method("shield-alone-see-through", None),
            method("oracle", None),
        ],
        metrics: 3,
        rows,
    }
}

fn table3_csv(r: &Results) -> String {
    let mut out = String::from("tested_on,trained_on,success_ours,success_paper,collision_ours\n");
    for (i, row) in r.table3.iter().enumerate() {
        for (j, cell) in row.iter().enumerate() {
            let _ = writeln!(
                out,
                "{},{},{},{},{}",
                SCENARIOS[i],
                SCENARIOS[j],
                cell.as_ref()
                    .map_or(String::new(), |c| c.success.to_string()),
                paper::TABLE3[i][j],
                cell.as_ref()
                    .map_or(String::new(), |c| c.collision.to_string()),
            );
        }
    }
    out
}

fn training_csv(r: &Results) -> String {
    let mut out = String::from(
        "experiment,status,actors,updates,env_steps,minutes,best_success,best_collision,best_time_s,best_at_minutes,best_at_env_steps,target_at_minutes,target_at_env_steps\n",
    );
    for run in &r.runs {
        let s = &run.summary;
        let b = s.best.as_ref();
        let t = s.reached.as_ref().map(|t| &t.evaluation);
        let opt = |v: Option<String>| v.unwrap_or_default();
        let _ = writeln!(
            out,
            "{},{},{},{},{},{:.2},{},{},{},{},{},{},{}",
            run.experiment,
            s.status,
            s.actors,
            s.updates,
            s.env_steps,
            s.wall_seconds / 60.0,
            opt(b.map(|b| (100.0 * b.success_rate).to_string())),
            opt(b.map(|b| (100.0 * b.collision_rate).to_string())),
            opt(b.and_then(|b| b.mean_time_s).map(|v| v.to_string())),
            opt(b.map(|b| format!("{:.2}", b.wall_seconds / 60.0))),
            opt(b.map(|b| b.env_steps.to_string())),
            opt(t.map(|t| format!("{:.2}", t.wall_seconds / 60.0))),
            opt(t.map(|t| t.env_steps.to_string())),
        );
    }
    out
}

/// README.md, with Tables I and II when the plan has them.
fn markdown(
    plan: &Plan,
    r: &Results,
    table1: Option<&Comparison>,
    table2: Option<&Comparison>,
) -> String {
    let mut md = String::new();
    let w = &mut md;
    let _ = writeln!(w, "# The paper's tables, measured by crossroads\n");
    if r.quick {
        let _ = writeln!(
            w,
            "> **--quick smoke run**: tiny networks and budgets, {} trials per cell. \
             The numbers below show that the pipeline works, not what the method reaches.\n",
            r.trials
        );
    }
    if r.baselines_only {
        let _ = writeln!(
            w,
            "> **Baselines only** (`--baselines-only`): the TTC cells and sweeps, measured on \
             this simulator; no network was trained or evaluated, so the DQN cells are empty.\n"
        );
    }
    let _ = writeln!(
        w,
        "Generated by `crossroads reproduce` ({}, {}); {} trials per cell, seed {}, \
         the same trials for every method; {:.1} minutes in all ({}). \
         Ours first, the paper's (Isele et al., ICRA 2018) in brackets. \
         Time is the mean time to the goal of successful trials; brake is traffic's \
         brake-light seconds per trial by SUMO's rule (cars within 100 m of the junction; \
         the paper does not define its measure, see reports/sumo/NOTES.md). DQN cells evaluate each run's \
         `best/` weights (chosen on the run's own periodic evaluations, train.eval_trials trials of another seed){}.\n",
        r.started,
        r.machine,
        r.trials,
        r.seed,
        r.minutes,
        trained(r),
        if r.runs.iter().any(|run| run.experiment.contains("-seed")) {
            "; an experiment trained from several seeds (`<experiment>-seed<k>` runs) acts on \
             the mean of its networks' Q-values (see the training section)"
        } else {
            ""
        }
    );
    if let Some(t) = table1 {
        table1_md(w, r, t);
    }
    if let Some(t) = table2 {
        table2_md(w, r, t);
    }
    if plan.wants(Part::Table3) {
        table3_md(w, r);
    }
    if plan.wants(Part::Fig3) {
        let _ = writeln!(
            w,
            "## Figure 3: TTC threshold sweeps and the DQN points\n\n\
             ![Figure 3](fig3.png)\n\n\
             Each curve is TTC at thresholds 0, 0.25, ... s (collision rate against \
             mean time to cross); the paper's claim is that the DQN points lie beyond \
             the whole curve (faster at the same collision rate).\n"
        );
    }
    if plan.wants(Part::Drivers) {
        let _ = writeln!(
            w,
            "## Safety across drivers\n\n\
             Every Table I scenario against the drivers' reaction time and the share of \
             inattentive drivers, for TTC tuned for human drivers, DQN-TTG, DQN-TTG behind \
             the shield and the shield alone: [drivers/README.md](drivers/README.md).\n"
        );
    }
    shortfalls_md(w, r);
    ladder_md(w, r);
    shield_md(w, r);
    training_md(w, r);
    md
}

fn table1_md(w: &mut String, r: &Results, table: &Comparison) {
    let _ = writeln!(w, "## Table I: no occlusion\n");
    w.push_str(&table.to_markdown());
    let thresholds: Vec<String> = r
        .table1
        .iter()
        .map(|row| {
            format!(
                "{} {}",
                title(&row.scenario),
                row.ttc_threshold
                    .map_or("none free of collisions".to_owned(), |t| format!("{t} s"))
            )
        })
        .collect();
    let _ = writeln!(
        w,
        "\nDQN-TTG + shield is a network trained behind the shield \
         (`ttg-<scenario>+shield`: a vetoed *go* executes as a wait and is stored at its value \
         less a small cost), for use behind it only. TTC thresholds (the paper's rule: the \
         lowest with zero collisions over {} trials): {}.\n",
        r.trials,
        thresholds.join(", ")
    );
}

fn table2_md(w: &mut String, r: &Results, table: &Comparison) {
    let _ = writeln!(
        w,
        "## Table II: occlusion (left turn across two lanes, traffic does not brake)\n"
    );
    w.push_str(&table.to_markdown());
    let thresholds: Vec<String> = r
        .table2
        .iter()
        .map(|row| {
            format!(
                "{} m {}",
                row.length_m,
                row.ttc_threshold
                    .map_or("none free of collisions".to_owned(), |t| format!("{t} s"))
            )
        })
        .collect();
    let _ = writeln!(
        w,
        "\nEach length is evaluated on its own family (`occluded-30`, `-60`, `-90`: walls on \
         the left, right or both, random width and offset); the DQNs are trained on all \
         lengths together (`occluded`); DQN-Creep + shield is a network trained behind the \
         shield (`creep-occluded+shield`: a vetoed *go* executes as the shield's fallback \
         and is stored at its value less a small cost), for use behind it only. \
         TTC-with-creep thresholds (lowest without collisions): {}.\n",
        thresholds.join(", ")
    );
}

fn table3_md(w: &mut String, r: &Results) {
    let _ = writeln!(
        w,
        "## Table III: transfer (DQN-TTG success %, trained on the column, tested on the row)\n"
    );
    let _ = write!(w, "| tested \\ trained |");
    for s in SCENARIOS {
        let _ = write!(w, " {} |", title(s));
    }
    let _ = write!(w, "\n| --- |");
    for _ in SCENARIOS {
        w.push_str(" --- |");
    }
    w.push('\n');
    for (i, row) in r.table3.iter().enumerate() {
        let _ = write!(w, "| {} |", title(SCENARIOS[i]));
        for (j, cell) in row.iter().enumerate() {
            let _ = write!(
                w,
                " {} |",
                pair(cell.as_ref().map(|c| c.success), paper::TABLE3[i][j], 1)
            );
        }
        w.push('\n');
    }
    let _ = writeln!(
        w,
        "\nThe paper's transfer networks had 25,000 training episodes; ours are Table I's \
         runs.\n"
    );
}

/// Every DQN cell below the paper's success or above its collisions.
fn shortfalls_md(w: &mut String, r: &Results) {
    if r.baselines_only {
        return;
    }
    let mut lines = Vec::new();
    let mut check = |what: String, ours: Option<&ReportCell>, success: f64, collision: f64| {
        let Some(c) = ours else {
            return;
        };
        let ds = c.success - success;
        let dc = c.collision - collision;
        if ds < -0.005 || dc > 0.005 {
            lines.push(format!(
                "- {what}: success {:.2} % vs {success} % ({ds:+.2} points), collisions {:.2} % vs {collision} % ({dc:+.2} points)",
                c.success, c.collision
            ));
        }
    };
    for row in &r.table1 {
        if let Some(i) = SCENARIOS.iter().position(|s| *s == row.scenario) {
            let p = &paper::TABLE1[i];
            let n = title(&row.scenario);
            check(
                format!("Table I, DQN-Sequential on {n}"),
                row.sequential.as_ref(),
                p[1].success,
                p[1].collision,
            );
            check(
                format!("Table I, DQN-TTG on {n}"),
                row.ttg.as_ref(),
                p[2].success,
                p[2].collision,
            );
        }
    }
    for (i, row) in r.table2.iter().enumerate() {
        let p = &paper::TABLE2[i];
        let n = format!("{} m", row.length_m);
        check(
            format!("Table II, DQN-TTG at {n}"),
            row.ttg.as_ref(),
            p[1].success,
            p[1].collision,
        );
        check(
            format!("Table II, DQN-Creep at {n}"),
            row.creep.as_ref(),
            p[2].success,
            p[2].collision,
        );
        check(
            format!("Table II, DQN-Sequential at {n}"),
            row.sequential.as_ref(),
            p[3].success,
            p[3].collision,
        );
    }
    let _ = writeln!(w, "## Where the DQNs fall short of the paper\n");
    if lines.is_empty() {
        let _ = writeln!(w, "Nowhere among the cells measured.\n");
    } else {
        let _ = writeln!(w, "{}\n", lines.join("\n"));
    }
    let _ = writeln!(
        w,
        "Why, where we know: see NOTES.md next to a committed report, and the \
         simulator's calibration notes (`sim` crate docs).\n"
    );
}

/// Table II's cells against the best achievable on the same trials: the
/// shield alone, the shield alone with walls that hide nothing, and the
/// oracle that sees hidden cars; each cell's success in points below the
/// oracle's.
fn ladder_md(w: &mut String, r: &Results) {
    if r.table2.iter().all(|row| row.oracle.is_none()) {
        return;
    }
    let _ = writeln!(
        w,
        "## How far from the limit under occlusion\n\n\
         On Table II's trials: the oracle (`--policy {} --actions creep`) sees the cars \
         behind the walls and goes when going reaches the goal in every one of 16 futures \
         of the present, else creeps to the creep limit and waits; the shield alone with \
         transparent walls (`--shield see_through=1`) is the shield knowing every car but \
         not the future; the shield alone (`--policy {} --actions creep --shield`) is what \
         the ego's own view allows under the shield's assumptions. \"Below the oracle\" is \
         the success in points under the oracle's.\n\n\
         | occlusion | policy | success % | collision % | time s | below the oracle |\n\
         | --- | --- | --- | --- | --- | --- |",
        super::ORACLE,
        super::SHIELD_ALONE
    );
    for row in &r.table2 {
        let Some(top) = row.oracle.as_ref() else {
            continue;
        };
        let rungs = [
            ("oracle", Some(top)),
            ("shield alone, transparent walls", row.see_through.as_ref()),
            ("shield alone", row.shield_alone.as_ref()),
            ("DQN-Creep + shield", row.shielded.as_ref()),
            ("DQN-Creep", row.creep.as_ref()),
            ("TTC with creep", row.ttc_creep.as_ref()),
            ("DQN-Sequential", row.sequential.as_ref()),
            ("DQN-TTG", row.ttg.as_ref()),
        ];
        let mut first = true;
        for (name, cell) in rungs {
            let Some(c) = cell else { continue };
            let label = if first {
                format!("{} m", row.length_m)
            } else {
                String::new()
            };
            first = false;
            let _ = writeln!(
                w,
                "| {label} | {name} | {:.2} | {:.2} | {} | {:.2} |",
                c.success,
                c.collision,
                num(c.time, 2),
                top.success - c.success
            );
        }
    }
    w.push('\n');
}

/// The shield section's rows of one table row: the network behind the
/// shield (with the shield alone's cell to compare against) and the shield
/// alone (`[shielded, alone]`), each with the row's TTC and unshielded DQN
/// cells to compare against.
fn shield_rows<'a>(
    label: String,
    [shielded, alone]: [Option<&'a ReportCell>; 2],
    ttc: Option<&'a ReportCell>,
    dqn: Option<&'a ReportCell>,
) -> impl Iterator<Item = ShieldRow<'a>> {
    let alone_label = format!("{label}, shield alone");
    let net = shielded.map(|cell| ShieldRow {
        label,
        cell,
        ttc,
        dqn,
        alone,
    });
    let rule = alone.map(|cell| ShieldRow {
        label: alone_label,
        cell,
        ttc,
        dqn,
        alone: None,
    });
    net.into_iter().chain(rule)
}

/// One row of the shield section: a cell behind the shield and what it is
/// compared with.
struct ShieldRow<'a> {
    label: String,
    cell: &'a ReportCell,
    ttc: Option<&'a ReportCell>,
    dqn: Option<&'a ReportCell>,
    /// The shield alone, on a network's row.
    alone: Option<&'a ReportCell>,
}

/// The safety shield's targets per row: zero collisions; at least TTC's
/// success; on Table I a mean time at least 15 % below TTC's and within
/// 5 % of the unshielded DQN's; a network's mean time within 2 % of the
/// shield alone's.
fn shield_md(w: &mut String, r: &Results) {
    let rows1 = r.table1.iter().flat_map(|row| {
        shield_rows(
            title(&row.scenario),
            [row.shielded.as_ref(), row.shield_alone.as_ref()],
            row.ttc.as_ref(),
            row.ttg.as_ref(),
        )
    });
    let rows2 = r.table2.iter().flat_map(|row| {
        shield_rows(
            format!("{} m", row.length_m),
            [row.shielded.as_ref(), row.shield_alone.as_ref()],
            row.ttc_creep.as_ref(),
            None,
        )
    });
    let rows: Vec<_> = rows1.chain(rows2).collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        w,
        "## The DQN behind the safety shield\n\n\
         `crossroads eval --policy <run>/best --shield` on the same trials: every *go* the \
         network chooses is checked against the cars the ego senses and phantom cars where \
         its view ends, and vetoed when any could come too close (`sim::shield`). The \
         shield alone is `--policy {} --shield`: a policy that always wants to go, so the \
         ego goes at the first moment the shield allows and the shield's fallback (wait; \
         creep to the creep limit on Table II) acts until then. The networks are those \
         trained behind the shield (`ttg-<scenario>+shield`, `creep-occluded+shield`). \
         Targets: no collision, at least the TTC column's success; on Table I also a mean \
         time at least 15 % below TTC's and within 5 % of the unshielded DQN's; a network's \
         mean time at most 2 % above the shield alone's.\n\n\
         | row | collisions | success vs TTC | time / TTC's | time / DQN's | time / shield alone's | go vetoed |\n\
         | --- | --- | --- | --- | --- | --- | --- |",
        super::SHIELD_ALONE
    );
    let mark = |ok: bool| if ok { "✓" } else { "✗" };
    for row in rows {
        let ShieldRow {
            label,
            cell: s,
            ttc,
            dqn,
            alone,
        } = row;
        let ratio = |other: Option<&ReportCell>| -> Option<f64> { Some(s.time? / other?.time?) };
        let vs_ttc = ttc.map_or("–".to_owned(), |t| {
            format!(
                "{} {:.2} % vs {:.2} %",
                mark(s.success >= t.success),
                s.success,
                t.success
            )
        });
        let time_ttc = match (ratio(ttc), dqn) {
            (Some(q), Some(_)) => format!("{} {q:.3}", mark(q <= 0.85)),
            (Some(q), None) => format!("{q:.3}"),
            (None, _) => "–".to_owned(),
        };
        let time_dqn =
            ratio(dqn).map_or("–".to_owned(), |q| format!("{} {q:.3}", mark(q <= 1.05)));
        let time_alone =
            ratio(alone).map_or("–".to_owned(), |q| format!("{} {q:.3}", mark(q <= 1.02)));
        let vetoes = s.shield.map_or("–".to_owned(), |v| {
            format!(
                "{} of {} ({:.1} %)",
                v.vetoes,
                v.go_decisions,
                100.0 * v.vetoes as f64 / v.go_decisions.max(1) as f64
            )
        });
        let _ = writeln!(
            w,
            "| {label} | {} {:.2} % | {vs_ttc} | {time_ttc} | {time_dqn} | {time_alone} | {vetoes} |",
            mark(s.collision == 0.0),
            s.collision
        );
    }
    let _ = writeln!(
        w,
        "\nOn Table II the unshielded comparison is DQN-Creep; the time target applies \
         to Table I only.\n"
    );
}

fn training_md(w: &mut String, r: &Results) {
    if r.runs.is_empty() {
        return;
    }
    let _ = writeln!(
        w,
        "## Training on this machine: time and environment steps\n\n\
         Greedy evaluations during training used the run's own seed and train.eval_trials \
         trials; \"target\" is the experiment's train.target_* confirmed on \
         train.confirm_trials trials.\n\n\
         | run | status | actors | updates | env steps | minutes | best greedy evaluation | best at (min / env steps) | target at (min / env steps) |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    let members: Vec<&str> = r
        .runs
        .iter()
        .map(|run| run.experiment.as_str())
        .filter(|name| name.contains("-seed"))
        .collect();
    for run in &r.runs {
        let s = &run.summary;
        let best = s.best.as_ref();
        let target = s.reached.as_ref().map(|t| &t.evaluation);
        let _ = writeln!(
            w,
            "| [{name}](runs/{name}/curve.png) | {} | {} | {} | {} | {:.1} | {} | {} | {} |",
            s.status,
            s.actors,
            s.updates,
            s.env_steps,
            s.wall_seconds / 60.0,
            best.map_or("–".to_owned(), |b| format!(
                "{:.2} % / {:.2} % coll / {}",
                100.0 * b.success_rate,
                100.0 * b.collision_rate,
                num(b.mean_time_s, 2) + " s"
            )),
            best.map_or("–".to_owned(), |b| format!(
                "{:.1} / {}",
                b.wall_seconds / 60.0,
                b.env_steps
            )),
            target.map_or("not reached".to_owned(), |t| format!(
                "{:.1} / {}",
                t.wall_seconds / 60.0,
                t.env_steps
            )),
            name = run.experiment,
        );
    }
    if !members.is_empty() {
        let _ = writeln!(
            w,
            "\n{} trained the same experiment from other seeds (actor.seed and learner.seed \
             = k): that experiment's cells act on the mean Q-values of every member's best \
             weights (a `dqn-mean:` policy; `crossroads eval --policy a/best,b/best,...`).",
            members
                .iter()
                .map(|m| format!("`{m}`"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let _ = writeln!(w, "\n{}", training_time(r));
    let _ = writeln!(w, "\n![Learning curves](curves.png)\n");
}

/// The training time of the report's networks: the sum of their runs'
/// wall times (each on the machine its summary names), and the part this
/// call trained.
pub(super) fn training_time(r: &Results) -> String {
    let total: f64 = r.runs.iter().map(|run| run.summary.wall_seconds).sum();
    let this_call: f64 = r
        .runs
        .iter()
        .filter(|run| r.trained.contains(&run.experiment))
        .map(|run| run.summary.wall_seconds)
        // Not `sum`: an empty f64 sum is -0.0, printed "-0".
        .fold(0.0, |a, b| a + b);
    format!(
        "Training time of the {} runs: {:.1} hours in all ({:.0} minutes), {:.0} minutes of it \
         trained by this call ({} of the runs).",
        r.runs.len(),
        total / 3600.0,
        total / 60.0,
        this_call / 60.0,
        r.trained.len()
    )
}

/// Figure 3: per scenario, TTC's collision rate against its mean time over
/// the threshold sweep, with the DQN points.
fn fig3(path: &Path, r: &Results) -> anyhow::Result<()> {
    let mut panels = Vec::new();
    for s in FIG3_SCENARIOS {
        let mut series = Vec::new();
        if let Some(sweep) = r.sweeps.iter().find(|w| w.scenario == s && !w.creep) {
            let (lo, hi) = (
                sweep.sweep.first().map_or(0.0, |p| p.threshold),
                sweep.sweep.last().map_or(0.0, |p| p.threshold),
            );
            series.push(Series {
                label: format!("TTC, thresholds {lo}-{hi} s"),
                points: sweep
                    .sweep
                    .iter()
                    .filter_map(|p| p.mean_time_s.map(|t| (t, 100.0 * p.collision_rate)))
                    .collect(),
                line: true,
            });
        }
        let row = r.table1.iter().find(|row| row.scenario == s);
        for (label, cell) in [
            ("DQN-TTG", row.and_then(|row| row.ttg.as_ref())),
            (
                "DQN-Sequential",
                row.and_then(|row| row.sequential.as_ref()),
            ),
            (
                "DQN-TTG + shield",
                row.and_then(|row| row.shielded.as_ref()),
            ),
        ] {
            if let Some(c) = cell
                && let Some(t) = c.time
            {
                series.push(Series {
                    label: label.into(),
                    points: vec![(t, c.collision)],
                    line: false,
                });
            }
        }
        if !series.is_empty() {
            panels.push(Panel {
                title: title(s),
                x_label: "mean time to cross (s)".into(),
                y_label: "collision rate (%)".into(),
                series,
                log_y: false,
            });
        }
    }
    anyhow::ensure!(!panels.is_empty(), "nothing to draw for Figure 3");
    plot::grid(
        path,
        Some(&format!(
            "Figure 3: time to cross against collisions, {} trials per point",
            r.trials
        )),
        2,
        &panels,
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reproduce::RunRecord;
    use crate::train::record::Summary;

    #[test]
    fn the_training_time_sums_every_run_and_names_this_calls_part() {
        let run = |name: &str, seconds: f64| RunRecord {
            experiment: name.to_owned(),
            summary: Summary {
                wall_seconds: seconds,
                ..Summary::default()
            },
            curve: Vec::new(),
        };
        let r = Results {
            runs: vec![run("ttg-left", 2_400.0), run("ttg-right", 5_400.0)],
            trained: vec!["ttg-right".to_owned()],
            ..Results::default()
        };
        assert_eq!(
            training_time(&r),
            "Training time of the 2 runs: 2.2 hours in all (130 minutes), 90 minutes of it \
             trained by this call (1 of the runs)."
        );
        // Every run reused: zero minutes, not "-0".
        let reused = Results {
            trained: Vec::new(),
            ..r
        };
        assert!(
            training_time(&reused)
                .contains(", 0 minutes of it trained by this call (0 of the runs)"),
            "{}",
            training_time(&reused)
        );
    }
}

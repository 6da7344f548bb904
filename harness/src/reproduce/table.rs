//! A table of the paper's kind ([`Comparison`]), built once from the
//! results and written twice: as long CSV, a line per row, method and
//! metric (`key,method,metric,ours,paper`), and as the report's Markdown, a
//! line per metric with `ours (paper)` per method.

use std::fmt::Write as _;

/// The metrics of a cell, with their decimals in Markdown; a table shows
/// the first [`Comparison::metrics`], those the paper gives.
const METRICS: [(&str, usize); 4] = [
    ("success %", 2),
    ("collision %", 2),
    ("time s", 2),
    ("brake s", 2),
];

/// One method of a table.
#[derive(Debug, Clone, Copy)]
pub(super) struct Method {
    /// Its name in the CSV (`dqn-ttg`).
    pub csv: &'static str,
    /// Its heading in Markdown; `None` for a method only the CSV lists.
    pub heading: Option<&'static str>,
}

/// One method's metrics in one row.
#[derive(Debug, Clone)]
pub(super) struct Entry {
    /// Ours, in [`METRICS`] order (`None` where not measured).
    pub ours: [Option<f64>; 4],
    /// The paper's, in the same order, for a method the paper has.
    pub paper: Option<Vec<f64>>,
}

/// One row: a scenario, an occluder length.
#[derive(Debug, Clone)]
pub(super) struct ComparisonRow {
    /// The row's key in the CSV (`left`, `30`).
    pub key: String,
    /// Its label in Markdown (`Left`, `30 m`).
    pub label: String,
    /// An entry per method, in the table's order.
    pub entries: Vec<Entry>,
}

/// Our metrics beside the paper's, per row and method.
#[derive(Debug, Clone)]
pub(super) struct Comparison {
    /// The key column's CSV name (`scenario`, `occlusion_m`).
    pub key_csv: &'static str,
    /// Its Markdown heading (`scenario`, `occlusion`).
    pub key_heading: &'static str,
    /// The methods, those the paper has first.
    pub methods: Vec<Method>,
    /// How many of [`METRICS`] the table has.
    pub metrics: usize,
    pub rows: Vec<ComparisonRow>,
}

/// `v` to `decimals` places, or a dash.
pub(super) fn num(v: Option<f64>, decimals: usize) -> String {
    v.map_or("–".to_owned(), |v| format!("{v:.decimals$}"))
}

/// `ours (paper)`, both to `decimals` places.
pub(super) fn pair(ours: Option<f64>, paper: f64, decimals: usize) -> String {
    format!("{} ({paper:.decimals$})", num(ours, decimals))
}

impl Comparison {
    /// The CSV file: a header, then a line per row, method and metric,
    /// every number in full (the paper's column empty for a method it
    /// lacks).
    pub fn to_csv(&self) -> String {
        let mut out = format!("{},method,metric,ours,paper\n", self.key_csv);
        let text = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
        for row in &self.rows {
            for (method, entry) in self.methods.iter().zip(&row.entries) {
                for (k, (metric, _)) in METRICS.iter().take(self.metrics).enumerate() {
                    let paper = entry.paper.as_ref().map(|p| p[k]);
                    let _ = writeln!(
                        out,
                        "{},{},{},{},{}",
                        row.key,
                        method.csv,
                        metric.replace(' ', "_"),
                        text(entry.ours[k]),
                        text(paper)
                    );
                }
            }
        }
        out
    }

    /// The Markdown table: a line per row and metric, the row's label on
    /// its first; `ours (paper)` for the methods the paper has, ours alone
    /// for the others with a heading.
    pub fn to_markdown(&self) -> String {
        let shown: Vec<(usize, &str)> = self
            .methods
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.heading.map(|h| (i, h)))
            .collect();
        let mut headings = vec![self.key_heading, "metric"];
        headings.extend(shown.iter().map(|(_, h)| *h));
        let mut w = format!(
            "| {} |\n| {} |\n",
            headings.join(" | "),
            vec!["---"; headings.len()].join(" | ")
        );
        for row in &self.rows {
            for (k, &(metric, d)) in METRICS.iter().take(self.metrics).enumerate() {
                let label = if k == 0 { row.label.as_str() } else { "" };
                let _ = write!(w, "| {label} | {metric} |");
                for &(i, _) in &shown {
                    let entry = &row.entries[i];
                    let cell = match &entry.paper {
                        Some(paper) => pair(entry.ours[k], paper[k], d),
                        None => num(entry.ours[k], d),
                    };
                    let _ = write!(w, " {cell} |");
                }
                w.push('\n');
            }
        }
        w
    }
}

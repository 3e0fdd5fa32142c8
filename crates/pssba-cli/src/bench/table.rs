//! Means over seeds and the three tables (APE, occupancy, wall time) laid out like the
//! paper's Table I: rows = methods, columns = scenes; as text, markdown and JSON.

use super::run::{BenchMethod, Measurement};
use serde::Serialize;
use std::fmt::Write as _;

/// The paper's Table I APE (m) per scene, rows as [`BenchMethod::ALL`] (DESIGN.md section 4).
/// Our `crane` is the CARIC crane mesh and `hangar` our procedural hangar (the paper's CARIC
/// hangar is unavailable); `curved` and `truss` have no counterpart.
pub fn paper_ape(scene: &str) -> Option<[f64; 5]> {
    match scene {
        "mbs" => Some([0.11, 0.09, 0.05, 0.05, 0.02]),
        "hangar" => Some([0.12, 0.07, 0.06, 0.03, 0.01]),
        "crane" => Some([0.11, 0.07, 0.06, 0.04, 0.01]),
        "street" => Some([0.17, 0.09, 0.08, 0.06, 0.03]),
        _ => None,
    }
}

/// One scene x method cell, averaged over the seeds that succeeded.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Scene name.
    pub scene: String,
    /// Method name (`initial`, `balm`, `point2plane`, `pss-ba-fs`, `pss-ba`).
    pub method: &'static str,
    /// Mean APE (m) over the successful seeds; null when every seed failed.
    pub ape_m: Option<f64>,
    /// Mean occupied 0.1 m voxels over the successful seeds.
    pub occupancy: Option<f64>,
    /// Mean wall time of the method (s); null for `initial`.
    pub time_s: Option<f64>,
    /// Seeds run.
    pub seeds: usize,
    /// Seeds on which the method returned an error.
    pub failures: usize,
    /// APE per seed (seed 1 first), null where it failed.
    pub ape_m_per_seed: Vec<Option<f64>>,
    /// Error texts of the failed seeds, as "seed N: text".
    pub errors: Vec<String>,
}

fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

impl Row {
    /// The cell of `method` on `scene` from its per-seed measurements (seed 1 first).
    pub fn new(scene: &str, method: BenchMethod, runs: &[(u64, &Measurement)]) -> Self {
        Self {
            scene: scene.to_owned(),
            method: method.name(),
            ape_m: mean(runs.iter().filter_map(|(_, m)| m.ape_m)),
            occupancy: mean(runs.iter().filter_map(|(_, m)| m.occupancy)),
            time_s: mean(runs.iter().filter_map(|(_, m)| m.time_s)),
            seeds: runs.len(),
            failures: runs.iter().filter(|(_, m)| m.error.is_some()).count(),
            ape_m_per_seed: runs.iter().map(|(_, m)| m.ape_m).collect(),
            errors: runs
                .iter()
                .filter_map(|(seed, m)| m.error.as_ref().map(|e| format!("seed {seed}: {e}")))
                .collect(),
        }
    }
}

/// Which number a table shows.
#[derive(Debug, Clone, Copy)]
pub enum Metric {
    /// APE (m).
    Ape,
    /// Occupied voxels.
    Occupancy,
    /// Wall time (s).
    Time,
}

impl Metric {
    /// Every table, in print order.
    pub const ALL: [Metric; 3] = [Metric::Ape, Metric::Occupancy, Metric::Time];

    fn title(self) -> &'static str {
        match self {
            Metric::Ape => "APE (m): translation RMSE after SE(3) alignment, mean over seeds",
            Metric::Occupancy => {
                "Occupied 0.1 m voxels of the merged cloud (mean over 8 grid offsets and over \
                 seeds; fewer = sharper)"
            }
            Metric::Time => "Wall time of the method (s, simulation excluded), mean over seeds",
        }
    }

    /// The cell text: the value, `failed` when every seed failed, a `*` when some did.
    fn cell(self, row: &Row) -> String {
        let value = match self {
            Metric::Ape => row.ape_m.map(|v| format!("{v:.4}")),
            Metric::Occupancy => row.occupancy.map(|v| format!("{v:.0}")),
            Metric::Time if row.method == BenchMethod::Initial.name() => Some("-".to_owned()),
            Metric::Time => row.time_s.map(|v| format!("{v:.2}")),
        };
        match value {
            None => "failed".to_owned(),
            Some(v) if row.failures > 0 => format!("{v}*"),
            Some(v) => v,
        }
    }
}

/// The row of `method` on `scene`.
fn find<'a>(rows: &'a [Row], scene: &str, method: BenchMethod) -> Option<&'a Row> {
    rows.iter()
        .find(|r| r.scene == scene && r.method == method.name())
}

/// PSS-BA's wall time over BALM's on `scene` (the speed target of issue 12: at most 1).
fn time_ratio(rows: &[Row], scene: &str) -> Option<f64> {
    let time = |method| find(rows, scene, method).and_then(|r| r.time_s);
    let (pss_ba, balm) = (time(BenchMethod::PssBa)?, time(BenchMethod::Balm)?);
    (balm > 0.0).then(|| pss_ba / balm)
}

/// The ratio row's cell on `scene`.
fn ratio_cell(rows: &[Row], scene: &str) -> String {
    time_ratio(rows, scene).map_or_else(|| "-".to_owned(), |r| format!("{r:.2}x"))
}

/// Label of the ratio row under the wall-time table.
const RATIO_LABEL: &str = "PSS-BA/BALM";

/// One plain-text table (fixed-width columns).
pub fn text_table(rows: &[Row], scenes: &[String], metric: Metric) -> String {
    let mut out = format!("{}\n", metric.title());
    let _ = write!(out, "{:<12}", "method");
    for scene in scenes {
        let _ = write!(out, " {scene:>10}");
    }
    out.push('\n');
    for method in BenchMethod::ALL {
        let _ = write!(out, "{:<12}", method.label());
        for scene in scenes {
            let cell = find(rows, scene, method).map_or_else(|| "-".to_owned(), |r| metric.cell(r));
            let _ = write!(out, " {cell:>10}");
        }
        out.push('\n');
    }
    if matches!(metric, Metric::Time) {
        let _ = write!(out, "{RATIO_LABEL:<12}");
        for scene in scenes {
            let _ = write!(out, " {:>10}", ratio_cell(rows, scene));
        }
        out.push('\n');
    }
    out
}

/// One markdown table; the APE table shows the paper's number beside ours.
pub fn markdown_table(rows: &[Row], scenes: &[String], metric: Metric) -> String {
    let mut out = format!("**{}**", metric.title());
    if matches!(metric, Metric::Ape) {
        out.push_str(" — ours (paper's Table I)");
    }
    out.push_str("\n\n| method |");
    for scene in scenes {
        let _ = write!(out, " {scene} |");
    }
    out.push_str("\n|---|");
    out.push_str(&"---:|".repeat(scenes.len()));
    out.push('\n');
    for (k, method) in BenchMethod::ALL.into_iter().enumerate() {
        let _ = write!(out, "| {} |", method.label());
        for scene in scenes {
            let mut cell =
                find(rows, scene, method).map_or_else(|| "-".to_owned(), |r| metric.cell(r));
            if let (Metric::Ape, Some(paper)) = (metric, paper_ape(scene)) {
                let _ = write!(cell, " ({:.2})", paper[k]);
            }
            let _ = write!(out, " {cell} |");
        }
        out.push('\n');
    }
    if matches!(metric, Metric::Time) {
        let _ = write!(out, "| {RATIO_LABEL} |");
        for scene in scenes {
            let _ = write!(out, " {} |", ratio_cell(rows, scene));
        }
        out.push('\n');
    }
    out
}

/// Failures listed under the tables (empty when none).
pub fn failure_notes(rows: &[Row]) -> String {
    let mut out = String::new();
    for row in rows.iter().filter(|r| r.failures > 0) {
        for error in &row.errors {
            let _ = writeln!(out, "* {} on {}, {error}", row.method, row.scene);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(scene: &str, method: BenchMethod, time_s: Option<f64>) -> Row {
        Row {
            scene: scene.to_owned(),
            method: method.name(),
            ape_m: Some(0.01),
            occupancy: Some(1.0),
            time_s,
            seeds: 1,
            failures: 0,
            ape_m_per_seed: vec![Some(0.01)],
            errors: Vec::new(),
        }
    }

    #[test]
    fn time_tables_end_with_the_pss_ba_over_balm_ratio() {
        let rows = vec![
            row("a", BenchMethod::Balm, Some(2.0)),
            row("a", BenchMethod::PssBa, Some(5.0)),
            row("b", BenchMethod::Balm, None),
            row("b", BenchMethod::PssBa, Some(1.0)),
        ];
        let scenes = vec!["a".to_owned(), "b".to_owned()];
        let text = text_table(&rows, &scenes, Metric::Time);
        let last = text.lines().last().expect("rows");
        assert!(last.starts_with(RATIO_LABEL), "{text}");
        assert!(
            last.contains("2.50x") && last.trim_end().ends_with('-'),
            "{last}"
        );
        let markdown = markdown_table(&rows, &scenes, Metric::Time);
        assert!(
            markdown.contains("| PSS-BA/BALM | 2.50x | - |"),
            "{markdown}"
        );
        let ape = text_table(&rows, &scenes, Metric::Ape);
        assert!(!ape.contains(RATIO_LABEL), "only under the time table");
    }
}

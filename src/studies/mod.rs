//! The studies of `skinbox report`: speed against accuracy, and the point where each method
//! fails (docs/design.md sections 2, 4, 6 and 7).
//!
//! - C1 [`send_on_delta`]: per scene, packet rate against reconstruction error over a sweep
//!   of thresholds around the papers' Table I.
//! - C2 [`fidelity`]: wall time per simulated second against error relative to the RTL, for
//!   the RTL co-simulation and the closed-form [`rate_model`], across skin sizes.
//! - C3 [`batching`]: the flush timeout's latency against the link capacity it reaches.
//! - C4 [`boundaries`]: UART baud mismatch (RTL), cells per bus, sensor noise, event loss.
//! - C5 [`sample_time`]: when each packet was sampled, as the host assigns it by three
//!   methods, against the cell models' truth; cost and failure boundaries.
//! - C6 [`sample_rate`]: the scenes' packet rate against sample rate, beside the papers'
//!   Fig. 11 fits.
//!
//! [`run`] runs them and writes `summary.md` (every number behind every chart, as tables)
//! and each chart as PNG and SVG into one directory. `quick` runs reduced sweeps (the test
//! suite runs them). Every point of every grid goes through [`points::Points`], so a run can
//! be split into shards on several machines and merged ([`points`]).

pub mod batching;
pub mod boundaries;
pub mod chart;
pub mod fidelity;
pub mod mode_rate;
pub mod points;
pub mod rate_model;
pub mod sample_rate;
pub mod sample_time;
pub mod send_on_delta;

use anyhow::Context;
pub use points::{Merged, Points, Shard, ShardFile};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What to run.
#[derive(Debug, Clone)]
pub struct Options {
    /// Output directory (created if missing).
    pub out: PathBuf,
    /// Reduced sweeps.
    pub quick: bool,
    /// Compute only this share of the points and write them, no summary or charts.
    pub shard: Option<Shard>,
    /// Compute nothing: take every point from these merged shards (their `quick` wins).
    pub merged: Option<Merged>,
}

/// Reports progress: one call per finished step.
pub struct Progress<'a> {
    done: u64,
    total: u64,
    report: &'a mut dyn FnMut(u64, u64, &str),
}

impl<'a> Progress<'a> {
    /// A progress of `total` steps, reported to `report(done, total, what is next)`.
    pub fn new(total: u64, report: &'a mut dyn FnMut(u64, u64, &str)) -> Self {
        Progress {
            done: 0,
            total,
            report,
        }
    }

    /// Starts the next step.
    pub fn step(&mut self, what: &str) {
        (self.report)(self.done, self.total, what);
        self.done += 1;
    }
}

/// A table of the summary.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Column headers.
    pub headers: Vec<String>,
    /// Rows of cells, as printed.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// An empty table with these columns.
    pub fn new(headers: &[&str]) -> Table {
        Table {
            headers: headers.iter().map(|h| h.to_string()).collect(),
            rows: Vec::new(),
        }
    }

    /// Appends a row (as many cells as headers).
    pub fn row(&mut self, cells: Vec<String>) {
        assert_eq!(cells.len(), self.headers.len(), "one cell per column");
        self.rows.push(cells);
    }

    /// The table as GitHub markdown.
    pub fn to_markdown(&self) -> String {
        let mut s = format!("| {} |\n", self.headers.join(" | "));
        let _ = writeln!(s, "|{}", "---|".repeat(self.headers.len()));
        for r in &self.rows {
            let _ = writeln!(s, "| {} |", r.join(" | "));
        }
        s
    }
}

/// One study's part of the summary.
#[derive(Debug, Clone)]
pub struct Section {
    /// `C1` .. `C4d`.
    pub id: &'static str,
    /// Heading.
    pub title: String,
    /// What was done and how to read it.
    pub text: String,
    /// Key numbers: (what, value), printed as a two-column table.
    pub findings: Vec<(String, String)>,
    /// Every number behind the charts.
    pub tables: Vec<Table>,
    /// The charts.
    pub charts: Vec<chart::Chart>,
}

/// What [`run`] wrote.
#[derive(Debug, Clone)]
pub struct Written {
    /// The summary (not for a shard).
    pub summary: Option<PathBuf>,
    /// Every chart file, PNG and SVG (none for a shard).
    pub charts: Vec<PathBuf>,
    /// A shard's points file.
    pub shard_file: Option<PathBuf>,
    /// Points this run computed (none for a merge).
    pub computed: usize,
    /// Points of the whole grid.
    pub points: usize,
    /// Wall time of the whole run, s.
    pub wall_s: f64,
}

/// Steps [`run`] reports.
pub fn steps(quick: bool) -> u64 {
    send_on_delta::steps(quick)
        + fidelity::steps(quick)
        + batching::steps(quick)
        + boundaries::steps(quick)
        + sample_time::steps(quick)
        + sample_rate::steps(quick)
        + mode_rate::steps(quick)
        + 1
}

/// Runs every study and writes the summary and charts; or, for a shard, its points.
pub fn run(options: &Options, progress: &mut Progress) -> anyhow::Result<Written> {
    let started = Instant::now();
    std::fs::create_dir_all(&options.out)
        .with_context(|| format!("creating {}", options.out.display()))?;
    let (mut grid, q) = match (&options.merged, options.shard) {
        (Some(_), Some(_)) => anyhow::bail!("a run is either a shard or a merge, not both"),
        (Some(merged), None) => (Points::replay(merged.clone()), merged.quick),
        (None, Some(shard)) => (Points::shard(shard), options.quick),
        (None, None) => (Points::all(), options.quick),
    };
    let mut sections = vec![send_on_delta::study(q, progress, &mut grid)?];
    sections.push(fidelity::study(q, progress, &mut grid)?);
    sections.push(batching::study(q, progress, &mut grid)?);
    sections.extend(boundaries::study(q, progress, &mut grid)?);
    sections.push(sample_time::study(q, progress, &mut grid)?);
    sections.push(sample_rate::study(q, progress, &mut grid)?);
    sections.push(mode_rate::study(q, progress, &mut grid)?);
    let points = grid.len();
    if grid.shard_of().is_some() {
        progress.step("writing the shard's points");
        let file = grid
            .finish(q, started.elapsed().as_secs_f64())?
            .expect("a shard's file");
        let path = file.write(&options.out)?;
        return Ok(Written {
            summary: None,
            charts: Vec::new(),
            shard_file: Some(path),
            computed: file.rows.len(),
            points,
            wall_s: started.elapsed().as_secs_f64(),
        });
    }
    let computed = if options.merged.is_some() { 0 } else { points };
    grid.finish(q, 0.0)?;
    progress.step("writing the charts");
    let mut charts = Vec::new();
    for s in &sections {
        for c in &s.charts {
            charts.extend(c.write(&options.out)?);
        }
    }
    let wall_s = started.elapsed().as_secs_f64();
    let summary = options.out.join("summary.md");
    let origin = match &options.merged {
        Some(m) => format!(
            ", merged from {} shards (the longest ran {:.1} s of wall time).",
            m.shards, m.longest_shard_s
        ),
        None => format!(" in {wall_s:.1} s of wall time."),
    };
    std::fs::write(&summary, summary_markdown(&sections, q, &origin))
        .with_context(|| format!("writing {}", summary.display()))?;
    Ok(Written {
        summary: Some(summary),
        charts,
        shard_file: None,
        computed,
        points,
        wall_s,
    })
}

fn summary_markdown(sections: &[Section], quick: bool, origin: &str) -> String {
    let mut s = String::from("# skinbox report\n\n");
    let _ = writeln!(
        s,
        "Written by `skinbox report{}`{origin} Every number behind \
         every chart is in the tables below; the charts are beside this file as PNG and SVG.\n",
        if quick { " --quick" } else { "" }
    );
    for sec in sections {
        let _ = writeln!(s, "## {} {}\n\n{}\n", sec.id, sec.title, sec.text);
        for c in &sec.charts {
            let _ = writeln!(s, "![{}]({}.png)\n", c.title, c.name);
        }
        if !sec.findings.is_empty() {
            let mut t = Table::new(&["finding", "value"]);
            for (k, v) in &sec.findings {
                t.row(vec![k.clone(), v.clone()]);
            }
            let _ = writeln!(s, "{}", t.to_markdown());
        }
        for t in &sec.tables {
            let _ = writeln!(s, "{}", t.to_markdown());
        }
    }
    s
}

/// The cell models' scene file `name` (`cosim/scenes/<name>.toml`).
pub fn scene(name: &str) -> anyhow::Result<skinbox_cells::Scene> {
    Ok(skinbox_cells::Scene::load(
        &skinbox_cells::scenes_dir().join(format!("{name}.toml")),
    )?)
}

/// Mean RMS reconstruction error of the eight channels that carry a signal (the second
/// temperature sensor reads 0), % of each channel's full range.
pub fn mean_error_pct(stats: &skinbox_cells::SceneStats) -> f64 {
    use skinbox_protocol::Channel;
    Channel::ALL[..8]
        .iter()
        .map(|&c| stats.rms_error_pct(c))
        .sum::<f64>()
        / 8.0
}

/// Path helper for tests and the command: `<dir>/<name>.png`.
pub fn png(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}.png"))
}

//! `skinbox report`: the studies (speed against accuracy, failure boundaries) with their
//! charts and a summary; the work is in `skinbox::studies`.

use skinbox::studies::{run, steps, Options, Progress};
use std::path::PathBuf;

/// Arguments of `skinbox report`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory for summary.md and the charts (PNG and SVG).
    #[arg(long, default_value = "build/report")]
    out: PathBuf,
    /// Reduced sweeps (what the test suite runs): smaller scenes, fewer points.
    #[arg(long)]
    quick: bool,
}

#[derive(serde::Serialize)]
struct Output {
    summary: PathBuf,
    charts: Vec<PathBuf>,
    wall_s: f64,
}

/// Runs the studies.
pub fn run_report(args: &Args, json: bool) -> anyhow::Result<()> {
    let options = Options {
        out: args.out.clone(),
        quick: args.quick,
    };
    let bar = indicatif::ProgressBar::new(steps(args.quick));
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "[{bar:40}] {pos}/{len} {elapsed} (ETA {eta}) {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let mut report = |done: u64, _total: u64, what: &str| {
        bar.set_position(done);
        bar.set_message(what.to_string());
    };
    let mut progress = Progress::new(steps(args.quick), &mut report);
    let written = run(&options, &mut progress)?;
    bar.finish_and_clear();
    let out = Output {
        summary: written.summary,
        charts: written.charts,
        wall_s: written.wall_s,
    };
    if json {
        return super::print_json(&out);
    }
    println!(
        "wrote {} and {} charts in {:.1} s",
        out.summary.display(),
        out.charts.len(),
        out.wall_s
    );
    Ok(())
}

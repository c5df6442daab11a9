//! `skinbox report`: the studies (speed against accuracy, failure boundaries) with their
//! charts and a summary; the work is in `skinbox::studies`. `--shard K/N` computes a share
//! of the points on one machine, `--merge` writes the report from every share.

use skinbox::studies::{run, steps, Merged, Options, Progress, Shard, ShardFile};
use std::path::PathBuf;

/// Arguments of `skinbox report`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory for summary.md and the charts (PNG and SVG), or a shard's points file.
    #[arg(long, default_value = "build/report")]
    out: PathBuf,
    /// Reduced sweeps (what the test suite runs): smaller scenes, fewer points.
    #[arg(long)]
    quick: bool,
    /// Compute only share K of N of every study's points (K from 1 to N) and write them to
    /// OUT/points-K-of-N.jsonl, without summary or charts; merge the N shares with --merge.
    #[arg(long, value_name = "K/N", conflicts_with = "merge")]
    shard: Option<Shard>,
    /// Write the summary and charts from the shard files (points-K-of-N.jsonl) in these
    /// directories, computing nothing; every shard of one split must be there once.
    #[arg(long, value_name = "DIR", num_args = 1..)]
    merge: Vec<PathBuf>,
}

#[derive(serde::Serialize)]
struct Output {
    summary: Option<PathBuf>,
    charts: Vec<PathBuf>,
    shard_file: Option<PathBuf>,
    points_computed: usize,
    points: usize,
    wall_s: f64,
}

/// Runs the studies.
pub fn run_report(args: &Args, json: bool) -> anyhow::Result<()> {
    let merged = if args.merge.is_empty() {
        None
    } else {
        let merged = Merged::new(ShardFile::read_dirs(&args.merge)?)?;
        if args.quick && !merged.quick {
            anyhow::bail!("--quick given, but the shards ran without --quick");
        }
        Some(merged)
    };
    let quick = merged.as_ref().map_or(args.quick, |m| m.quick);
    let options = Options {
        out: args.out.clone(),
        quick,
        shard: args.shard,
        merged,
    };
    let bar = indicatif::ProgressBar::new(steps(quick));
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
    let mut progress = Progress::new(steps(quick), &mut report);
    let written = run(&options, &mut progress)?;
    bar.finish_and_clear();
    let out = Output {
        summary: written.summary,
        charts: written.charts,
        shard_file: written.shard_file,
        points_computed: written.computed,
        points: written.points,
        wall_s: written.wall_s,
    };
    if json {
        return super::print_json(&out);
    }
    match (&out.summary, &out.shard_file) {
        (_, Some(file)) => println!(
            "wrote {}: {} of {} points in {:.1} s",
            file.display(),
            out.points_computed,
            out.points,
            out.wall_s
        ),
        (Some(summary), None) => println!(
            "wrote {} and {} charts in {:.1} s",
            summary.display(),
            out.charts.len(),
            out.wall_s
        ),
        (None, None) => unreachable!("a run writes a summary or a shard file"),
    }
    Ok(())
}

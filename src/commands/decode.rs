//! `skinbox decode`: a pcap's box datagrams to cell packets or full samples, as CSV or JSON
//! lines in physical units with box time, each with its estimated sample time in box time
//! and on the pcap's clock (docs/time.md).

use clap::Args;
use skinbox_host::output::{sort_by_host_time, RowFormat, RowKind, RowWriter};
use skinbox_host::pcap::{self, PcapOptions};
use skinbox_host::DecoderConfig;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `skinbox decode`.
#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// The pcap to decode.
    pub file: PathBuf,
    /// Comma-separated values (the default).
    #[arg(long, conflicts_with = "jsonl")]
    pub csv: bool,
    /// One JSON object per line (also chosen by --json).
    #[arg(long)]
    pub jsonl: bool,
    /// One row per packet: the cell's full nine-channel sample after it (event to data).
    #[arg(long, conflicts_with = "events")]
    pub samples: bool,
    /// One row per cell packet as received (the default).
    #[arg(long)]
    pub events: bool,
    /// Write the rows here instead of stdout.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
    /// Only UDP datagrams from or to this port.
    #[arg(long)]
    pub port: Option<u16>,
    /// The cells' sample rate, for the summary and the sample times; without it, learned
    /// from the stamps (a first pass over the file).
    #[arg(long)]
    pub sample_rate_hz: Option<f64>,
    /// Rows in order of their sample's host time (several boxes merged on one host time
    /// line) instead of arrival order; holds every row in memory.
    #[arg(long)]
    pub by_host_time: bool,
    /// Where the cells sit on their chains, for the sample times.
    #[command(flatten)]
    pub timing: super::TimingArgs,
    /// ROS 2 messages: with --mcap, a recording instead of rows.
    #[command(flatten)]
    pub ros: super::ros::RosArgs,
}

/// Decodes the file; rows on stdout (or --output), a one-line summary on stderr.
pub fn run(args: DecodeArgs, json: bool) -> anyhow::Result<()> {
    super::check_sample_rate(args.sample_rate_hz)?;
    let bytes = pcap::read_file(&args.file)?;
    let format = if args.jsonl || (json && !args.csv) {
        RowFormat::JsonLines
    } else {
        RowFormat::Csv
    };
    let kind = if args.samples {
        RowKind::Samples
    } else {
        RowKind::Packets
    };
    let out: Box<dyn Write> = match &args.output {
        Some(path) => Box::new(
            std::fs::File::create(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?,
        ),
        None => Box::new(std::io::stdout().lock()),
    };
    let options = PcapOptions {
        decoder: DecoderConfig {
            sample_rate_hz: args.sample_rate_hz,
            ..DecoderConfig::default()
        },
        udp_port: args.port,
    };
    // The sample clocks need the nominal rate up front: given, or learned in a first pass.
    let rate_hz = match args.sample_rate_hz {
        Some(rate) => rate,
        None => pcap::decode_pcap_with(&bytes, &options, &mut ())?.sample_rate_hz,
    };
    let timing = args.timing.timing(rate_hz)?;
    anyhow::ensure!(
        args.ros.foxglove.is_none(),
        "--foxglove serves a live capture: use it with skinbox capture or emulate"
    );
    anyhow::ensure!(
        !args.ros.ros2,
        "--ros2 publishes a live capture: use it with skinbox capture or emulate"
    );
    if let Some(path) = &args.ros.mcap {
        return record_mcap(&bytes, &options, timing, &args, path, rate_hz, json);
    }
    let (report, (times, methods), rows) = if args.by_host_time {
        let mut writer = RowWriter::new(Vec::new(), format, kind).with_timing(timing);
        let report = pcap::decode_pcap_with(&bytes, &options, &mut writer)?;
        let times = timing_summary(&writer);
        let (rows, text) = writer.finish_into()?;
        let sorted = sort_by_host_time(&String::from_utf8_lossy(&text), format);
        let mut out = std::io::BufWriter::new(out);
        match out.write_all(sorted.as_bytes()).and_then(|()| out.flush()) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
            Err(e) => return Err(e.into()),
        }
        (report, times, rows)
    } else {
        let mut writer =
            RowWriter::new(std::io::BufWriter::new(out), format, kind).with_timing(timing);
        let report = pcap::decode_pcap_with(&bytes, &options, &mut writer)?;
        let times = timing_summary(&writer);
        let rows = match writer.finish() {
            Ok(rows) => rows,
            // The reader went away (`| head`): not an error of ours.
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
            Err(e) => return Err(e.into()),
        };
        (report, times, rows)
    };
    eprintln!(
        "{rows} rows from {} records in {} datagrams of {} boxes; {} datagrams missing, {} event packets missing, bad input {}; other traffic {}",
        report.records,
        report.records_datagrams,
        report.boxes.len(),
        report.losses.datagrams_missing,
        report.losses.event_packets_missing,
        report.bad_input,
        report.other_traffic
    );
    eprintln!(
        "sample times at {rate_hz} Hz: {}; host times: {}",
        super::sample_method_line(methods),
        super::host_time_line(&times)
    );
    Ok(())
}

/// How the writer's records were timed: each box's host-time map, and the records by
/// sample-time method.
fn timing_summary<W: std::io::Write>(
    writer: &RowWriter<W>,
) -> (
    Vec<skinbox_host::timing::BoxTimeSummary>,
    skinbox_host::timing::SampleMethodCounts,
) {
    writer
        .timing()
        .map(|t| (t.summary(), t.method_counts()))
        .unwrap_or_default()
}

/// `--mcap`: the skinbox_msgs topics to an MCAP recording; a summary on stderr (or JSON).
fn record_mcap(
    bytes: &[u8],
    options: &PcapOptions,
    timing: skinbox_host::timing::Timing,
    args: &DecodeArgs,
    path: &std::path::Path,
    rate_hz: f64,
    json: bool,
) -> anyhow::Result<()> {
    let out = skinbox_ros::mcap_out::McapOutput::create(path)?;
    // Decoding and timing on this thread, the messages and the file on another.
    let mut sink =
        skinbox_ros::sink::RosSink::pipelined(timing, args.ros.settings()?, vec![Box::new(out)])?;
    let report = pcap::decode_pcap_with(bytes, options, &mut sink)?;
    let published = sink.finish()?;
    if json {
        return super::print_json(&serde_json::json!({
            "mcap": path,
            "published": published,
            "sample_rate_hz": rate_hz,
            "report": report,
        }));
    }
    eprintln!(
        "{}: {} samples in {} messages on /skinbox/samples, {} on /skinbox/status, {} on /skinbox/activity; {} datagrams missing, bad input {}",
        path.display(),
        published.samples,
        published.samples_messages,
        published.status_messages,
        published.activity_messages,
        report.losses.datagrams_missing,
        report.bad_input
    );
    Ok(())
}

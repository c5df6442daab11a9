//! `skinbox capture`: receive the box's datagrams live on a UDP socket.

use clap::Args;
use skinbox_host::live::{self, CaptureLimits};
use skinbox_host::output::{RowFormat, RowKind, RowWriter};
use skinbox_host::pcap::PcapFrameWriter;
use skinbox_host::{Decoder, DecoderConfig};
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `skinbox capture`.
#[derive(Debug, Args)]
pub struct CaptureArgs {
    /// Address to listen on, e.g. 0.0.0.0:54091, the box's default host port (port 0 picks
    /// a free port; the bound address is printed on stderr first). Every box sending to it
    /// is followed on its own (box id and source address).
    #[arg(long)]
    pub listen: SocketAddr,
    /// Record every datagram to this pcap file.
    #[arg(long)]
    pub pcap: Option<PathBuf>,
    /// Stop after this many milliseconds (default: at Ctrl-C).
    #[arg(long)]
    pub duration_ms: Option<u64>,
    /// Stop after this many datagrams.
    #[arg(long)]
    pub count: Option<u64>,
    /// Socket receive buffer to ask for, in bytes (a warning says when the kernel grants
    /// less, and which sysctl allows more).
    #[arg(long, default_value_t = live::DEFAULT_RECV_BUFFER_BYTES)]
    pub recv_buffer: usize,
    /// Datagrams taken per receive call.
    #[arg(long, default_value_t = live::DEFAULT_BATCH)]
    pub batch: usize,
    /// Wait after draining the socket before waiting again, in microseconds, so one
    /// wake-up takes many datagrams (0: wake for every datagram).
    #[arg(long, default_value_t = live::DEFAULT_COALESCE.as_micros() as u64)]
    pub coalesce_us: u64,
    /// The cells' sample rate, for rates in % of data mode; without it, learned from the
    /// stamps (the sample times of `--rows` then assume 125 Hz: give it for them).
    #[arg(long)]
    pub sample_rate_hz: Option<f64>,
    /// Claim the stream of the box at this command address first: a stream-to command
    /// from the capture's own socket, so the box sends its datagrams here.
    #[arg(long)]
    pub claim: Option<String>,
    /// With --claim: send the box a read-tick command this often, in milliseconds; each
    /// acknowledgement is an exchange that maps the box's time to the host's (the rows'
    /// host times then come with an error bound). 0: none.
    #[arg(long, default_value_t = 100, requires = "claim")]
    pub exchange_ms: u64,
    /// With --claim: take each exchange's host send time from the host's own clock just
    /// before the command is sent, not from the kernel's send stamp (SO_TIMESTAMPING, the
    /// default; an exchange without one falls back to the host's clock, counted in
    /// `exchange_stamps`).
    #[arg(long, requires = "claim")]
    pub user_space_stamps: bool,
    /// Write every record as a CSV row to this file (`-`: stdout), with its sample time in
    /// box time and in host time (CLOCK_REALTIME, from the kernel's receive timestamps).
    #[arg(long)]
    pub rows: Option<PathBuf>,
    /// With --rows: one row per record, the cell's full sample after it (event to data).
    #[arg(long, requires = "rows")]
    pub samples: bool,
    /// Where the cells sit on their chains, for the sample times.
    #[command(flatten)]
    pub timing: super::TimingArgs,
    /// ROS 2 messages: an MCAP recording, the Foxglove live view (not with --rows).
    #[command(flatten)]
    pub ros: super::ros::RosArgs,
}

/// The sample times the rows and the ROS 2 outputs carry.
type Timing = skinbox_host::timing::Timing;

/// The `--rows` writer.
type Rows = RowWriter<std::io::BufWriter<Box<dyn Write>>>;

/// With `--claim`: the claimed stream's socket, its exchange and the read-tick sender.
#[allow(clippy::type_complexity)]
fn claim_stream(
    args: &CaptureArgs,
    socket: tokio::net::UdpSocket,
    stop_read_ticks: &std::sync::Arc<std::sync::atomic::AtomicBool>,
    send_stamps: &Option<skinbox_host::kernel_stamps::CommandSendStamps>,
) -> anyhow::Result<(
    tokio::net::UdpSocket,
    Option<skinbox_host::control::Exchange>,
    Option<std::thread::JoinHandle<u64>>,
)> {
    Ok(match &args.claim {
        Some(box_addr) => {
            let live::Claimed {
                socket,
                exchange,
                box_addr: to,
                sender,
            } = live::claim(socket, box_addr).map_err(|e| anyhow::anyhow!("--claim {e}"))?;
            eprintln!("claimed the stream: {}", exchange.ack);
            let read_ticks = (args.exchange_ms > 0).then(|| {
                live::send_read_ticks_stamped(
                    sender,
                    to,
                    exchange.ack.box_id,
                    Duration::from_millis(args.exchange_ms),
                    stop_read_ticks.clone(),
                    send_stamps.clone(),
                )
            });
            (socket, Some(exchange), read_ticks)
        }
        None => (socket, None, None),
    })
}

/// The `--pcap` recorder, when asked for.
fn open_pcap(
    args: &CaptureArgs,
) -> anyhow::Result<Option<PcapFrameWriter<std::io::BufWriter<std::fs::File>>>> {
    Ok(match &args.pcap {
        Some(path) => Some(PcapFrameWriter::new(std::io::BufWriter::new(
            std::fs::File::create(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?,
        ))?),
        None => None,
    })
}

/// The `--rows` writer, when asked for, with the sample times of `timing`.
fn open_rows(
    args: &CaptureArgs,
    timing: impl FnOnce() -> anyhow::Result<Timing>,
) -> anyhow::Result<Option<Rows>> {
    Ok(match &args.rows {
        Some(path) => {
            let out: Box<dyn Write> = if path.as_os_str() == "-" {
                Box::new(std::io::stdout())
            } else {
                Box::new(
                    std::fs::File::create(path)
                        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?,
                )
            };
            let kind = if args.samples {
                RowKind::Samples
            } else {
                RowKind::Packets
            };
            Some(
                RowWriter::new(std::io::BufWriter::new(out), RowFormat::Csv, kind)
                    .with_timing(timing()?),
            )
        }
        None => None,
    })
}

/// The ROS 2 outputs, when any is asked for, with the sample times of `timing`.
fn open_ros(
    args: &CaptureArgs,
    timing: impl FnOnce() -> anyhow::Result<Timing>,
) -> anyhow::Result<Option<skinbox_ros::sink::RosSink>> {
    if !args.ros.any() {
        return Ok(None);
    }
    let mut outputs: Vec<Box<dyn skinbox_ros::sink::Output + Send>> = Vec::new();
    if let Some(path) = &args.ros.mcap {
        outputs.push(Box::new(skinbox_ros::mcap_out::McapOutput::create(path)?));
    }
    if let Some(addr) = args.ros.foxglove {
        let server = skinbox_ros::foxglove::FoxgloveServer::start(addr)?;
        eprintln!("foxglove live view on ws://{}", server.local_addr());
        outputs.push(Box::new(server));
    }
    if args.ros.ros2 {
        let dds = skinbox_ros::dds::DdsOutput::create(
            skinbox_ros::dds::ros_domain_id()?,
            skinbox_ros::dds::DdsSettings {
                samples_best_effort: args.ros.ros2_best_effort,
            },
        )?;
        eprintln!("ROS 2 topics over DDS in domain {}", dds.domain());
        outputs.push(Box::new(DdsReport(dds)));
    }
    let timing = timing()?;
    let settings = args.ros.settings()?;
    if args.ros.foxglove.is_none() && !args.ros.ros2 {
        // A recording only: the messages and the file on a thread of their own,
        // off the receiving thread.
        Ok(Some(skinbox_ros::sink::RosSink::pipelined(
            timing, settings, outputs,
        )?))
    } else {
        // Live outputs: each message out as its datagram is decoded.
        Ok(Some(skinbox_ros::sink::RosSink::new(
            timing, settings, outputs,
        )))
    }
}

/// Resolves after `duration_ms`, or at Ctrl-C.
async fn shutdown(duration_ms: Option<u64>) {
    match duration_ms {
        Some(ms) => {
            tokio::select! {
                _ = tokio::time::sleep(Duration::from_millis(ms)) => {}
                _ = tokio::signal::ctrl_c() => {}
            }
        }
        None => {
            let _ = tokio::signal::ctrl_c().await;
        }
    }
}

/// The summary line printed every second on stderr.
fn progress_line(s: &live::CaptureStats, d: &Decoder) {
    // Cheap getters: no report (and no rate learning) on the receive thread.
    eprintln!(
        "{:7.1} s: {} datagrams, {} records, {} missing, {} bad, {} other, {:.1} % CPU",
        s.wall_s,
        s.datagrams,
        d.records(),
        d.datagrams_missing(),
        d.bad_input_total(),
        d.other_traffic().total,
        100.0 * s.cpu_s / s.wall_s.max(1e-9)
    );
}

/// What a capture ends with, for its report.
struct Outcome {
    stats: live::CaptureStats,
    granted: usize,
    recv_buffer_warning: Option<String>,
    claimed: Option<skinbox_host::control::Exchange>,
    passed_over: u64,
    report: skinbox_host::Report,
    host_times: Option<Vec<skinbox_host::timing::BoxTimeSummary>>,
    sample_methods: Option<skinbox_host::timing::SampleMethodCounts>,
    read_ticks_sent: Option<u64>,
    exchanges_unused: Option<u64>,
    exchange_stamps: Option<skinbox_host::timing::ExchangeStampCounts>,
    published: Option<skinbox_ros::sink::Published>,
}

/// The timing's outcome, the ROS 2 messages published; closes the row and ROS outputs.
#[allow(clippy::type_complexity)]
fn finish_outputs(
    rows: Option<Rows>,
    ros: Option<skinbox_ros::sink::RosSink>,
    read_ticks_sent: Option<u64>,
) -> anyhow::Result<(
    Option<Vec<skinbox_host::timing::BoxTimeSummary>>,
    Option<skinbox_host::timing::SampleMethodCounts>,
    Option<skinbox_host::timing::ExchangeStampCounts>,
    Option<skinbox_ros::sink::Published>,
    Option<u64>,
)> {
    let host_times = rows
        .as_ref()
        .and_then(|w| w.timing())
        .or(ros.as_ref().map(|r| r.timing()))
        .map(|t| t.summary());
    let sample_methods = rows
        .as_ref()
        .and_then(|w| w.timing())
        .or(ros.as_ref().map(|r| r.timing()))
        .map(|t| t.method_counts());
    // which stamps the exchanges' send times are (with --claim and a timing)
    let exchange_stamps = rows
        .as_ref()
        .and_then(|w| w.timing())
        .or(ros.as_ref().map(|r| r.timing()))
        .filter(|_| read_ticks_sent.is_some())
        .map(|t| t.exchange_stamps().clone());
    let published = match ros {
        Some(r) => Some(r.finish()?),
        None => None,
    };
    let exchanges_unused = rows
        .as_ref()
        .and_then(|w| w.timing())
        .map(|t| t.exchanges_unused());
    if let Some(w) = rows {
        match w.finish() {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok((
        host_times,
        sample_methods,
        exchange_stamps,
        published,
        exchanges_unused,
    ))
}

impl Outcome {
    /// Prints the report: JSON, or the summary and its host time lines.
    fn print(&self, json: bool) -> anyhow::Result<()> {
        if json {
            return super::print_json(&serde_json::json!({
                "capture": self.stats,
                "recv_buffer_bytes": live::usable_recv_buffer(self.granted),
                "recv_buffer_warning": self.recv_buffer_warning,
                "claim": self.claimed.as_ref().map(|e| serde_json::json!({
                    "result": e.ack.result.name(),
                    "attempts": e.attempts,
                    "rtt_us": e.rtt_ns as f64 / 1000.0,
                    "datagrams_before_capture": self.passed_over,
                    "datagrams_dropped": e.dropped,
                })),
                "report": self.report,
                "host_times": self.host_times,
                "sample_methods": self.sample_methods,
                "read_ticks_sent": self.read_ticks_sent,
                "exchanges_unused": self.exchanges_unused,
                "exchange_stamps": self.exchange_stamps,
                "ros": self.published,
            }));
        }
        print!("{}", self.report.summary());
        if let Some(methods) = self.sample_methods {
            println!("sample times: {}", super::sample_method_line(methods));
        }
        if let Some(times) = &self.host_times {
            println!("host times: {}", super::host_time_line(times));
        }
        if let Some(s) = &self.exchange_stamps {
            println!(
                "exchange send stamps: {} ({} kernel, {} user space{})",
                s.name(),
                s.kernel,
                s.user_space,
                if s.fallbacks.is_empty() {
                    String::new()
                } else {
                    format!("; fell back: {:?}", s.fallbacks)
                }
            );
        }
        if let Some(p) = &self.published {
            println!(
                "ROS 2: {} samples in {} messages on /skinbox/samples, {} on /skinbox/status, {} on /skinbox/activity",
                p.samples, p.samples_messages, p.status_messages, p.activity_messages
            );
        }
        Ok(())
    }
}

/// Runs the capture on a single-threaded tokio runtime until the duration, the count or
/// Ctrl-C; prints a summary line every second on stderr and the report at the end.
pub fn run(args: CaptureArgs, json: bool) -> anyhow::Result<()> {
    super::check_sample_rate(args.sample_rate_hz)?;
    anyhow::ensure!(
        args.duration_ms.is_none_or(|ms| ms > 0),
        "--duration-ms must be a positive number of milliseconds"
    );
    anyhow::ensure!(args.batch >= 1, "--batch must be at least 1");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(async move {
        let (socket, granted) = live::bind_udp(args.listen, args.recv_buffer)?;
        eprintln!(
            "listening on {} (receive buffer {} bytes)",
            socket.local_addr()?,
            live::usable_recv_buffer(granted)
        );
        let stop_read_ticks = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        // the kernel's send stamps of the read-tick commands, for the exchanges
        let send_stamps = (args.claim.is_some() && args.exchange_ms > 0 && !args.user_space_stamps)
            .then(skinbox_host::kernel_stamps::CommandSendStamps::new);
        let (socket, claimed, read_ticks) =
            claim_stream(&args, socket, &stop_read_ticks, &send_stamps)?;
        let recv_buffer_warning = live::recv_buffer_warning(args.recv_buffer, granted);
        if let Some(w) = &recv_buffer_warning {
            eprintln!("{w}");
        }
        let mut recorder = open_pcap(&args)?;
        let rate_hz = args
            .sample_rate_hz
            .unwrap_or(skinbox_host::decoder::ASSUMED_SAMPLE_RATE_HZ);
        let timing = || -> anyhow::Result<Timing> {
            let t = args.timing.timing(rate_hz)?;
            Ok(match &send_stamps {
                Some(s) => t.with_send_stamps(s.clone()),
                None => t,
            })
        };
        let mut rows = open_rows(&args, timing)?;
        let mut decoder = Decoder::new(DecoderConfig {
            sample_rate_hz: args.sample_rate_hz,
            ..DecoderConfig::default()
        });
        // stream datagrams that arrived while the claim waited for its acknowledgement
        let passed_over = claimed.as_ref().map_or(0, |e| e.passed_over.len() as u64);
        if let Some(e) = &claimed {
            for (from, payload) in &e.passed_over {
                decoder.push_datagram_from(Some(*from), payload, &mut ());
            }
        }
        let shutdown = shutdown(args.duration_ms);
        anyhow::ensure!(
            rows.is_none() || !args.ros.any(),
            "--rows and the ROS 2 outputs (--mcap, --foxglove, --ros2) are one or the other"
        );
        let mut ros = open_ros(&args, timing)?;
        let sink: &mut dyn skinbox_host::RecordSink = match (&mut rows, &mut ros) {
            (Some(w), _) => w,
            (None, Some(r)) => r,
            (None, None) => &mut (),
        };
        let stats = live::run_capture(
            &socket,
            &mut decoder,
            sink,
            recorder.as_mut(),
            CaptureLimits {
                max_datagrams: args.count,
                progress_every: Duration::from_secs(1),
                batch: args.batch,
                coalesce: Duration::from_micros(args.coalesce_us),
            },
            shutdown,
            &mut progress_line,
        )
        .await?;
        stop_read_ticks.store(true, std::sync::atomic::Ordering::Relaxed);
        let read_ticks_sent = read_ticks.map(|t| t.join().unwrap_or(0));
        if let Some(w) = recorder {
            w.finish()?.flush()?;
        }
        let (host_times, sample_methods, exchange_stamps, published, exchanges_unused) =
            finish_outputs(rows, ros, read_ticks_sent)?;
        let mut report = decoder.report();
        report.frames.frames = stats.datagrams + passed_over;
        report.frames.udp_payloads = stats.datagrams + passed_over;
        report.frames.capture_span_s = stats.wall_s;
        report.host = Some(skinbox_host::report::HostCost {
            cpu_s: stats.cpu_s,
            wall_s: stats.wall_s,
            cpu_ns_per_packet: stats.cpu_ns_per_record(),
        });
        Outcome {
            stats,
            granted,
            recv_buffer_warning,
            claimed,
            passed_over,
            report,
            host_times,
            sample_methods,
            read_ticks_sent,
            exchanges_unused,
            exchange_stamps,
            published,
        }
        .print(json)
    })
}

/// The DDS output of `--ros2`, which says on stderr what it sent when the capture ends.
struct DdsReport(skinbox_ros::dds::DdsOutput);

impl skinbox_ros::sink::Output for DdsReport {
    fn publish(
        &mut self,
        topic: skinbox_ros::sink::Topic,
        log_time_ns: u64,
        cdr: &[u8],
    ) -> std::io::Result<()> {
        self.0.publish(topic, log_time_ns, cdr)
    }

    fn max_samples_message_bytes(&self) -> Option<usize> {
        self.0.max_samples_message_bytes()
    }

    fn close(&mut self) -> std::io::Result<()> {
        let p = self.0.published();
        let us = |ns: Option<u64>| ns.map_or(f64::NAN, |n| n as f64 / 1e3);
        eprintln!(
            "ROS 2 over DDS: {} samples messages, {} status, {} activity written, {} writes failed; receive to publish p50 {:.0} us, p99 {:.0} us, max {:.0} us; write call p99 {:.0} us",
            p.messages[0],
            p.messages[1],
            p.messages[2],
            p.write_errors,
            us(p.latency_p50_ns),
            us(p.latency_p99_ns),
            us(p.latency_max_ns),
            us(p.write_p99_ns)
        );
        if let Some(e) = &p.first_write_error {
            eprintln!("ROS 2 over DDS: the first failed write: {e}");
        }
        self.0.close()
    }
}

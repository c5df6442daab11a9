//! `skinbox sim`: a scene of skin cells through the co-simulated box to a pcap, decoded by
//! the host client.

use anyhow::Context;
use serde::Serialize;
use skinbox_cells::scene::Scene;
use skinbox_cells::Mode;
use skinbox_cosim::closed_loop::{run_closed_loop, ClosedLoopRun, ClosedLoopSpec};
use skinbox_cosim::sim::{Fidelity, SimReport};
use skinbox_gateware::interface_box::BoxConfig;
use std::path::PathBuf;

/// Arguments of `skinbox sim`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene: a built-in scene's name (`moving_arm`, ... : the files of cosim/scenes) or a
    /// scene file (TOML); the default is stroking_upper_arm.
    scene: Option<String>,
    /// Scene time at which the box starts to listen, ms: the default skips the scenes'
    /// one-second warm-up, where every cell's first sample sends all nine channels.
    #[arg(long, default_value_t = 1000.0)]
    from_ms: f64,
    /// Simulated time of the scene, ms (then one status period and 2 ms to flush); at most
    /// 10,000 through the RTL, 3,600,000 through the reference model.
    #[arg(long, default_value_t = 100.0)]
    duration_ms: f64,
    /// Number of cells (overrides the scene).
    #[arg(long)]
    cells: Option<usize>,
    /// The cells' sample rate, Hz (overrides the scene).
    #[arg(long)]
    sample_rate_hz: Option<f64>,
    /// Number of buses, one box port each (overrides the scene).
    #[arg(long)]
    buses: Option<usize>,
    /// What the cells send: every sample, or send-on-delta events (overrides the scene).
    #[arg(long, value_enum)]
    mode: Option<ModeArg>,
    /// Flush timeout of the box, us.
    #[arg(long, default_value_t = 100.0)]
    flush_timeout_us: f64,
    /// Status period of the box, ms (the run ends after a report that counts every packet).
    #[arg(long, default_value_t = 5.0)]
    status_period_ms: f64,
    /// The box's own time-sync period, ms (0: its sync generator off; else at least 1; the
    /// default keeps the cells in time, docs/time.md).
    #[arg(long, default_value_t = 100.0)]
    sync_period_ms: f64,
    /// Write the frames to this pcap (default: SCENE.pcap in the current directory).
    #[arg(long)]
    pcap: Option<PathBuf>,
    /// Write a VCD trace of the box (slow; builds a traced model).
    #[arg(long)]
    vcd: Option<PathBuf>,
    /// Random edge jitter of every UART line, peak ns (uniform, seeded by the scene seed).
    #[arg(long, default_value_t = 0.0)]
    jitter_ns: f64,
    /// Which model of the box: the verilated RTL, or the packet-level reference model
    /// (same frames, orders of magnitude faster).
    #[arg(long, value_enum, default_value_t = FidelityArg::Rtl)]
    fidelity: FidelityArg,
    /// Ethernet frames of a pcap or pcapng for the box's GMII receive (ARP, pings,
    /// commands, anything), at their timestamps relative to the first one from the window's
    /// start; padded to 60 bytes and given their FCS as a MAC sends them. The box's replies
    /// go into the output pcap beside its datagrams and the report decodes them.
    #[arg(long)]
    host_frames: Option<PathBuf>,
    /// Send the --host-frames back to back, this many us from the end of one to the start
    /// of the next (from the window's start), instead of at their timestamps.
    #[arg(long, requires = "host_frames")]
    host_frames_gap_us: Option<f64>,
    /// Check the box's transmit pins against the plan of the scene's commands (the control
    /// model's downlink, predicted before the run); the cells hear the pins either way.
    #[arg(long, conflicts_with = "host_frames")]
    check_plan: bool,
    /// How the cells obey the scene's time syncs (overrides `[time_sync] rate`): set the
    /// phase only, or the phase and the rate (docs/time.md, the rate servo).
    #[arg(long, value_enum)]
    sync_servo: Option<ServoArg>,
    /// The cells' oscillators wander as real ones do (`[oscillator]` at its defaults, unless
    /// the scene has one): a random walk and temperature steps.
    #[arg(long)]
    oscillator_wander: bool,
}

/// `--sync-servo` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ServoArg {
    /// Each sync sets the cell's phase.
    Phase,
    /// Each sync sets the phase; successive ones the rate.
    Rate,
}

/// `--mode` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ModeArg {
    /// One data packet per sample.
    Data,
    /// Send-on-delta event packets.
    Event,
}

/// The scene `name_or_path`: a file, or a built-in scene's name.
pub(crate) fn load_scene(name_or_path: Option<&str>) -> anyhow::Result<Scene> {
    Ok(Scene::find(name_or_path)?)
}

/// `--fidelity` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum FidelityArg {
    /// Verilator, every clock.
    Rtl,
    /// Packet-level reference model.
    Reference,
}

impl From<FidelityArg> for Fidelity {
    fn from(f: FidelityArg) -> Self {
        match f {
            FidelityArg::Rtl => Fidelity::Rtl,
            FidelityArg::Reference => Fidelity::Reference,
        }
    }
}

#[derive(Serialize)]
struct Output {
    scene: String,
    cells: usize,
    buses: usize,
    from_ms: f64,
    fidelity: Fidelity,
    mode: String,
    sample_rate_hz: f64,
    packets_offered_by_cells: u64,
    /// Every drop at the bus roots since the scene start.
    packets_dropped_at_bus_roots: u64,
    /// Of them, packets sampled before the box listens (the warm-up).
    packets_dropped_at_bus_roots_warmup: u64,
    /// Of them, packets sampled in the window the box listens to.
    packets_dropped_at_bus_roots_window: u64,
    /// Set when the window lost packets at the bus roots: the buses are overloaded.
    bus_root_loss_warning: Option<String>,
    /// Set when packets began on the pins before the box's ports left reset at the window
    #[serde(flatten)]
    sim: SimReport,
    pcap: PathBuf,
    host: skinbox_host::Report,
    /// The host's sample time (its default method, the estimate from the stamps) minus
    /// the cell models' true sample time, over the delivered packets (docs/time.md).
    sample_time_error_us: SampleTimeError,
    /// The same for the arrival stamp as the sample time.
    arrival_stamp_error_us: SampleTimeError,
    /// The same for (c), the grid point of the box's time the cells sample on, when the
    /// scene's cells are time-synced through the box (`[time_sync]` or sync commands).
    synced_sample_time_error_us: Option<SampleTimeError>,
    /// The scene's cell commands through the box and what the cells heard of the
    /// downlink (with --host-frames, of what the host's own frames sent down).
    downlink: DownlinkOutput,
    /// The frames of --host-frames and what the box answered.
    host_frames: Option<HostFramesOutput>,
}

/// What came of the frames of `--host-frames`.
#[derive(Serialize)]
struct HostFramesOutput {
    /// The file.
    file: PathBuf,
    /// Frames put on the box's GMII receive.
    frames_sent: usize,
    /// Box tick of the first frame's last byte and of the last frame's.
    first_tick: u64,
    /// See `first_tick`.
    last_tick: u64,
    /// The box's answers: every one, and by kind (etherparse's reading).
    replies: u64,
    /// ARP replies.
    arp_replies: u64,
    /// ICMP echo replies.
    echo_replies: u64,
    /// Acknowledgements, by result.
    acknowledgements: std::collections::BTreeMap<&'static str, u64>,
    /// Answers of none of these kinds (must be 0).
    other_replies: u64,
    /// The fate of every received frame, from the box counter block of the last status
    /// report (`frames_received` and one fate each).
    box_counters: std::collections::BTreeMap<&'static str, u32>,
    /// Received frames the box counted in no fate (must be 0).
    unaccounted_frames: u32,
    /// Changes of the box's UART transmit pins (cell commands the frames sent down).
    uart_tx_pin_changes: usize,
}

/// The scene's `[[commands]]` in the window, sent by the host to the box, what the box
/// sent down its UART pins and what the cells heard there.
#[derive(Serialize)]
struct DownlinkOutput {
    /// Command frames the host sent.
    commands_sent: usize,
    /// Queued by the box (ack `ok`).
    commands_accepted: usize,
    /// Refused by the box (ack `downlink_full`).
    commands_refused: usize,
    /// Cell command packets the cells' UART receivers took from the box's pins.
    packets_on_pins: usize,
    /// What the cells' receivers took and rejected.
    cells_received: skinbox_model::cell_uart::ReceiverCounts,
    /// Times the cells were generated (once ahead, then once for every step in which they
    /// received a command).
    cell_generations: usize,
    /// Transmit pin changes in the window.
    pin_changes: usize,
}

/// Sample time error figures, us (absolute).
#[derive(Serialize)]
struct SampleTimeError {
    method: &'static str,
    packets: u64,
    p50: f64,
    p99: f64,
    max: f64,
    worst_cell_p99: f64,
}

impl SampleTimeError {
    fn of(method: &'static str, e: &skinbox::studies::sample_time::Errors) -> Self {
        SampleTimeError {
            method,
            packets: e.packets,
            p50: e.p50_us,
            p99: e.p99_us,
            max: e.max_us,
            worst_cell_p99: e.worst_cell_p99_us,
        }
    }
}

/// The scene of `args` with its overrides, the fidelity and the box (one port per bus).
fn scene_and_box(args: &Args) -> anyhow::Result<(Scene, Fidelity, BoxConfig)> {
    let mut scene = load_scene(args.scene.as_deref())?;
    if let Some(cells) = args.cells {
        scene.config.scene.cells = cells;
    }
    if let Some(rate) = args.sample_rate_hz {
        scene.config.scene.sample_rate_hz = rate;
    }
    if let Some(buses) = args.buses {
        scene.config.scene.buses = buses;
    }
    if let Some(mode) = args.mode {
        scene.config.scene.mode = match mode {
            ModeArg::Data => Mode::Data,
            ModeArg::Event => Mode::Event,
        };
    }
    if let Some(servo) = args.sync_servo {
        let sync = scene.config.time_sync.as_mut().ok_or_else(|| {
            anyhow::anyhow!("--sync-servo needs a scene with a [time_sync] table")
        })?;
        sync.rate = servo == ServoArg::Rate;
    }
    if args.oscillator_wander && scene.config.oscillator.is_none() {
        scene.config.oscillator = Some(Default::default());
    }
    scene.check()?;
    let fidelity = Fidelity::from(args.fidelity);
    let max_ms = match fidelity {
        Fidelity::Rtl => 10_000.0,
        Fidelity::Reference => 3_600_000.0,
    };
    anyhow::ensure!(
        args.duration_ms > 0.0 && args.duration_ms <= max_ms,
        "--duration-ms {} must be above 0 and at most {max_ms} with --fidelity {} (the RTL runs about 2 M cycles/s)",
        args.duration_ms,
        match fidelity {
            Fidelity::Rtl => "rtl",
            Fidelity::Reference => "reference",
        }
    );
    anyhow::ensure!(
        args.from_ms >= 0.0,
        "--from-ms {} must not be negative",
        args.from_ms
    );
    let buses = scene.config.scene.buses;
    anyhow::ensure!(
        (1..=64).contains(&buses),
        "the scene has {buses} buses; the box has 1 to 64 ports, one per bus"
    );
    anyhow::ensure!(
        args.sync_period_ms == 0.0 || (1.0..=34_359.0).contains(&args.sync_period_ms),
        "--sync-period-ms {} must be 0 (off) or 1 to 34359 (32 bits of 8 ns ticks)",
        args.sync_period_ms
    );
    let config = BoxConfig {
        ports: buses,
        flush_timeout_ticks: (args.flush_timeout_us * 125.0).round() as u64,
        status_period_ticks: (args.status_period_ms * 125_000.0).round() as u64,
        sync_period_ticks: (args.sync_period_ms * 125_000.0).round() as u64,
        ..BoxConfig::default()
    };
    Ok((scene, fidelity, config))
}

/// Runs the scene.
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    let (scene, fidelity, config) = scene_and_box(args)?;
    let buses = config.ports;
    // the scene's cell commands go from the host through the box's downlink to the cells,
    // which hear its transmit pins
    let window_ns = ((args.from_ms * 1e6) as u64, (args.duration_ms * 1e6) as u64);
    let pcap = args
        .pcap
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.pcap", scene.name())));
    let mut closed = ClosedLoopSpec::new(&scene, config, window_ns.0, window_ns.1);
    let scene_commands = closed.sim.host_frames.len();
    closed.sim.pcap = Some(pcap.clone());
    closed.sim.vcd = args.vcd.clone();
    if let Some(file) = &args.host_frames {
        anyhow::ensure!(
            scene_commands == 0,
            "--host-frames: the scene sends {scene_commands} cell commands of its own in the window ([[commands]]); use a scene without"
        );
        closed.sim.host_frames = host_frames(file, args.host_frames_gap_us, window_ns.1)?;
    }
    anyhow::ensure!(
        (0.0..=50.0).contains(&args.jitter_ns),
        "--jitter-ns {} must be 0 to 50 (a fifth of a bit)",
        args.jitter_ns
    );
    closed.sim.jitter = skinbox_cosim::line::Jitter {
        peak_ns: args.jitter_ns,
        seed: scene.config.scene.seed,
    };
    anyhow::ensure!(
        fidelity == Fidelity::Rtl || args.vcd.is_none(),
        "--vcd traces the RTL; it needs --fidelity rtl"
    );
    let bar = progress_bar(closed.sim.duration_ns / 8);
    let done = run_closed_loop(&closed, fidelity, &mut |done, _| {
        bar.set_message("simulating");
        bar.set_position(done);
    })?;
    bar.finish_and_clear();
    let (run, spec, generated) = (&done.run, &done.spec, &done.generated);
    let downlink = downlink_output(&done, scene_commands)?;
    if args.check_plan {
        check_plan(
            &skinbox_cosim::scene::plan_downlink(&scene, &spec.config, window_ns.0, window_ns.1),
            &run.uart_tx,
            spec,
        )?;
    }
    let host_frames_output = args
        .host_frames
        .as_ref()
        .map(|file| host_frames_output(file, spec, run));
    let report = run.report.clone();

    // the host told the scene's true sample rate and cell count, so its "% of data mode"
    // and per-cell rates are over the whole skin
    let options = skinbox_host::pcap::PcapOptions {
        decoder: skinbox_host::DecoderConfig {
            sample_rate_hz: Some(scene.config.scene.sample_rate_hz),
            cells: Some(scene.config.scene.cells as u64),
            ..Default::default()
        },
        ..Default::default()
    };
    let decoded = skinbox_host::decode_pcap_file(&pcap, &options)
        .with_context(|| format!("decoding {}", pcap.display()))?;
    let host = decoded.report;
    let from_ns = (args.from_ms * 1e6) as u64;
    let (arrival_stamp_error_us, sample_time_error_us) = sample_time_errors(
        generated,
        &decoded.records,
        &scene,
        from_ns,
        args.duration_ms,
    );
    let synced_sample_time_error_us = done.received.iter().any(|p| is_sync(&p.bytes)).then(|| {
        synced_sample_time_error(
            generated,
            &decoded.records,
            &scene,
            (from_ns, args.duration_ms),
            &done.received,
        )
    });
    let (dropped, dropped_window, bus_root_loss_warning) =
        bus_root_losses(generated, from_ns, report.packets_sent, &scene);
    let out = Output {
        scene: scene.name().to_string(),
        cells: scene.config.scene.cells,
        buses,
        from_ms: args.from_ms,
        fidelity,
        mode: format!("{:?}", scene.config.scene.mode).to_lowercase(),
        sample_rate_hz: scene.config.scene.sample_rate_hz,
        packets_offered_by_cells: generated.buses.iter().map(|b| b.stats.offered).sum(),
        packets_dropped_at_bus_roots: dropped,
        packets_dropped_at_bus_roots_warmup: dropped - dropped_window,
        packets_dropped_at_bus_roots_window: dropped_window,
        bus_root_loss_warning,
        sim: report,
        pcap,
        host,
        sample_time_error_us,
        arrival_stamp_error_us,
        synced_sample_time_error_us,
        downlink,
        host_frames: host_frames_output,
    };
    if json {
        return super::print_json(&out);
    }
    print_summary(&out);
    Ok(())
}

/// Packets dropped at the bus roots since the scene start and in the window from `from_ns`
/// (against `sent` on the pins there), and a warning when the window lost any.
fn bus_root_losses(
    generated: &skinbox_cells::Generated,
    from_ns: u64,
    sent: u64,
    scene: &Scene,
) -> (u64, u64, Option<String>) {
    let dropped: u64 = generated.buses.iter().map(|b| b.stats.dropped).sum();
    let dropped_window: u64 = generated
        .buses
        .iter()
        .map(|b| b.dropped_from(from_ns))
        .sum();
    let warning = (dropped_window > 0).then(|| {
        let offered = sent + dropped_window;
        format!(
            "{dropped_window} packets sampled in the window were dropped at the bus roots (FIFO full), against {sent} that reached the box pins ({:.1} % lost): the buses are overloaded at {} cells on {} buses, {} Hz; use more buses or a lower sample rate",
            100.0 * dropped_window as f64 / offered.max(1) as f64,
            scene.config.scene.cells,
            scene.config.scene.buses,
            scene.config.scene.sample_rate_hz
        )
    });
    (dropped, dropped_window, warning)
}

/// The frames of `file` on the box's GMII receive from the window's start (the edge the
/// ports start to listen at): at their timestamps relative to the first, or `gap_us` apart;
/// never closer than the 12-byte inter-frame gap. They must have left by the window's end
/// (`window_ns` after its start), so the last status report counts them.
fn host_frames(
    file: &std::path::Path,
    gap_us: Option<f64>,
    window_ns: u64,
) -> anyhow::Result<Vec<skinbox_cosim::run::HostFrame>> {
    use skinbox_cosim::run::{HostFrame, PORTS_READY_CYCLE};
    use skinbox_protocol::TICK_NS;
    const INTER_FRAME_GAP: u64 = 12;
    let bytes = skinbox_host::pcap::read_file(file)?;
    let frames = skinbox_host::pcap::ethernet_frames(&bytes)
        .with_context(|| format!("--host-frames {}", file.display()))?;
    if let Some(gap) = gap_us {
        anyhow::ensure!(
            gap.is_finite() && gap >= 0.0,
            "--host-frames-gap-us {gap} must be 0 or more"
        );
    }
    let gap_cycles = gap_us.map(|g| (g * 1e3 / TICK_NS as f64).round() as u64);
    let first_ts = frames.first().map(|f| f.0).unwrap_or_default();
    let mut free = PORTS_READY_CYCLE;
    let mut out = Vec::with_capacity(frames.len());
    for (ts, ethernet) in &frames {
        anyhow::ensure!(
            ethernet.len() >= 14,
            "--host-frames: a frame of {} bytes has no Ethernet header",
            ethernet.len()
        );
        let wanted = match gap_cycles {
            Some(gap) => free + gap.saturating_sub(INTER_FRAME_GAP),
            None => {
                PORTS_READY_CYCLE
                    + (ts.saturating_sub(first_ts).as_nanos() / u128::from(TICK_NS)) as u64
            }
        };
        let f = HostFrame::from_ethernet(wanted.max(free), ethernet);
        free = f.last_edge() + 1 + INTER_FRAME_GAP;
        out.push(f);
    }
    let end = PORTS_READY_CYCLE + window_ns / TICK_NS;
    if let Some(last) = out.last() {
        anyhow::ensure!(
            last.last_edge() < end,
            "--host-frames: the last of {} frames ends {:.1} us after the window's start, after its end; give a longer --duration-ms or a --host-frames-gap-us",
            out.len(),
            ((last.last_edge() - PORTS_READY_CYCLE) * TICK_NS) as f64 / 1e3
        );
    }
    Ok(out)
}

/// The box's answers to the host's frames, read with etherparse, and the fates its last
/// status report counted.
fn host_frames_output(
    file: &std::path::Path,
    spec: &skinbox_cosim::run::SimSpec,
    run: &skinbox_cosim::run::SimRun,
) -> HostFramesOutput {
    use etherparse::{NetSlice, SlicedPacket, TransportSlice};
    use skinbox_cosim::run::TICK_ZERO_CYCLE;
    use skinbox_model::timing::RECEIVE_TICK_LAG;
    use skinbox_protocol::command::AckRepr;
    let tick = |f: &skinbox_cosim::run::HostFrame| {
        (f.last_edge() + RECEIVE_TICK_LAG).saturating_sub(TICK_ZERO_CYCLE)
    };
    let mut out = HostFramesOutput {
        file: file.to_path_buf(),
        frames_sent: spec.host_frames.len(),
        first_tick: spec.host_frames.first().map_or(0, tick),
        last_tick: spec.host_frames.last().map_or(0, tick),
        replies: run.replies.len() as u64,
        arp_replies: 0,
        echo_replies: 0,
        acknowledgements: Default::default(),
        other_replies: 0,
        box_counters: Default::default(),
        unaccounted_frames: 0,
        uart_tx_pin_changes: run.uart_tx.len(),
    };
    for reply in &run.replies {
        // preamble and SFD before, the FCS after
        let ethernet = &reply.bytes[8..reply.bytes.len().saturating_sub(4)];
        let kind =
            SlicedPacket::from_ethernet(ethernet)
                .ok()
                .and_then(|p| match (&p.net, &p.transport) {
                    (Some(NetSlice::Arp(a)), _)
                        if a.operation() == etherparse::ArpOperation::REPLY =>
                    {
                        Some("arp")
                    }
                    (_, Some(TransportSlice::Icmpv4(i)))
                        if matches!(i.icmp_type(), etherparse::Icmpv4Type::EchoReply(_)) =>
                    {
                        Some("echo")
                    }
                    (_, Some(TransportSlice::Udp(u))) => {
                        AckRepr::parse(u.payload()).ok().map(|a| a.result.name())
                    }
                    _ => None,
                });
        match kind {
            Some("arp") => out.arp_replies += 1,
            Some("echo") => out.echo_replies += 1,
            Some(result) => *out.acknowledgements.entry(result).or_insert(0) += 1,
            None => out.other_replies += 1,
        }
    }
    // the box counter block of the last status datagram that carried one
    let last_block = run.frames.iter().rev().find_map(|f| {
        let ethernet = f.bytes.get(8..f.bytes.len().saturating_sub(4))?;
        let udp = skinbox_host::frame::udp_payload(
            ethernet,
            skinbox_host::frame::LinkType::Ethernet,
            None,
        )
        .ok()?;
        skinbox_protocol::DatagramRepr::parse_box_counters(udp.payload)
            .ok()?
            .1
    });
    if let Some(c) = last_block {
        out.box_counters = skinbox_protocol::box_counters::BoxCounter::ALL
            .iter()
            .map(|k| (k.name(), c.get(*k)))
            .collect();
        out.unaccounted_frames = c.unaccounted_frames();
    }
    out
}

/// Method (c) over the delivered records: the grid point of box time the stamp minus the
/// cell's half round trip falls on (the host's `SampleTimer::on_box_grid`, in box time),
/// taken to scene time.
/// Counted from when the box's first sync on the port has reached the bus's last cell and
/// a sample period has passed: the simulated box starts its time base at the window, so
/// cells sample on the scene's time until then.
fn synced_sample_time_error(
    generated: &skinbox_cells::Generated,
    records: &[skinbox_host::DecodedRecord],
    scene: &Scene,
    (from_ns, duration_ms): (u64, f64),
    received: &[skinbox_model::cell_uart::ReceivedPacket],
) -> SampleTimeError {
    use skinbox::studies::sample_time::{errors, matched, Method};
    use skinbox_protocol::TICK_NS;
    let window = from_ns..from_ns + (duration_ms * 1e6) as u64;
    let offset_ns = skinbox_cosim::scene::scene_ns_of_tick(0, from_ns) as f64;
    let buses = matched(generated, records, window, |tick| tick * TICK_NS);
    let b = &scene.config.bus;
    let cells_per_bus = scene.config.scene.cells.div_ceil(buses.len().max(1)) as u64;
    let settled_ns = |port: usize| {
        received
            .iter()
            .find(|s| s.port == port && is_sync(&s.bytes))
            .map_or(u64::MAX, |s| {
                s.tick * TICK_NS
                    + b.processing_ns
                    + cells_per_bus * b.hop_latency_ns
                    + (1e9 / scene.config.scene.sample_rate_hz) as u64
            })
    };
    let settled: Vec<Vec<_>> = buses
        .iter()
        .enumerate()
        .map(|(port, bus)| {
            let from = settled_ns(port);
            bus.iter().copied().filter(|p| p.stamp_ns >= from).collect()
        })
        .collect();
    let (packets, assigned): (Vec<_>, Vec<_>) = settled
        .iter()
        .flat_map(|bus| {
            // the host's own timer on the box's grid (what `decode --synced` uses)
            use skinbox_host::sample_clock::{PathModel, Positions, SampleTimer};
            let hops = bus.iter().map(|p| (p.cell_id, p.hops)).collect();
            let mut timer = SampleTimer::new(
                scene.config.scene.sample_rate_hz,
                PathModel {
                    processing_ns: b.processing_ns,
                    hop_latency_ns: b.hop_latency_ns,
                    hops: Positions::Listed(hops),
                },
            )
            .on_box_grid();
            let box_grid: Vec<f64> = bus
                .iter()
                .map(|p| timer.push(0, 0, p.cell_id, p.stamp_ns).sample_time_ns)
                .collect();
            bus.iter()
                .copied()
                .zip(box_grid.into_iter().map(move |g| g + offset_ns))
        })
        .unzip();
    SampleTimeError::of(Method::Synced.name(), &errors(&packets, &assigned, 0))
}

/// A time-sync cell command packet.
fn is_sync(bytes: &[u8; skinbox_protocol::cell::PACKET_LEN]) -> bool {
    matches!(
        skinbox_protocol::cell_command::CellCommandRepr::parse(bytes).map(|r| r.command),
        Ok(skinbox_protocol::cell_command::CellCommand::TimeSync { .. })
    )
}

/// What the scene's commands did on the way down: the acknowledgements of the `commands`
/// command frames the host sent, and what the cells' receivers heard.
fn downlink_output(done: &ClosedLoopRun, commands: usize) -> anyhow::Result<DownlinkOutput> {
    use skinbox_protocol::command::{AckRepr, AckResult};
    let acks: Vec<AckResult> = done
        .run
        .replies
        .iter()
        .filter_map(|f| AckRepr::parse(f.bytes.get(8 + 42..f.bytes.len().checked_sub(4)?)?).ok())
        .map(|a| a.result)
        .collect();
    Ok(DownlinkOutput {
        commands_sent: commands,
        commands_accepted: acks.iter().filter(|r| **r == AckResult::Ok).count(),
        commands_refused: acks
            .iter()
            .filter(|r| **r == AckResult::DownlinkFull)
            .count(),
        packets_on_pins: done.received.len(),
        cells_received: done.receiver,
        cell_generations: done.generations,
        pin_changes: done.run.uart_tx.len(),
    })
}

/// `--check-plan`: the box's transmit pins must be as the plan of the scene's commands
/// predicted them.
fn check_plan(
    plan: &skinbox_cosim::scene::DownlinkPlan,
    pins: &[skinbox_model::downlink::PinChange],
    spec: &skinbox_cosim::run::SimSpec,
) -> anyhow::Result<()> {
    let last_tick = skinbox_cosim::run::cycles(spec) - skinbox_cosim::run::TICK_ZERO_CYCLE;
    let planned: Vec<_> = plan
        .pin_changes
        .iter()
        .filter(|c| c.tick <= last_tick)
        .copied()
        .collect();
    if let Some(i) = (0..planned.len().max(pins.len())).find(|&i| planned.get(i) != pins.get(i)) {
        anyhow::bail!(
            "the box's downlink differs from the plan at pin change {i}: box {:?}, plan {:?}",
            pins.get(i),
            planned.get(i)
        );
    }
    Ok(())
}

/// The progress bar of a run of `len` cycles.
fn progress_bar(len: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{msg} [{bar:40}] {percent}% {elapsed} (ETA {eta})",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar.set_message("building the model");
    bar
}

/// The sample time errors of the arrival stamp and of the host's estimate over the
/// delivered records, against the cell models' truth. A stamp of tick `t` is the edge of
/// simulation cycle `t + TICK_ZERO_CYCLE`; the simulation starts `PORTS_READY_NS` before
/// scene time `from_ns`.
fn sample_time_errors(
    generated: &skinbox_cells::Generated,
    records: &[skinbox_host::DecodedRecord],
    scene: &Scene,
    from_ns: u64,
    duration_ms: f64,
) -> (SampleTimeError, SampleTimeError) {
    use skinbox::studies::sample_time::{
        assign_arrival, assign_estimated, errors, matched, Errors, Method,
    };
    use skinbox_protocol::TICK_NS;
    let zero_ns = skinbox_cosim::run::TICK_ZERO_CYCLE * TICK_NS;
    let lead_ns = skinbox_cosim::scene::PORTS_READY_NS;
    let window = from_ns..from_ns + (duration_ms * 1e6) as u64;
    let buses = matched(generated, records, window, |tick| {
        (tick * TICK_NS + zero_ns + from_ns).saturating_sub(lead_ns)
    });
    let rate = scene.config.scene.sample_rate_hz;
    let hop = scene.config.bus.hop_latency_ns;
    let all = |assign: &dyn Fn(&[skinbox::studies::sample_time::Stamped]) -> Vec<f64>| {
        let (packets, assigned): (Vec<_>, Vec<_>) = buses
            .iter()
            .flat_map(|bus| bus.iter().copied().zip(assign(bus)))
            .unzip();
        errors(&packets, &assigned, 0)
    };
    let a: Errors = all(&|bus| assign_arrival(bus));
    let b: Errors = all(&|bus| assign_estimated(bus, rate, hop));
    (
        SampleTimeError::of(Method::Arrival.name(), &a),
        SampleTimeError::of(Method::Estimated.name(), &b),
    )
}

fn print_summary(o: &Output) {
    let s = &o.sim;
    println!(
        "scene {}: {} cells on {} buses, {} mode, {} Hz, {:.1} ms simulated from {:.0} ms on ({} model)",
        o.scene,
        o.cells,
        o.buses,
        o.mode,
        o.sample_rate_hz,
        s.sim_seconds * 1e3,
        o.from_ms,
        match o.fidelity {
            Fidelity::Rtl => "RTL",
            Fidelity::Reference => "reference",
        }
    );
    println!(
        "cells:  {} packets offered since the scene start, {} dropped at the bus roots (FIFO full: {} in the warm-up, {} in the window); {} on the box pins in the window",
        o.packets_offered_by_cells,
        o.packets_dropped_at_bus_roots,
        o.packets_dropped_at_bus_roots_warmup,
        o.packets_dropped_at_bus_roots_window,
        s.packets_sent
    );
    if let Some(w) = &o.bus_root_loss_warning {
        println!("warning: {w}");
    }
    println!(
        "box:    {} frames ({} records, {} status), {} records; {} of {} packets delivered, {} corrupted, {} mistimed",
        s.frames, s.record_datagrams, s.status_datagrams, s.records, s.packets_delivered, s.packets_sent, s.records_corrupted, s.records_mistimed
    );
    let losses: Vec<String> = s
        .losses_by_cause
        .iter()
        .map(|(c, n)| format!("{c} {n}"))
        .collect();
    println!(
        "        box counters: {} good, {}",
        s.box_packets_good,
        losses.join(", ")
    );
    println!(
        "        timestamps: stamp - true start edge {:.3} ticks max, {:.3} mean (8 ns ticks)",
        s.ts_error_max_ticks, s.ts_error_mean_ticks
    );
    if let Some(d) = Some(&o.downlink).filter(|d| d.commands_sent > 0) {
        println!(
            "        downlink: {} cell commands from the host, {} queued, {} refused (downlink_full); {} packets heard by the cells on the UART transmit pins ({} rejected), the cells generated {} times",
            d.commands_sent, d.commands_accepted, d.commands_refused, d.packets_on_pins, d.cells_received.packets_discarded, d.cell_generations
        );
    }
    if let Some(f) = &o.host_frames {
        let acks: Vec<String> = f
            .acknowledgements
            .iter()
            .map(|(r, n)| format!("{r} {n}"))
            .collect();
        let fates: Vec<String> = f
            .box_counters
            .iter()
            .filter(|(_, v)| **v != 0)
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        println!(
            "        host frames: {} from {} (ticks {} to {}); {} replies: {} ARP, {} echo, acknowledgements {}{}",
            f.frames_sent,
            f.file.display(),
            f.first_tick,
            f.last_tick,
            f.replies,
            f.arp_replies,
            f.echo_replies,
            if acks.is_empty() { "none".to_string() } else { acks.join(", ") },
            if f.other_replies > 0 { format!(", {} other", f.other_replies) } else { String::new() }
        );
        println!(
            "        fates: {}{}",
            fates.join(", "),
            if f.unaccounted_frames > 0 {
                format!("; {} frames unaccounted", f.unaccounted_frames)
            } else {
                String::new()
            }
        );
    }
    let h = &o.host;
    println!(
        "host:   {} records ({} data, {} event), {} cells active, {:.1} % of data mode over {} cells ({})",
        h.records,
        h.data_packets,
        h.event_packets,
        h.cells_active,
        h.packet_rate_percent_of_data_mode,
        h.cells_denominator.cells,
        h.cells_denominator.source
    );
    println!(
        "        losses seen: {} datagrams missing, {} event sequence gaps ({} event packets missing), {} box packets lost",
        h.losses.datagrams_missing, h.losses.event_sequence_gaps, h.losses.event_packets_missing, h.losses.box_packets_lost
    );
    let (a, b) = (&o.arrival_stamp_error_us, &o.sample_time_error_us);
    match &o.synced_sample_time_error_us {
        // the box sent time syncs: the cells sample on its grid, and the host times them so
        Some(c) => {
            println!(
                "        sample time - true sample time: {} (the box's syncs) p50 {:.3} us, p99 {:.3} us, max {:.3} us, worst cell p99 {:.3} us",
                c.method, c.p50, c.p99, c.max, c.worst_cell_p99
            );
            println!(
                "        the same records by {}: p50 {:.1} us, p99 {:.1} us, max {:.1} us ({} p50 {:.0} us, p99 {:.0} us)",
                b.method, b.p50, b.p99, b.max, a.method, a.p50, a.p99
            );
        }
        None => println!(
            "        sample time - true sample time: {} p50 {:.1} us, p99 {:.1} us, max {:.1} us ({} p50 {:.0} us, p99 {:.0} us); the box sent no time syncs",
            b.method, b.p50, b.p99, b.max, a.method, a.p50, a.p99
        ),
    }
    println!(
        "speed:  {:.2} M cycles/s, {:.2} s wall for {:.1} ms simulated",
        s.cycles_per_second / 1e6,
        s.wall_seconds,
        s.sim_seconds * 1e3
    );
    println!("pcap:   {}", o.pcap.display());
}

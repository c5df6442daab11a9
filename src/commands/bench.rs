//! `skinbox bench <what>`: benchmarks, each printing its figures (JSON with --json).
//! Add a variant to [`BenchCommand`] for another benchmark.

use clap::{Args, Subcommand};

/// The benchmarks.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Decode an in-memory capture (data and event mode mixed); prints packets_per_second.
    Decode(DecodeBenchArgs),
    /// Replay on loopback at rising rates; prints max_lossless_records_per_second.
    Live(LiveBenchArgs),
    /// Decode an in-memory capture into an MCAP recording of the ROS 2 topics, pipelined (as
    /// decode --mcap) and on one thread; prints samples per second of wall and of CPU time.
    Mcap(McapBenchArgs),
    /// Verilator co-simulation: the harness against the bare model loop and the reference
    /// model.
    Sim(SimBenchArgs),
    /// Box time to host time on loopback: the same responder twice, the exchanges stamped
    /// in user space and by the kernel (SO_TIMESTAMPING); prints each one's mapping error
    /// p50/p99/max side by side.
    ClockMap(ClockMapBenchArgs),
}

/// Arguments of `skinbox bench clock-map`.
#[derive(Debug, Args)]
pub struct ClockMapBenchArgs {
    /// Exchanges of each method (after a warm-up of at least 10).
    #[arg(long, default_value_t = 1000)]
    pub exchanges: usize,
    /// Wait between exchanges, ms.
    #[arg(long, default_value_t = 2)]
    pub interval_ms: u64,
    /// How much faster the responder's box clock runs, ppm.
    #[arg(long, default_value_t = 80.0)]
    pub drift_ppm: f64,
    /// Most random delay the responder adds before it stamps a request, us (a path
    /// asymmetry the host cannot see; 0: none).
    #[arg(long, default_value_t = 60)]
    pub delay_in_us: u64,
    /// Most random delay it adds after it stamps its answer, us.
    #[arg(long, default_value_t = 20)]
    pub delay_out_us: u64,
}

/// Arguments of `skinbox bench sim`.
#[derive(Debug, Args)]
pub struct SimBenchArgs {
    /// Ports of the box.
    #[arg(long, default_value_t = 8)]
    pub ports: usize,
    /// Clock cycles per measurement.
    #[arg(long, default_value_t = 5_000_000)]
    pub cycles: u64,
    /// Rounds; the fastest counts.
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
}

/// Arguments of `skinbox bench decode`.
#[derive(Debug, Args)]
pub struct DecodeBenchArgs {
    /// At least this many cell packets.
    #[arg(long, default_value_t = 1_000_000)]
    pub packets: usize,
    /// Rounds; the fastest counts.
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
}

/// Arguments of `skinbox bench mcap`.
#[derive(Debug, Args)]
pub struct McapBenchArgs {
    /// At least this many cell packets.
    #[arg(long, default_value_t = 1_000_000)]
    pub packets: usize,
    /// Rounds of each way; the fastest and the slowest are printed.
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
    /// Chunk sizes of the recording to compare, KiB (taking turns within each round).
    #[arg(long, value_delimiter = ',', default_values_t = [skinbox_ros::mcap_out::DEFAULT_CHUNK_BYTES / 1024])]
    pub chunk_kib: Vec<u64>,
}

/// Arguments of `skinbox bench live`.
#[derive(Debug, Args)]
pub struct LiveBenchArgs {
    /// Record rates to try, in records per second, rising.
    #[arg(long, value_delimiter = ',', default_values_t = [500e3, 1e6, 2e6, 3e6, 4.5e6, 6e6, 7e6, 8e6])]
    pub rates: Vec<f64>,
    /// Seconds per rate step.
    #[arg(long, default_value_t = 1.0)]
    pub step_s: f64,
    /// Receivers to compare side by side: datagrams per receive call of each (1: one call
    /// per datagram, as a plain recv loop).
    #[arg(long, value_delimiter = ',', default_values_t = [1, skinbox_host::live::DEFAULT_BATCH])]
    pub batches: Vec<usize>,
    /// Each receiver's wait after draining the socket, in microseconds (0: wake for every
    /// datagram); as many as --batches.
    #[arg(long, value_delimiter = ',', default_values_t = [0, 0])]
    pub coalesce_us: Vec<u64>,
    /// Receive buffer to ask for in the rate steps, in bytes.
    #[arg(long, default_value_t = skinbox_host::live::DEFAULT_RECV_BUFFER_BYTES)]
    pub recv_buffer: usize,
    /// Receive buffers to try at --buffer-rate, rising, in bytes (e.g.
    /// 1048576,2097152,4194304): reports the smallest lossless one. Asking for more than
    /// net.core.rmem_max needs root (SO_RCVBUFFORCE).
    #[arg(long, value_delimiter = ',')]
    pub recv_buffers: Vec<usize>,
    /// Record rate of the receive buffer sweep.
    #[arg(long, default_value_t = 4.5e6)]
    pub buffer_rate: f64,
}

/// The host benchmarks' capture of at least `min_packets` cell packets
/// ([`skinbox_cosim::synthetic::bench_capture`]) as their payloads.
fn bench_payloads(
    min_packets: usize,
    seed: u64,
) -> anyhow::Result<skinbox_host::bench::BenchPayloads> {
    let capture = skinbox_cosim::synthetic::bench_capture(min_packets, seed)?;
    Ok(skinbox_host::bench::BenchPayloads {
        payloads: capture.payloads(),
        data_packets: capture.data_packets,
        event_packets: capture.event_packets,
    })
}

/// Runs one benchmark.
pub fn run(what: BenchCommand, json: bool) -> anyhow::Result<()> {
    match what {
        BenchCommand::Sim(a) => sim(a, json),
        BenchCommand::Mcap(a) => mcap(a, json),
        BenchCommand::ClockMap(a) => clock_map(a, json),
        BenchCommand::Decode(a) => decode(a, json),
        BenchCommand::Live(a) => live(a, json),
    }
}

/// The Verilator co-simulation benchmark: the harness, the bare loop and the reference model.
fn sim(a: SimBenchArgs, json: bool) -> anyhow::Result<()> {
    let r = skinbox_cosim::bench::bench_sim(a.ports, a.cycles, a.rounds)?;
    if json {
        return super::print_json(&r);
    }
    println!(
        "{}-port box, {} cycles: harness {:.2} M cycles/s, bare loop {:.2} M cycles/s ({:.0} % of bare; goals 5 M and 75 %)",
        r.ports,
        r.cycles,
        r.rtl_cycles_per_second / 1e6,
        r.bare_cycles_per_second / 1e6,
        100.0 * r.harness_fraction_of_bare
    );
    println!(
        "line rate: every port's UART busy (clock errors -1 .. +1 %): {} packets sent, {} delivered in the run",
        r.packets_sent, r.packets_delivered
    );
    println!(
        "reference model on the same line-rate traffic: {:.0} M cycles/s, {:.0} x the harness",
        r.line_rate_reference_cycles_per_second / 1e6,
        r.line_rate_reference_speedup,
    );
    println!(
        "scene {} ({} ports, {} cycles): RTL {:.2} M cycles/s, reference {:.0} M cycles/s: {:.0} x (goal 1,000 x); frames {}",
        r.scene,
        r.scene_ports,
        r.scene_cycles,
        r.scene_rtl_cycles_per_second / 1e6,
        r.scene_reference_cycles_per_second / 1e6,
        r.reference_speedup,
        if r.reference_agrees {
            "identical to the RTL's"
        } else {
            "DIFFER from the RTL's"
        }
    );
    anyhow::ensure!(
        r.reference_agrees,
        "the reference model's frames differ from the RTL's"
    );
    Ok(())
}

/// The MCAP recording benchmark: pipelined against one thread, for each chunk size.
fn mcap(a: McapBenchArgs, json: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        !a.chunk_kib.is_empty() && a.chunk_kib.iter().all(|k| *k > 0),
        "--chunk-kib: one or more sizes, each at least 1"
    );
    let capture = bench_payloads(a.packets, 7)?;
    let path = std::env::temp_dir().join(format!("skinbox-bench-{}.mcap", std::process::id()));
    let chunks: Vec<u64> = a.chunk_kib.iter().map(|k| k * 1024).collect();
    let r = skinbox_ros::bench::bench_mcap(&capture.payloads, &path, a.rounds, &chunks);
    let _ = std::fs::remove_file(&path);
    let r = r?;
    if json {
        return super::print_json(&r);
    }
    for r in &r {
        println!(
            "MCAP, chunks of {} KiB: {} samples in {} messages ({:.1} MB) decoded, timed and written, {} rounds of each way (fastest-slowest):",
            r.chunk_bytes / 1024,
            r.samples,
            r.messages,
            r.file_bytes as f64 / 1e6,
            r.rounds
        );
        println!(
            "  pipelined (as decode --mcap): {:.3}-{:.3} s wall, {:.3}-{:.3} s CPU of both threads ({:.3}-{:.3} s the decoding thread's): {:.2} M samples/s of wall time (goal {:.0} M)",
            r.pipelined_wall_s.min,
            r.pipelined_wall_s.max,
            r.pipelined_cpu_s.min,
            r.pipelined_cpu_s.max,
            r.pipelined_decoding_thread_cpu_s.min,
            r.pipelined_decoding_thread_cpu_s.max,
            r.pipelined_samples_per_second / 1e6,
            r.goal_samples_per_second / 1e6
        );
        println!(
            "  one thread: {:.3}-{:.3} s CPU ({:.3}-{:.3} s wall): {:.2} M samples/s of CPU time",
            r.one_thread_cpu_s.min,
            r.one_thread_cpu_s.max,
            r.one_thread_wall_s.min,
            r.one_thread_wall_s.max,
            r.one_thread_samples_per_second / 1e6
        );
        println!(
            "  decoding and timing alone {:.3}-{:.3} s CPU; the messages and the file the rest: {:.2} M samples/s of CPU time; the two recordings {}",
            r.decode_and_timing_cpu_s.min,
            r.decode_and_timing_cpu_s.max,
            r.ros_samples_per_second / 1e6,
            if r.files_identical {
                "byte for byte the same"
            } else {
                "DIFFER"
            }
        );
        anyhow::ensure!(
            r.files_identical,
            "the pipelined recording differs from the one-thread recording"
        );
    }
    Ok(())
}

/// The box-to-host time mapping on loopback, user-space against kernel stamps.
fn clock_map(a: ClockMapBenchArgs, json: bool) -> anyhow::Result<()> {
    use skinbox_host::clock_bench::{clock_map_loopback, ClockMapBenchConfig, ExchangeStamping};
    anyhow::ensure!(a.exchanges >= 1, "--exchanges must be at least 1");
    let config = ClockMapBenchConfig {
        exchanges: a.exchanges,
        interval: std::time::Duration::from_millis(a.interval_ms),
        drift_ppm: a.drift_ppm,
        max_delay_in_ns: a.delay_in_us * 1_000,
        max_delay_out_ns: a.delay_out_us * 1_000,
    };
    let runs = [ExchangeStamping::UserSpace, ExchangeStamping::Kernel]
        .into_iter()
        .map(|stamping| clock_map_loopback(stamping, &config))
        .collect::<Result<Vec<_>, _>>()?;
    let beyond_bound = |r: &skinbox_host::clock_bench::ClockMapRun| {
        r.samples
            .iter()
            .filter(|s| s.error_ns > s.bound_ns + 8.0)
            .count()
    };
    if json {
        let methods: Vec<_> = runs
            .iter()
            .map(|r| {
                serde_json::json!({
                    "stamping": r.stamping,
                    "error_us": r.error_us(),
                    "stamps": r.sources(),
                    "fallbacks": r.fallbacks,
                    "not_enabled": r.not_enabled,
                    "warm_up_exchanges": r.warm_up_exchanges,
                    "beyond_bound": beyond_bound(r),
                    "drift_ppm": r.drift_ppm,
                    "drift_bound_ppm": r.drift_bound_ppm,
                })
            })
            .collect();
        return super::print_json(&serde_json::json!({
            "config": config,
            "methods": methods,
            "goal_p99_us": 5.0,
        }));
    }
    println!(
        "box time to host time on loopback: {} exchanges {} ms apart, box {} ppm fast, 0-{} us delay in, 0-{} us out",
        a.exchanges, a.interval_ms, a.drift_ppm, a.delay_in_us, a.delay_out_us
    );
    println!(
        "{:<12} {:>9} {:>9} {:>9}  stamps, fallbacks, beyond bound",
        "method", "p50 us", "p99 us", "max us"
    );
    for r in &runs {
        let e = r.error_us();
        let name = match r.stamping {
            ExchangeStamping::UserSpace => "user space",
            ExchangeStamping::Kernel => "kernel",
        };
        println!(
            "{name:<12} {:>9.2} {:>9.2} {:>9.2}  {:?}, {:?}, {}",
            e.p50,
            e.p99,
            e.max,
            r.sources(),
            r.fallbacks,
            beyond_bound(r)
        );
        if let Some(why) = &r.not_enabled {
            println!("  no kernel stamps: {why}");
        }
    }
    Ok(())
}

/// The decoding benchmark on one core.
fn decode(a: DecodeBenchArgs, json: bool) -> anyhow::Result<()> {
    let capture = bench_payloads(a.packets, 7)?;
    let r = skinbox_host::bench::bench_decode(&capture, a.rounds);
    if json {
        return super::print_json(&r);
    }
    println!(
        "decoded {} cell packets ({} data, {} event) in {} datagrams: {:.2} M packets/s on one core, {:.1} ns per packet (goal 10 M/s)",
        r.cell_packets,
        r.data_packets,
        r.event_packets,
        r.datagrams,
        r.packets_per_second / 1e6,
        r.ns_per_packet
    );
    Ok(())
}

/// The loopback replay at rising rates, and the receive buffer sweep.
fn live(a: LiveBenchArgs, json: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.batches.iter().all(|b| *b >= 1),
        "--batches: each receiver takes at least 1 datagram per call"
    );
    anyhow::ensure!(
        a.batches.len() == a.coalesce_us.len(),
        "--coalesce-us needs one value per --batches value ({} and {})",
        a.coalesce_us.len(),
        a.batches.len()
    );
    let receivers = a
        .batches
        .iter()
        .zip(&a.coalesce_us)
        .map(|(b, us)| (*b, std::time::Duration::from_micros(*us)))
        .collect();
    let config = skinbox_host::bench::LiveBenchConfig {
        rates: a.rates,
        step_s: a.step_s,
        receivers,
        recv_buffer_bytes: a.recv_buffer,
        recv_buffers: a.recv_buffers,
        buffer_rate: a.buffer_rate,
    };
    let capture = bench_payloads(config.packets_needed(), 11)?;
    let r = skinbox_host::bench::bench_live(&config, &capture)?;
    if json {
        return super::print_json(&r);
    }
    let line = |s: &skinbox_host::bench::LiveStep| {
        println!(
            "batch {:3}, coalesce {:4} us, buffer {:9}: {:9.0} records/s asked, {:9.0} sent: {} of {} datagrams received in {} calls, {} missing; receiver CPU {:.0} ns per datagram, {:.1} ns per record{}",
            s.batch,
            s.coalesce_us,
            skinbox_host::live::usable_recv_buffer(s.recv_buffer_bytes),
            s.target_records_per_second,
            s.sent_records_per_second,
            s.datagrams_received,
            s.datagrams_sent,
            s.receive_calls,
            s.datagrams_missing,
            s.receiver_cpu_ns_per_datagram,
            s.receiver_cpu_ns_per_record,
            if s.lossless { "" } else { "  LOSS" }
        )
    };
    r.steps.iter().for_each(line);
    for (receiver, best) in &r.max_lossless_records_per_second {
        println!(
            "receiver {receiver} (batch/coalesce us): max lossless {:.2} M records/s (goal 4.5 M, at most {} ns CPU per record)",
            best / 1e6,
            r.goal_cpu_ns_per_record
        );
    }
    if !r.buffer_steps.is_empty() {
        r.buffer_steps.iter().for_each(line);
        match r.smallest_lossless_recv_buffer_bytes {
            Some(b) => println!("smallest lossless receive buffer: {b} bytes"),
            None => println!("no receive buffer tried was lossless"),
        }
    }
    Ok(())
}

//! The host side of skinbox: receives the interface box's UDP datagrams live or from pcap
//! files, decodes them down to cell data and event packets, rebuilds full cell samples from
//! events, detects every loss and reports what the papers report.
//!
//! The core is I/O-free: [`frame`] takes a captured frame to its UDP payload, [`Decoder`]
//! takes box datagrams to [`DecodedRecord`]s (detecting datagram sequence gaps, duplicates,
//! reordering, per-cell event sequence gaps, box counter deltas and box resets), and
//! [`EventToData`] turns records into full nine-channel [`Sample`]s. The shells around it
//! read and write pcap files ([`pcap`]), receive live on a tokio UDP socket ([`live`]) and
//! replay a pcap to a socket ([`replay`]).
//!
//! Follow one cell packet in reading order: [`frame::udp_payload`] finds the box datagram in
//! an Ethernet frame; [`Decoder::push_datagram`] checks it with the format crate
//! (`skinbox_protocol::datagram::Datagram::new_checked`), walks its records and parses each
//! cell packet; [`RecordSink::record`] hands the record on; [`Decoder::report`] sums it up.
//!
//! For a co-simulation that wrote a pcap: [`decode_pcap_file`] (or [`decode_pcap_bytes`])
//! returns the [`Report`] and every decoded record in one call.
//!
//! Bad input (truncated or garbled frames and datagrams, wrong magic or version, unknown
//! kinds, non-UDP frames, truncated pcap files) is counted by reason in
//! [`BadInput`], never a panic.

#![warn(missing_docs)]

pub mod bad_input;
pub mod bench;
mod box_map;
pub mod clock_bench;
pub mod clock_map;
pub mod control;
pub mod convert;
pub mod decoder;
pub mod frame;
pub mod kernel_stamps;
pub mod live;
pub mod other_traffic;
pub mod output;
pub mod pcap;
pub mod rate;
pub mod replay;
pub mod report;
pub mod rows;
pub mod sample_clock;
pub mod sequence;
#[cfg(target_os = "linux")]
mod sockaddr;
pub mod timing;
pub mod wireshark;

pub use bad_input::BadInput;
pub use convert::{EventToData, Sample};
pub use decoder::{DecodedRecord, Decoder, DecoderConfig, RecordSink};
pub use pcap::{decode_pcap_bytes, decode_pcap_file, PcapDecode};
pub use report::Report;

/// Box ticks (8 ns) to seconds of box time.
pub fn ticks_to_seconds(tick: u64) -> f64 {
    tick as f64 / skinbox_protocol::TICKS_PER_SECOND as f64
}

/// CPU time this thread has used so far, in nanoseconds (0 where the clock is missing).
pub fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// CPU time this process has used so far, in nanoseconds (0 where the clock is missing).
pub fn process_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec through a valid pointer.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

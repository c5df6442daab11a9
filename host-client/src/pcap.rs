//! Reading pcap and pcapng files and writing pcap files (pcap-file's parsers and writer,
//! etherparse's slicer and builder), and decoding a capture into a [`Report`] in one call.
//!
//! A capture is read whole into memory and parsed with `pcap_file::pcap::PcapParser` or
//! `pcap_file::pcapng::PcapNgParser` (told apart by the first four bytes), so a truncated
//! last packet is told apart from a corrupt record and counted, not fatal. A pcapng may hold
//! several sections and interfaces, each with its own link type and timestamp resolution
//! (`if_tsresol`, `if_tsoffset`), as Wireshark and dumpcap write them.

use crate::bad_input::{BadInput, Reason};
use crate::decoder::{DecodedRecord, Decoder, DecoderConfig, RecordSink};
use crate::frame::{self, LinkType, UdpDatagram};
use crate::other_traffic::OtherTraffic;
use crate::report::{FrameCounts, HostCost, Report};
use pcap_file::pcap::PcapParseError;
use pcap_file::pcap::PcapParser;
use pcap_file::pcapng::{Block, PcapNgParseError, PcapNgParser};
use pcap_file::DataLink;
use std::io::Write;
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

/// Why a pcap cannot be read at all.
#[derive(Debug, thiserror::Error)]
pub enum PcapError {
    /// The file could not be read or written. (The I/O error is part of the message, not a
    /// separate cause, so a printed chain says it once.)
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// What failed.
        error: std::io::Error,
    },
    /// The file starts with neither a pcap header nor a pcapng section header.
    #[error("not a pcap or pcapng file: {0}")]
    NotPcap(String),
    /// A link type this decoder does not read.
    #[error("unsupported pcap link type {0:?} (Ethernet, raw IPv4/IPv6 are read)")]
    LinkType(DataLink),
    /// Writing a packet failed.
    #[error("writing pcap: {0}")]
    Write(String),
}

/// What to decode from a pcap.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PcapOptions {
    /// Decoder settings.
    pub decoder: DecoderConfig,
    /// Only UDP datagrams with this source or destination port (default: any port).
    pub udp_port: Option<u16>,
}

/// Frames, bad input and other traffic of one pass over a pcap.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PcapScan {
    /// Frame counts.
    pub frames: FrameCounts,
    /// Frames and pcap records rejected.
    pub bad: BadInput,
    /// Frames that are not the box's, by kind.
    pub other: OtherTraffic,
}

/// Block type of a pcapng section header, as the file's first four bytes.
const PCAPNG_MAGIC: [u8; 4] = [0x0A, 0x0D, 0x0D, 0x0A];

/// The frame format of a capture link type, or `None` when the decoder does not read it.
fn link_type(datalink: DataLink) -> Option<LinkType> {
    match datalink {
        DataLink::ETHERNET => Some(LinkType::Ethernet),
        DataLink::RAW | DataLink::IPV4 | DataLink::IPV6 => Some(LinkType::RawIp),
        DataLink::LINUX_SLL => Some(LinkType::LinuxSll),
        _ => None,
    }
}

/// Takes one captured frame: counts it, finds its UDP datagram or counts why not. A frame
/// without a timestamp (`None`: a pcapng simple packet block) is passed on with a zero
/// timestamp and leaves the capture span alone.
fn take_frame(
    scan: &mut PcapScan,
    ts: Option<Duration>,
    data: &[u8],
    link: LinkType,
    udp_port: Option<u16>,
    f: &mut impl FnMut(Duration, UdpDatagram<'_>),
) {
    match frame::udp_payload(data, link, udp_port) {
        Ok(udp) => {
            scan.frames.udp_payloads += 1;
            f(ts.unwrap_or_default(), udp);
        }
        Err(reject) => reject.count_in(&mut scan.bad, &mut scan.other),
    }
}

/// Calls `f` with the timestamp and UDP datagram of every frame of a pcap or pcapng that
/// carries a skinbox datagram; counts every other frame as other traffic by kind, or as
/// bad input by reason. Frames of pcapng simple packet blocks
/// have no timestamp: `f` gets a zero one, and they do not enter the capture span.
pub fn for_each_udp_payload(
    bytes: &[u8],
    udp_port: Option<u16>,
    mut f: impl FnMut(Duration, UdpDatagram<'_>),
) -> Result<PcapScan, PcapError> {
    for_each_frame(bytes, &mut |scan, ts, data, link| {
        take_frame(scan, ts, data, link, udp_port, &mut f)
    })
}

/// A frame of a capture file: the scan so far, its timestamp (`None`: a pcapng simple
/// packet block), its bytes and its link type.
type FrameFn<'a> = dyn FnMut(&mut PcapScan, Option<Duration>, &[u8], LinkType) + 'a;

/// Calls `f` with every frame of a pcap or pcapng whose link type is read; counts the
/// frames, the capture span and what cannot be read.
fn for_each_frame(bytes: &[u8], f: &mut FrameFn<'_>) -> Result<PcapScan, PcapError> {
    let mut span = (None, Duration::ZERO);
    let mut g = |scan: &mut PcapScan, ts: Option<Duration>, data: &[u8], link: LinkType| {
        scan.frames.frames += 1;
        if let Some(ts) = ts {
            span.0.get_or_insert(ts);
            span.1 = span.1.max(ts);
        }
        f(scan, ts, data, link);
    };
    let mut scan = if bytes.starts_with(&PCAPNG_MAGIC) {
        for_each_pcapng(bytes, &mut g)?
    } else {
        for_each_pcap(bytes, &mut g)?
    };
    if let Some(first) = span.0 {
        scan.frames.capture_span_s = span.1.saturating_sub(first).as_secs_f64();
    }
    Ok(scan)
}

/// Every Ethernet frame of a pcap or pcapng with its timestamp (zero for a pcapng simple
/// packet block), in file order: frames to send somewhere, not to decode. A frame of
/// another link type, or a file that ends inside a record, is an error that says which.
pub fn ethernet_frames(bytes: &[u8]) -> Result<Vec<(Duration, Vec<u8>)>, PcapError> {
    let mut frames = Vec::new();
    let mut other_link = None;
    let scan = for_each_frame(bytes, &mut |_, ts, data, link| {
        if link == LinkType::Ethernet {
            frames.push((ts.unwrap_or_default(), data.to_vec()));
        } else {
            other_link.get_or_insert(link);
        }
    })?;
    if let Some(link) = other_link {
        return Err(PcapError::NotPcap(format!(
            "a frame of link type {link:?}: only Ethernet frames can be sent"
        )));
    }
    if scan.bad.total > 0 {
        return Err(PcapError::NotPcap(format!(
            "unreadable records: {}",
            scan.bad
        )));
    }
    Ok(frames)
}

fn for_each_pcapng(bytes: &[u8], f: &mut FrameFn<'_>) -> Result<PcapScan, PcapError> {
    let (mut rest, mut parser) = PcapNgParser::new(bytes)
        .map_err(|e| PcapError::NotPcap(format!("pcapng section header: {e}")))?;
    let mut scan = PcapScan::default();
    while !rest.is_empty() {
        let (next, block) = match parser.next_block(rest) {
            Ok(x) => x,
            Err(PcapNgParseError::IncompleteBuffer(needed, have)) => {
                scan.bad.count(Reason::PcapTruncated, || {
                    format!("pcapng: truncated at end of file: the last block needs {needed} bytes, {have} remain")
                });
                break;
            }
            Err(e) => {
                let left = rest.len();
                scan.bad.count(Reason::PcapCorrupt, || {
                    format!("pcapng: corrupt block, {left} bytes left unread: {e}")
                });
                break;
            }
        };
        rest = next;
        // Timestamps come decoded with the interface's if_tsresol and if_tsoffset.
        let (interface, ts, data) = match block {
            Block::EnhancedPacket(p) => (p.interface_id, Some(p.timestamp), p.data),
            Block::Packet(p) => (u32::from(p.interface_id), Some(p.timestamp), p.data),
            // A simple packet block has no timestamp.
            Block::SimplePacket(p) => (0, None, p.data),
            _ => continue,
        };
        let datalink = parser
            .interfaces()
            .get(interface as usize)
            .map(|i| i.linktype);
        let Some(link) = datalink.and_then(link_type) else {
            scan.frames.frames += 1;
            scan.bad.count(Reason::PcapLinkType, || {
                format!("pcapng: interface {interface} has link type {datalink:?}, not read (Ethernet, raw IPv4/IPv6, Linux cooked v1 are)")
            });
            continue;
        };
        // The parser borrows packet data from `bytes`; owned data is read all the same.
        f(&mut scan, ts, &data, link);
    }
    Ok(scan)
}

fn for_each_pcap(bytes: &[u8], f: &mut FrameFn<'_>) -> Result<PcapScan, PcapError> {
    let (mut rest, parser) =
        PcapParser::new(bytes).map_err(|e| PcapError::NotPcap(e.to_string()))?;
    let link =
        link_type(parser.header().datalink).ok_or(PcapError::LinkType(parser.header().datalink))?;
    let mut scan = PcapScan::default();
    while !rest.is_empty() {
        match parser.next_packet(rest) {
            Ok((next, packet)) => {
                rest = next;
                let ts = packet.timestamp();
                // `next_packet` borrows from `bytes`; owned data is read all the same.
                let data = packet.into_data();
                f(&mut scan, Some(ts), &data, link);
            }
            Err(PcapParseError::IncompleteBuffer(needed, have)) => {
                scan.bad.count(Reason::PcapTruncated, || {
                    format!("pcap: truncated at end of file: the last record needs {needed} bytes, {have} remain")
                });
                break;
            }
            Err(e) => {
                let left = rest.len();
                scan.bad.count(Reason::PcapCorrupt, || {
                    format!("pcap: corrupt packet record, {left} bytes left unread: {e}")
                });
                break;
            }
        }
    }
    Ok(scan)
}

/// Decodes a pcap held in memory: every box datagram into `sink`, and the report. The
/// report's `host` holds this thread's CPU time per cell packet.
pub fn decode_pcap_with<S: RecordSink + ?Sized>(
    bytes: &[u8],
    options: &PcapOptions,
    sink: &mut S,
) -> Result<Report, PcapError> {
    let wall = std::time::Instant::now();
    let cpu = crate::thread_cpu_ns();
    let mut decoder = Decoder::new(options.decoder);
    let scan = for_each_udp_payload(bytes, options.udp_port, |timestamp, udp| {
        // A frame without a timestamp comes with zero.
        sink.datagram_received(
            (!timestamp.is_zero()).then_some(timestamp),
            Some(udp.source),
            udp.payload,
        );
        decoder.push_datagram_from(Some(udp.source), udp.payload, sink);
    })?;
    let cpu_ns = crate::thread_cpu_ns().saturating_sub(cpu);
    decoder.bad_input_mut().merge(&scan.bad);
    decoder.other_traffic_mut().merge(&scan.other);
    let mut report = decoder.report();
    report.frames = scan.frames;
    report.host = Some(HostCost {
        cpu_s: cpu_ns as f64 * 1e-9,
        wall_s: wall.elapsed().as_secs_f64(),
        cpu_ns_per_packet: if report.records > 0 {
            cpu_ns as f64 / report.records as f64
        } else {
            0.0
        },
    });
    Ok(report)
}

/// A decoded pcap: the report and every record.
#[derive(Debug, Clone)]
pub struct PcapDecode {
    /// The report.
    pub report: Report,
    /// Every decoded record, in capture order.
    pub records: Vec<DecodedRecord>,
}

/// Decodes a pcap held in memory, keeping every record.
pub fn decode_pcap_bytes(bytes: &[u8], options: &PcapOptions) -> Result<PcapDecode, PcapError> {
    let mut records = Vec::new();
    let report = decode_pcap_with(bytes, options, &mut records)?;
    Ok(PcapDecode { report, records })
}

/// Decodes a pcap file, keeping every record: the call for a co-simulation that wrote one.
pub fn decode_pcap_file(
    path: impl AsRef<Path>,
    options: &PcapOptions,
) -> Result<PcapDecode, PcapError> {
    let bytes = read_file(path.as_ref())?;
    decode_pcap_bytes(&bytes, options)
}

/// Reads a whole file, with its name in the error.
pub fn read_file(path: &Path) -> Result<Vec<u8>, PcapError> {
    std::fs::read(path).map_err(|error| PcapError::Io {
        path: path.display().to_string(),
        error,
    })
}

/// One UDP payload of a pcap with its capture time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TimedPayload {
    /// Capture time (since the epoch, as pcap stores it).
    pub timestamp: Duration,
    /// The UDP payload.
    pub payload: Vec<u8>,
}

/// The skinbox datagrams of a pcap (UDP payloads with the magic "SK", on `udp_port` if
/// given), with the scan's counts.
pub fn udp_payloads(
    bytes: &[u8],
    udp_port: Option<u16>,
) -> Result<(Vec<TimedPayload>, PcapScan), PcapError> {
    let mut out = Vec::new();
    let scan = for_each_udp_payload(bytes, udp_port, |timestamp, udp| {
        out.push(TimedPayload {
            timestamp,
            payload: udp.payload.to_vec(),
        })
    })?;
    Ok((out, scan))
}

/// Writes Ethernet II frames to a pcap (nanosecond timestamps): the protocol crate's writer
/// ([`skinbox_protocol::pcap::PcapFrameWriter`]), which also takes UDP payloads.
pub struct PcapFrameWriter<W: Write> {
    writer: skinbox_protocol::pcap::PcapFrameWriter<W>,
}

impl From<skinbox_protocol::pcap::PcapWriteError> for PcapError {
    fn from(e: skinbox_protocol::pcap::PcapWriteError) -> Self {
        PcapError::Write(e.0)
    }
}

impl<W: Write> PcapFrameWriter<W> {
    /// Writes the pcap header.
    pub fn new(writer: W) -> Result<Self, PcapError> {
        Ok(PcapFrameWriter {
            writer: skinbox_protocol::pcap::PcapFrameWriter::new(writer)?,
        })
    }

    /// Writes one frame.
    pub fn write_frame(&mut self, timestamp: Duration, frame: &[u8]) -> Result<(), PcapError> {
        Ok(self.writer.write_frame(timestamp, frame)?)
    }

    /// Writes a UDP payload inside an Ethernet II / IPv4 / UDP frame.
    pub fn write_udp(
        &mut self,
        timestamp: Duration,
        source: SocketAddr,
        destination: SocketAddr,
        payload: &[u8],
    ) -> Result<(), PcapError> {
        self.write_frame(
            timestamp,
            &frame::build_udp_frame(source, destination, payload),
        )
    }

    /// Flushes and returns the writer.
    pub fn finish(self) -> Result<W, PcapError> {
        Ok(self.writer.finish()?)
    }
}

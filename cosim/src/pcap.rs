//! pcap output of co-simulated frames: Ethernet link type, nanosecond timestamps = the
//! simulated time of the frame's first byte.

use pcap_file::pcap::{PcapHeader, PcapPacket, PcapTsResolution, PcapWriter};
use pcap_file::DataLink;
use std::io::Write;
use std::time::Duration;

/// Writes Ethernet frames (without preamble and FCS, as capture tools store them).
pub struct PcapOut<W: Write> {
    writer: PcapWriter<W>,
}

impl<W: Write> PcapOut<W> {
    /// A pcap file with nanosecond timestamps on `sink`.
    pub fn new(sink: W) -> Result<Self, pcap_file::pcap::PcapWriteError> {
        let header = PcapHeader {
            datalink: DataLink::ETHERNET,
            ts_resolution: PcapTsResolution::NanoSecond,
            ..PcapHeader::default()
        };
        Ok(PcapOut {
            writer: PcapWriter::with_header(sink, header)?,
        })
    }

    /// Writes one frame seen at `time_ns` of simulated time.
    pub fn write(
        &mut self,
        time_ns: u64,
        ethernet: &[u8],
    ) -> Result<(), pcap_file::pcap::PcapWriteError> {
        let packet = PcapPacket::new(
            Duration::from_nanos(time_ns),
            ethernet.len() as u32,
            ethernet,
        )
        .map_err(pcap_file::pcap::PcapWriteError::from)?;
        self.writer.write_packet(&packet)?;
        Ok(())
    }

    /// Flushes and returns the sink.
    pub fn into_inner(mut self) -> Result<W, pcap_file::pcap::PcapWriteError> {
        self.writer.flush()?;
        Ok(self.writer.into_inner())
    }
}

//! Ethernet frames written to a pcap file (nanosecond timestamps, pcap-file's writer): the
//! capture format both sides of the link write, the co-simulation the box's frames and the
//! host client what it received.

use pcap_file::pcap::{PcapHeader, PcapPacket, PcapWriter};
use pcap_file::{DataLink, Endianness};
use std::io::Write;
use std::time::Duration;

/// Writing a pcap failed (the writer's message).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("writing pcap: {0}")]
pub struct PcapWriteError(pub String);

/// Writes Ethernet II frames to a pcap (nanosecond timestamps).
pub struct PcapFrameWriter<W: Write> {
    writer: PcapWriter<W>,
}

impl<W: Write> PcapFrameWriter<W> {
    /// Writes the pcap header.
    pub fn new(writer: W) -> Result<Self, PcapWriteError> {
        let header = PcapHeader {
            datalink: DataLink::ETHERNET,
            ts_resolution: pcap_file::pcap::PcapTsResolution::NanoSecond,
            endianness: Endianness::native(),
            ..PcapHeader::default()
        };
        let writer =
            PcapWriter::with_header(writer, header).map_err(|e| PcapWriteError(e.to_string()))?;
        Ok(PcapFrameWriter { writer })
    }

    /// Writes one frame (destination MAC to the last payload or padding byte).
    pub fn write_frame(&mut self, timestamp: Duration, frame: &[u8]) -> Result<(), PcapWriteError> {
        let packet = PcapPacket::new(timestamp, frame.len() as u32, frame)
            .map_err(|e| PcapWriteError(e.to_string()))?;
        self.writer
            .write_packet(&packet)
            .map_err(|e| PcapWriteError(e.to_string()))?;
        Ok(())
    }

    /// Flushes and returns the writer.
    pub fn finish(mut self) -> Result<W, PcapWriteError> {
        self.writer
            .flush()
            .map_err(|e| PcapWriteError(e.to_string()))?;
        Ok(self.writer.into_inner())
    }
}

//! GMII bytes to Ethernet frames, checked with independent code.

use crate::GmiiByte;
use std::fmt;

/// One frame as it left the box.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Clock cycle of the first preamble byte.
    pub first_cycle: u64,
    /// Preamble to FCS.
    pub bytes: Vec<u8>,
}

/// Splits GMII bytes into frames: a frame ends where `tx_en` fell (cycles not
/// consecutive). Also returns the shortest gap between frames, in clocks.
pub fn assemble(bytes: &[GmiiByte]) -> (Vec<Frame>, Option<u64>) {
    let mut frames: Vec<Frame> = vec![];
    let mut min_gap: Option<u64> = None;
    let mut previous: Option<u64> = None;
    for b in bytes {
        match previous {
            Some(p) if b.cycle == p + 1 => {}
            _ => {
                if let Some(p) = previous {
                    let gap = b.cycle - p - 1;
                    min_gap = Some(min_gap.map_or(gap, |g| g.min(gap)));
                }
                frames.push(Frame {
                    first_cycle: b.cycle,
                    bytes: vec![],
                });
            }
        }
        frames
            .last_mut()
            .expect("a frame was started")
            .bytes
            .push(b.data);
        previous = Some(b.cycle);
    }
    (frames, min_gap)
}

/// What is wrong with a frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FrameError(pub String);

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for FrameError {}

/// Checks a frame with code that is not the box's: preamble and SFD, FCS with the crc
/// crate, Ethernet II / IPv4 / UDP with etherparse (both checksums, lengths), zero
/// padding, minimum size. Returns the Ethernet frame without preamble and FCS, and the
/// UDP payload.
pub fn check(frame: &[u8]) -> Result<(&[u8], &[u8]), FrameError> {
    use etherparse::{NetHeaders, PacketHeaders, TransportHeader};
    let fail = |m: String| Err(FrameError(m));
    if frame.len() < 8 + 64 {
        return fail(format!(
            "{} bytes: shorter than preamble + 64-byte minimum frame",
            frame.len()
        ));
    }
    if frame[..7] != [0x55; 7] || frame[7] != 0xD5 {
        return fail(format!("preamble/SFD {:02x?}", &frame[..8]));
    }
    let (ethernet, fcs) = frame[8..].split_at(frame.len() - 12);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(ethernet);
    if fcs != crc.to_le_bytes() {
        return fail(format!(
            "FCS {fcs:02x?}, computed {:02x?}",
            crc.to_le_bytes()
        ));
    }
    let headers =
        PacketHeaders::from_ethernet_slice(ethernet).map_err(|e| FrameError(e.to_string()))?;
    let Some(NetHeaders::Ipv4(ip, _)) = &headers.net else {
        return fail("not IPv4".into());
    };
    if ip.header_checksum != ip.calc_header_checksum() {
        return fail(format!(
            "IPv4 checksum {:#06x}, computed {:#06x}",
            ip.header_checksum,
            ip.calc_header_checksum()
        ));
    }
    let Some(TransportHeader::Udp(udp)) = &headers.transport else {
        return fail("not UDP".into());
    };
    let rest = headers.payload.slice();
    let udp_len = usize::from(udp.length);
    if udp_len < 8 || udp_len - 8 > rest.len() || usize::from(ip.total_len) != 20 + udp_len {
        return fail(format!(
            "lengths: IPv4 total {}, UDP {}",
            ip.total_len, udp.length
        ));
    }
    let payload = &rest[..udp_len - 8];
    let sum = udp
        .calc_checksum_ipv4(ip, payload)
        .map_err(|e| FrameError(e.to_string()))?;
    if udp.checksum != sum {
        return fail(format!(
            "UDP checksum {:#06x}, computed {sum:#06x}",
            udp.checksum
        ));
    }
    if rest[payload.len()..].iter().any(|b| *b != 0) {
        return fail("non-zero padding".into());
    }
    Ok((ethernet, payload))
}

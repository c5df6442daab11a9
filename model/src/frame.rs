//! Frames on the box's Ethernet link as the models take and give them, with their clock
//! cycles.

/// One frame as it left the box.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Clock cycle of the first preamble byte.
    pub first_cycle: u64,
    /// Preamble to FCS.
    pub bytes: Vec<u8>,
}

/// A frame the host sends to the box, on GMII receive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HostFrame {
    /// The rising edge that samples its first preamble byte (a cycle of the run, counted
    /// from the start of its reset).
    pub edge: u64,
    /// The frame: destination MAC to FCS.
    pub frame: Vec<u8>,
}

impl HostFrame {
    /// The frame as it is on the wire: preamble, SFD, frame.
    pub fn wire(&self) -> Vec<u8> {
        let mut w = vec![0x55; 7];
        w.push(0xD5);
        w.extend(&self.frame);
        w
    }

    /// The rising edge that samples its last byte.
    pub fn last_edge(&self) -> u64 {
        self.edge + 8 + self.frame.len() as u64 - 1
    }

    /// An Ethernet frame as a capture holds it (destination MAC to payload, no FCS) as a
    /// MAC sends it: padded with zeros to 60 bytes, its FCS appended.
    pub fn from_ethernet(edge: u64, ethernet: &[u8]) -> HostFrame {
        let mut frame = ethernet.to_vec();
        frame.resize(frame.len().max(skinbox_protocol::link::MIN_FRAME_LEN), 0);
        let fcs = crate::control::crc32(&frame);
        frame.extend_from_slice(&fcs.to_le_bytes());
        HostFrame { edge, frame }
    }
}

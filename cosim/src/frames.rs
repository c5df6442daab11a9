//! GMII bytes to Ethernet frames; [`check`] checks them with independent code.

use crate::GmiiByte;

pub use skinbox_model::frame::Frame;

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

/// Shortest gap between consecutive frames, in clocks.
pub fn min_gap(frames: &[Frame]) -> Option<u64> {
    frames
        .windows(2)
        .map(|w| w[1].first_cycle - (w[0].first_cycle + w[0].bytes.len() as u64))
        .min()
}

pub use skinbox_frame_check::{check, FrameError};

/// Whether a frame the box sent (preamble to FCS) is an answer to the host rather than
/// one of its datagrams: an ARP frame, an ICMP message, or a UDP payload of the
/// acknowledgement kind. Looks at the type fields only; the frame is not checked.
pub fn is_reply(frame: &[u8]) -> bool {
    use skinbox_protocol::command::{peek_kind, KIND_ACK};
    use skinbox_protocol::link::{
        ETHERTYPE_ARP, ETHERTYPE_IPV4, IPV4_HEADER_LEN, IP_PROTOCOL_ICMP, IP_PROTOCOL_UDP,
        PREAMBLE_LEN, UDP_HEADER_LEN,
    };
    use skinbox_protocol::wire::ethernet::EthernetFrame;
    use skinbox_protocol::wire::ipv4::Ipv4Packet;
    let Some(Ok(ethernet)) = frame.get(PREAMBLE_LEN..).map(EthernetFrame::new_checked) else {
        return false;
    };
    match ethernet.ethertype() {
        ETHERTYPE_ARP => true,
        ETHERTYPE_IPV4 => match Ipv4Packet::new_checked(ethernet.payload()).map(|ip| ip.protocol())
        {
            Ok(IP_PROTOCOL_ICMP) => true,
            Ok(IP_PROTOCOL_UDP) => ethernet
                .payload()
                .get(IPV4_HEADER_LEN + UDP_HEADER_LEN..)
                .and_then(peek_kind)
                .is_some_and(|k| k == KIND_ACK),
            _ => false,
        },
        _ => false,
    }
}

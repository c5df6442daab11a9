//! ArpReceiver: the receive half of the ARP layer (docs/control.md, step 4): is the frame's
//! ARP packet a request for the box's IPv4 address?
//!
//! It listens to the frame parser's beats and compares, as they pass, the packet's fixed
//! header (hardware Ethernet, protocol IPv4, lengths 6 and 4, operation request) and its
//! target IPv4 address with the box's, with a [`FieldMatch`] each (positions from
//! `protocol::wire::arp` after the Ethernet header); it captures nothing. Every clock it
//! registers `request_for_box`, the two matches together. The reply takes the sender's
//! addresses from the request in the frame buffer, so the layer does not keep them.

use crate::field_match::FieldMatch;
use crate::hdl::*;
use crate::stream::FrameBeats;
use skinbox_protocol::link::{ARP_AT, ARP_REQUEST_HEADER};
use skinbox_protocol::wire::arp;
use skinbox_protocol::Field;

/// The frame bytes of the ARP packet's field `f`.
const fn in_frame(f: Field) -> Field {
    ARP_AT + f.start..ARP_AT + f.end
}

/// The receive half of the ARP layer; see the module documentation.
#[derive(LogicBlock)]
pub struct ArpReceiver {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The frame's bytes are an ARP request for the box's IPv4 address (if its EtherType
    /// is ARP).
    pub request_for_box: Signal<Out, Bit>,
    header: FieldMatch,
    target: FieldMatch,
    for_box: DFF<Bit>,
}

impl ArpReceiver {
    /// The layer of a box at IPv4 address `box_ip`.
    pub fn new(box_ip: [u8; 4]) -> Self {
        Self {
            clock: Default::default(),
            beats: Default::default(),
            request_for_box: Default::default(),
            header: FieldMatch::of(
                in_frame(arp::field::HARDWARE_TYPE.start..arp::field::OPERATION.end),
                &ARP_REQUEST_HEADER,
            ),
            target: FieldMatch::of(in_frame(arp::field::TARGET_IP), &box_ip),
            for_box: Default::default(),
        }
    }
}

impl Logic for ArpReceiver {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, for_box);
        self.header.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.header.beats);
        self.target.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.target.beats);
        self.for_box.d.next = self.header.equals.val() & self.target.equals.val();
        self.request_for_box.next = self.for_box.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{send_frame_beats, Bench, TestRng};
    use skinbox_protocol::link::LinkConfig;
    use skinbox_protocol::wire::arp::{ArpOperation, ArpRepr};

    /// Random ARP packets (requests and replies, for the box's address and others, a
    /// header byte changed) behind an Ethernet header: `request_for_box` is the wire
    /// layer's parse of the packet saying "a request for the box's address".
    #[test]
    fn requests_for_the_box_are_the_wire_layers() {
        let box_ip = LinkConfig::DEFAULT.box_ip;
        let mut rng = TestRng::new(41);
        let mut bench = Bench::new(ArpReceiver::new(box_ip), |a| &mut a.clock);
        let (mut yes, mut no) = (0, 0);
        for case in 0..300 {
            let mut target_ip = box_ip;
            if rng.chance(0.3) {
                target_ip[rng.next_u64() as usize % 4] ^= 1 << (rng.next_u64() % 8);
            }
            let repr = ArpRepr {
                operation: if rng.chance(0.8) {
                    ArpOperation::Request
                } else {
                    ArpOperation::Reply
                },
                sender_mac: [2, 0, 0, 0, 0, rng.next_u64() as u8],
                sender_ip: [192, 0, 2, rng.next_u64() as u8],
                target_mac: [0; 6],
                target_ip,
            };
            let mut frame = [0u8; ARP_AT + arp::PACKET_LEN + 22];
            repr.emit(&mut frame[ARP_AT..]);
            if rng.chance(0.2) {
                frame[ARP_AT + rng.next_u64() as usize % 8] ^= 1 << (rng.next_u64() % 8);
            }
            send_frame_beats(
                &mut bench,
                &mut rng,
                &frame,
                0.2,
                |u| &mut u.beats,
                |_, _| {},
            );
            let parsed = ArpRepr::parse(&frame[ARP_AT..]);
            let expected = matches!(parsed, Ok(r) if r.operation == ArpOperation::Request && r.target_ip == box_ip);
            assert_eq!(
                bench.uut.request_for_box.val(),
                expected,
                "case {case}: {parsed:?}"
            );
            if expected {
                yes += 1;
            } else {
                no += 1;
            }
        }
        assert!(
            yes > 80 && no > 80,
            "{yes} requests for the box, {no} other packets"
        );
    }
}

//! EthernetDemux: the Ethernet II layer of the receive path: whom a frame is for and what
//! it carries (docs/control.md, steps 3 to 5).
//!
//! It listens to the frame parser's beats and compares the destination MAC with the box's
//! and with broadcast, and the EtherType with ARP's and IPv4's, as they pass
//! ([`FieldMatch`], no capture; positions from `protocol::wire::ethernet`). At the first
//! byte after
//! the EtherType it registers `is_arp` (the ARP layer's fields follow; cleared at a frame's
//! first beat). Every clock it registers its checks: the destination is the box's MAC
//! (`to_box`) or broadcast (`broadcast`), the EtherType is IPv4 (`ipv4`); they stand from the second clock after the EtherType's last byte was
//! registered until the next frame reaches the field.

use crate::field_match::FieldMatch;
use crate::hdl::*;
use crate::stream::FrameBeats;
use skinbox_protocol::wire::ethernet::{self, ETHERTYPE_ARP, ETHERTYPE_IPV4};

/// The Ethernet layer of the receive path; see the module documentation.
#[derive(LogicBlock)]
pub struct EthernetDemux {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The registered beat is a frame's first.
    pub beat_first: Signal<In, Bit>,
    /// The EtherType is ARP (from the byte after it on).
    pub is_arp: Signal<Out, Bit>,
    /// The destination MAC is the box's.
    pub to_box: Signal<Out, Bit>,
    /// The destination MAC is broadcast.
    pub broadcast: Signal<Out, Bit>,
    /// The EtherType is IPv4.
    pub ipv4: Signal<Out, Bit>,
    // the destination MAC is the box's, is broadcast
    destination_is_box: FieldMatch,
    destination_is_broadcast: FieldMatch,
    // the EtherType is ARP's, is IPv4's
    ethertype_is_arp: FieldMatch,
    ethertype_is_ipv4: FieldMatch,
    payload_at: Constant<Bits<11>>,
    at_payload: DFF<Bit>,
    arp: DFF<Bit>,
    to_box_check: DFF<Bit>,
    broadcast_check: DFF<Bit>,
    ipv4_check: DFF<Bit>,
}

impl EthernetDemux {
    /// The layer of a box at MAC address `box_mac`.
    pub fn new(box_mac: [u8; 6]) -> Self {
        Self {
            clock: Default::default(),
            beats: Default::default(),
            beat_first: Default::default(),
            is_arp: Default::default(),
            to_box: Default::default(),
            broadcast: Default::default(),
            ipv4: Default::default(),
            destination_is_box: FieldMatch::of(ethernet::field::DESTINATION, &box_mac),
            destination_is_broadcast: FieldMatch::of(ethernet::field::DESTINATION, &[0xFF; 6]),
            ethertype_is_arp: FieldMatch::of(
                ethernet::field::ETHERTYPE,
                &ETHERTYPE_ARP.to_be_bytes(),
            ),
            ethertype_is_ipv4: FieldMatch::of(
                ethernet::field::ETHERTYPE,
                &ETHERTYPE_IPV4.to_be_bytes(),
            ),
            payload_at: constant(ethernet::HEADER_LEN as u64),
            at_payload: Default::default(),
            arp: Default::default(),
            to_box_check: Default::default(),
            broadcast_check: Default::default(),
            ipv4_check: Default::default(),
        }
    }
}

impl Logic for EthernetDemux {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            at_payload,
            arp,
            to_box_check,
            broadcast_check,
            ipv4_check
        );
        self.destination_is_box.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.destination_is_box.beats);
        self.destination_is_broadcast.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.destination_is_broadcast.beats);
        self.ethertype_is_arp.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.ethertype_is_arp.beats);
        self.ethertype_is_ipv4.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.ethertype_is_ipv4.beats);
        if self.beats.next_valid.val() {
            self.at_payload.d.next = self.beats.next_index.val() == self.payload_at.val();
        }
        if self.beats.beat_valid.val() & self.at_payload.q.val() {
            self.arp.d.next = self.ethertype_is_arp.equals.val();
        }
        if self.beats.beat_valid.val() & self.beat_first.val() {
            self.arp.d.next = false;
        }
        self.to_box_check.d.next = self.destination_is_box.equals.val();
        self.broadcast_check.d.next = self.destination_is_broadcast.equals.val();
        self.ipv4_check.d.next = self.ethertype_is_ipv4.equals.val();
        self.is_arp.next = self.arp.q.val();
        self.to_box.next = self.to_box_check.q.val();
        self.broadcast.next = self.broadcast_check.q.val();
        self.ipv4.next = self.ipv4_check.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{send_frame_beats, Bench, TestRng};
    use skinbox_protocol::link::LinkConfig;
    use skinbox_protocol::wire::ethernet::EthernetRepr;

    /// Random frames (the box's MAC, broadcast, others; ARP, IPv4 and other EtherTypes; a
    /// few too short to hold the header) with idle clocks between beats: after each, the
    /// checks are the wire layer's parse of the frame.
    #[test]
    fn checks_match_the_wire_layers_parse() {
        let box_mac = LinkConfig::DEFAULT.box_mac;
        let mut rng = TestRng::new(17);
        let mut bench = Bench::new(EthernetDemux::new(box_mac), |d| &mut d.clock);
        let mut seen_arp = 0;
        for case in 0..300 {
            let destination = match rng.next_u64() % 3 {
                0 => box_mac,
                1 => [0xFF; 6],
                _ => {
                    let mut m = box_mac;
                    m[rng.next_u64() as usize % 6] ^= 1 << (rng.next_u64() % 8);
                    m
                }
            };
            let ethertype = match rng.next_u64() % 3 {
                0 => ETHERTYPE_ARP,
                1 => ETHERTYPE_IPV4,
                _ => rng.next_u64() as u16,
            };
            let mut frame = vec![0u8; 14 + rng.next_u64() as usize % 50];
            EthernetRepr {
                destination,
                source: [2, 0, 0, 0, 0, 1],
                ethertype,
            }
            .emit(&mut frame);
            for b in frame.iter_mut().skip(14) {
                *b = rng.next_u64() as u8;
            }
            send_frame_beats(
                &mut bench,
                &mut rng,
                &frame,
                0.2,
                |u| &mut u.beats,
                |u, r| {
                    u.beat_first.next = r == Some(0);
                },
            );
            let repr = EthernetRepr::parse(&frame).unwrap();
            let u = &bench.uut;
            assert_eq!(u.to_box.val(), repr.destination == box_mac, "case {case}");
            assert_eq!(
                u.broadcast.val(),
                repr.destination == [0xFF; 6],
                "case {case}"
            );
            assert_eq!(
                u.ipv4.val(),
                repr.ethertype == ETHERTYPE_IPV4,
                "case {case}"
            );
            // (a frame of the header alone never shows a byte after the EtherType)
            if frame.len() > 14 {
                assert_eq!(
                    u.is_arp.val(),
                    repr.ethertype == ETHERTYPE_ARP,
                    "case {case}"
                );
                seen_arp += usize::from(repr.ethertype == ETHERTYPE_ARP);
            }
        }
        assert!(seen_arp > 50, "{seen_arp} ARP frames");
    }
}

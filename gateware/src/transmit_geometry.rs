//! TransmitGeometry: the frame transmitter's held descriptor (body length, raw or not)
//! and the frame's geometry computed from it: where the body ends, the frame's last
//! index, the IPv4 total length and the UDP length.
//!
//! While no frame goes out (`load`) the descriptor's body length is held, and whether it
//! is a raw frame's ([`RAW_FRAME_KIND`]: its body follows the SFD). The geometry
//! follows the held values a clock later (latency 1 from the take: valid from the frame's
//! index 1 on, nothing reads it at index 0). (The kind is read from the descriptor, which
//! its source holds until the body's last beat.) Cost: the held 12 bits and the geometry's
//! registers (3 x 11 + 2 x 16 bits), one adder each.

use crate::hdl::*;
use crate::stream::RAW_FRAME_KIND;
use crate::transmit_layout::{BODY_START, IPV4_AT_ON_WIRE, UDP_AT_ON_WIRE};
use skinbox_protocol::link::{FCS_LEN, PREAMBLE_LEN};

/// The held descriptor and the frame geometry.
#[derive(LogicBlock)]
pub struct TransmitGeometry {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// No frame goes out: hold the descriptor.
    pub load: Signal<In, Bit>,
    /// The descriptor's kind.
    pub descriptor_kind: Signal<In, Bits<8>>,
    /// The descriptor's body length.
    pub body_len: Signal<In, Bits<11>>,
    /// The held descriptor is a raw frame's.
    pub raw: Signal<Out, Bit>,
    /// The index of the first byte after the body (the first FCS byte).
    pub body_end: Signal<Out, Bits<11>>,
    /// `body_end - 1`.
    pub body_end_less_one: Signal<Out, Bits<11>>,
    /// The index before the frame's last one (its last FCS byte).
    pub end_minus_one: Signal<Out, Bits<11>>,
    /// The IPv4 total length.
    pub total_len: Signal<Out, Bits<16>>,
    /// The UDP length.
    pub udp_len: Signal<Out, Bits<16>>,
    // the body's first byte and the frame's last byte minus one, less the body length,
    // of a datagram and of a raw frame
    body_start: Constant<Bits<11>>,
    frame_end_over_body: Constant<Bits<11>>,
    raw_body_start: Constant<Bits<11>>,
    raw_frame_end_over_body: Constant<Bits<11>>,
    raw_kind: Constant<Bits<8>>,
    // IPv4 total length and UDP length minus the body length
    ip_len_over_body: Constant<Bits<16>>,
    udp_len_over_body: Constant<Bits<16>>,
    body_len_held: DFF<Bits<11>>,
    raw_held: DFF<Bit>,
    body_end_at: DFF<Bits<11>>,
    body_end_less_one_at: DFF<Bits<11>>,
    end_minus_one_at: DFF<Bits<11>>,
    total_len_value: DFF<Bits<16>>,
    udp_len_value: DFF<Bits<16>>,
    // the body's first byte and the frame's end over the body, datagram or raw frame
    geometry_start: Signal<Local, Bits<11>>,
    geometry_end_over_body: Signal<Local, Bits<11>>,
}

impl Default for TransmitGeometry {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            load: Default::default(),
            descriptor_kind: Default::default(),
            body_len: Default::default(),
            raw: Default::default(),
            body_end: Default::default(),
            body_end_less_one: Default::default(),
            end_minus_one: Default::default(),
            total_len: Default::default(),
            udp_len: Default::default(),
            body_start: constant(BODY_START as u64),
            frame_end_over_body: constant((BODY_START + FCS_LEN - 2) as u64),
            raw_body_start: constant(PREAMBLE_LEN as u64),
            raw_frame_end_over_body: constant((PREAMBLE_LEN + FCS_LEN - 2) as u64),
            raw_kind: constant(u64::from(RAW_FRAME_KIND)),
            ip_len_over_body: constant((BODY_START - IPV4_AT_ON_WIRE) as u64),
            udp_len_over_body: constant((BODY_START - UDP_AT_ON_WIRE) as u64),
            body_len_held: Default::default(),
            raw_held: Default::default(),
            body_end_at: Default::default(),
            body_end_less_one_at: Default::default(),
            end_minus_one_at: Default::default(),
            total_len_value: Default::default(),
            udp_len_value: Default::default(),
            geometry_start: Default::default(),
            geometry_end_over_body: Default::default(),
        }
    }
}

impl Logic for TransmitGeometry {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            body_len_held,
            raw_held,
            body_end_at,
            body_end_less_one_at,
            end_minus_one_at,
            total_len_value,
            udp_len_value
        );
        self.geometry_start.next = self.body_start.val();
        self.geometry_end_over_body.next = self.frame_end_over_body.val();
        if self.raw_held.q.val() {
            self.geometry_start.next = self.raw_body_start.val();
            self.geometry_end_over_body.next = self.raw_frame_end_over_body.val();
        }
        self.body_end_at.d.next = self.body_len_held.q.val() + self.geometry_start.val();
        self.body_end_less_one_at.d.next =
            self.body_len_held.q.val() + self.geometry_start.val() - 1;
        self.end_minus_one_at.d.next =
            self.body_len_held.q.val() + self.geometry_end_over_body.val();
        self.total_len_value.d.next =
            bit_cast::<16, 11>(self.body_len_held.q.val()) + self.ip_len_over_body.val();
        self.udp_len_value.d.next =
            bit_cast::<16, 11>(self.body_len_held.q.val()) + self.udp_len_over_body.val();
        if self.load.val() {
            self.body_len_held.d.next = self.body_len.val();
            self.raw_held.d.next = self.descriptor_kind.val() == self.raw_kind.val();
        }
        self.raw.next = self.raw_held.q.val();
        self.body_end.next = self.body_end_at.q.val();
        self.body_end_less_one.next = self.body_end_less_one_at.q.val();
        self.end_minus_one.next = self.end_minus_one_at.q.val();
        self.total_len.next = self.total_len_value.q.val();
        self.udp_len.next = self.udp_len_value.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::datagram::HEADER_LEN;

    /// Random datagram and raw frame descriptors: the lengths are the protocol's (IPv4
    /// header 20, UDP header 8, box header), the body ends after the headers (after the
    /// SFD for a raw frame), the frame four FCS bytes later.
    #[test]
    fn the_geometry_is_the_frames() {
        let mut rng = TestRng::new(0x6E0);
        let mut bench = Bench::new(TransmitGeometry::default(), |b| &mut b.clock);
        for round in 0..200 {
            let raw = round % 3 == 0;
            let kind = if raw {
                RAW_FRAME_KIND
            } else {
                1 + rng.byte() % 0x7F
            };
            let body_len = if raw { 60 } else { 0 } + rng.next_u64() % 1000;
            let u = &mut bench.uut;
            u.load.next = true;
            u.descriptor_kind.next = u64::from(kind).into();
            u.body_len.next = body_len.into();
            bench.cycle();
            // the take: the descriptor holds while the frame goes out
            let u = &mut bench.uut;
            u.load.next = false;
            u.descriptor_kind.next = 0.into();
            u.body_len.next = 0.into();
            bench.cycle();
            let u = &bench.uut;
            assert_eq!(u.raw.val(), raw, "round {round}");
            let start = if raw {
                8
            } else {
                8 + 14 + 20 + 8 + HEADER_LEN as u64
            };
            assert_eq!(u.body_end.val().to_u64(), start + body_len, "round {round}");
            assert_eq!(u.body_end_less_one.val().to_u64(), start + body_len - 1);
            // the last FCS byte is at body_end + 3
            assert_eq!(u.end_minus_one.val().to_u64(), start + body_len + 2);
            let udp_len = 8 + HEADER_LEN as u64 + body_len;
            if !raw {
                assert_eq!(u.total_len.val().to_u64(), 20 + udp_len, "round {round}");
                assert_eq!(u.udp_len.val().to_u64(), udp_len, "round {round}");
            }
        }
    }
}

//! ReplyChecksums: the reply builder's IPv4 header and UDP checksums, summed from the
//! bytes it writes.
//!
//! A byte to sum (`sum_ip`, `sum_udp`) is its 16-bit word's high byte at an even frame
//! position (`low_byte` low) and its low byte at an odd one. It is registered first (the
//! buffer's output, which a copied byte comes from, feeds no adder), then added; the sums
//! are folded twice, a register each, and complemented into the checksums, which are final
//! [`CHECKSUM_CLOCKS`] clocks after the last byte summed. A UDP checksum computed as 0 is
//! 0xFFFF (RFC 768). `restart` clears both sums. The IPv4 sum holds 16 words (a header
//! is 10), the UDP sum 256 ([`UDP_SUM_BYTES`]).

use crate::hdl::*;

/// Clocks from a summed byte to the checksums that include it: the byte's register, the
/// sum, two folds, the complement.
pub const CHECKSUM_CLOCKS: u64 = 5;

/// Bytes the UDP sum holds without overflowing (256 words of 0xFFFF in 24 bits).
pub const UDP_SUM_BYTES: usize = 512;

/// The reply's checksums.
#[derive(LogicBlock, Default)]
pub struct ReplyChecksums {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: no byte is summed.
    pub reset: Signal<In, Bit>,
    /// Clear both sums (a reply starts).
    pub restart: Signal<In, Bit>,
    /// The byte written.
    pub written: Signal<In, Bits<8>>,
    /// The byte's frame position is odd: the low byte of its word.
    pub low_byte: Signal<In, Bit>,
    /// Sum the byte into the IPv4 header checksum.
    pub sum_ip: Signal<In, Bit>,
    /// Sum the byte into the UDP checksum.
    pub sum_udp: Signal<In, Bit>,
    /// The IPv4 header checksum.
    pub ip_checksum: Signal<Out, Bits<16>>,
    /// The UDP checksum.
    pub udp_checksum: Signal<Out, Bits<16>>,
    s6_summand: DFF<Bits<16>>,
    s6_sum_ip: DFF<Bit>,
    s6_sum_udp: DFF<Bit>,
    ip_sum: DFF<Bits<20>>,
    udp_sum: DFF<Bits<24>>,
    ip_fold: DFF<Bits<17>>,
    ip_folded: DFF<Bits<16>>,
    udp_fold: DFF<Bits<17>>,
    udp_folded: DFF<Bits<16>>,
    ip_result: DFF<Bits<16>>,
    udp_result: DFF<Bits<16>>,
    summand: Signal<Local, Bits<16>>,
}

impl Logic for ReplyChecksums {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self, clock, s6_summand, s6_sum_ip, s6_sum_udp, ip_sum, udp_sum, ip_fold, ip_folded,
            udp_fold, udp_folded, ip_result, udp_result
        );
        self.summand.next = bit_cast::<16, 8>(self.written.val());
        if !self.low_byte.val() {
            self.summand.next = bit_cast::<16, 8>(self.written.val()) << 8;
        }
        // (summed a clock later, from a register: the buffer's output feeds no adder)
        self.s6_summand.d.next = self.summand.val();
        self.s6_sum_ip.d.next = self.sum_ip.val();
        self.s6_sum_udp.d.next = self.sum_udp.val();
        if self.s6_sum_ip.q.val() {
            self.ip_sum.d.next = self.ip_sum.q.val() + bit_cast::<20, 16>(self.s6_summand.q.val());
        }
        if self.s6_sum_udp.q.val() {
            self.udp_sum.d.next =
                self.udp_sum.q.val() + bit_cast::<24, 16>(self.s6_summand.q.val());
        }
        self.ip_fold.d.next = bit_cast::<17, 16>(self.ip_sum.q.val().get_bits::<16>(0))
            + bit_cast::<17, 4>(self.ip_sum.q.val().get_bits::<4>(16));
        // (at most 0x1000E: adding its carry bit cannot carry again)
        self.ip_folded.d.next = self.ip_fold.q.val().get_bits::<16>(0)
            + bit_cast::<16, 1>(self.ip_fold.q.val().get_bits::<1>(16));
        self.ip_result.d.next = !self.ip_folded.q.val();
        self.udp_fold.d.next = bit_cast::<17, 16>(self.udp_sum.q.val().get_bits::<16>(0))
            + bit_cast::<17, 8>(self.udp_sum.q.val().get_bits::<8>(16));
        self.udp_folded.d.next = self.udp_fold.q.val().get_bits::<16>(0)
            + bit_cast::<16, 1>(self.udp_fold.q.val().get_bits::<1>(16));
        self.udp_result.d.next = !self.udp_folded.q.val();
        if self.udp_folded.q.val() == 0xFFFF {
            // a computed 0 is sent as 0xFFFF (RFC 768)
            self.udp_result.d.next = 0xFFFF.into();
        }
        if self.restart.val() {
            self.ip_sum.d.next = 0.into();
            self.udp_sum.d.next = 0.into();
        }
        if self.reset.val() {
            self.s6_sum_ip.d.next = false;
            self.s6_sum_udp.d.next = false;
        }
        self.ip_checksum.next = self.ip_result.q.val();
        self.udp_checksum.next = self.udp_result.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::wire::checksum::checksum;

    /// Random frames: the IPv4 header's bytes summed into one checksum and a UDP part into
    /// the other, one byte per clock or with gaps, against the protocol's checksum.
    #[test]
    fn checksums_match_the_protocols() {
        let mut bench = Bench::new(ReplyChecksums::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xC5);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut udp_zero = 0;
        for round in 0..300 {
            let len = 2 + (rng.next_u64() % 120) as usize;
            let mut frame: Vec<u8> = (0..len).map(|_| rng.byte()).collect();
            if round % 50 == 0 {
                // all ones but a word: sums to 0xFFFF, a UDP checksum of 0
                frame.fill(0xFF);
                frame[0] = 0;
                frame[1] = 0;
            }
            // the IPv4 bytes: an even-aligned run of at most a header's 20; the UDP bytes:
            // from an even position on
            let ip_from = 2 * (rng.next_u64() as usize % (len / 2));
            let ip_to = (ip_from + (rng.next_u64() as usize % 21)).min(len);
            let udp_from = 2 * (rng.next_u64() as usize % (len / 2));
            bench.uut.restart.next = true;
            bench.cycle();
            bench.uut.restart.next = false;
            for (at, &byte) in frame.iter().enumerate() {
                let u = &mut bench.uut;
                u.written.next = u64::from(byte).into();
                u.low_byte.next = at % 2 == 1;
                u.sum_ip.next = (ip_from..ip_to).contains(&at);
                u.sum_udp.next = at >= udp_from;
                bench.cycle();
                if rng.chance(0.2) {
                    bench.uut.sum_ip.next = false;
                    bench.uut.sum_udp.next = false;
                    bench.cycle();
                }
            }
            bench.uut.sum_ip.next = false;
            bench.uut.sum_udp.next = false;
            bench.cycles(CHECKSUM_CLOCKS);
            let ip = checksum(&[&frame[ip_from..ip_to]]);
            let mut udp = checksum(&[&frame[udp_from..]]);
            if udp == 0 {
                udp = 0xFFFF;
                udp_zero += 1;
            }
            let u = &bench.uut;
            assert_eq!(
                u.ip_checksum.val().to_u64() as u16,
                ip,
                "round {round} IPv4"
            );
            assert_eq!(
                u.udp_checksum.val().to_u64() as u16,
                udp,
                "round {round} UDP"
            );
        }
        assert!(udp_zero > 0, "a UDP checksum of 0 came up");
    }
}

//! ReplyChecksums: the reply builder's IPv4 header and UDP checksums, summed from the
//! bytes it writes.
//!
//! A byte to sum (`sum_ip`, `sum_udp`) is its 16-bit word's high byte at an even frame
//! position (`low_byte` low) and its low byte at an odd one. The word is registered first,
//! once for each sum (0 for a sum the byte is not summed into; the buffer's output, which
//! a copied byte comes from, feeds no adder), then added into a running sum with an
//! end-around carry ([`OnesComplementSum`], one each) every clock, so a clock without a
//! byte adds the carry left over: two clocks after the last byte was added the carry is 0
//! and the sum is folded. The IPv4 checksum is its sum's complement (a wire). The UDP sum
//! adds the words' complements, so that it is the checksum itself, with no compare after
//! it: a ones'-complement sum with an end-around carry never becomes 0x0000 from terms that
//! are not all 0 (a summed byte's complemented word never is), so a checksum computed as 0
//! comes out as 0xFFFF, as RFC 768 sends it. The checksums include a byte three clocks
//! after it was summed; the programs wait [`CHECKSUM_CLOCKS`]. `restart` clears both sums.
//! A sum holds any number of bytes. Cost: the two registered words and the two sums (17
//! bits each).

use crate::hdl::*;
use crate::ones_complement_sum::OnesComplementSum;

/// Clocks from a summed byte to the clock its checksum byte may be taken (the programs'
/// wait): the words' register, the sum, the last carry (three clocks), and two to spare,
/// where the sums were once folded in registers (the replies' timing).
pub const CHECKSUM_CLOCKS: u64 = 5;

/// Bytes the UDP sum of a reply may hold (the longest reply's UDP part and pseudo header
/// fit; the running sum itself has no limit).
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
    /// The IPv4 header checksum ([`CHECKSUM_CLOCKS`] after the last byte summed).
    pub ip_checksum: Signal<Out, Bits<16>>,
    /// The UDP checksum (as `ip_checksum`).
    pub udp_checksum: Signal<Out, Bits<16>>,
    ip_sum: OnesComplementSum,
    udp_sum: OnesComplementSum,
    // the byte as its word, for each sum (0 when not summed into it)
    ip_word: DFF<Bits<16>>,
    udp_word: DFF<Bits<16>>,
    summand: Signal<Local, Bits<16>>,
}

impl Logic for ReplyChecksums {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, ip_word, udp_word);
        self.summand.next = bit_cast::<16, 8>(self.written.val());
        if !self.low_byte.val() {
            self.summand.next = bit_cast::<16, 8>(self.written.val()) << 8;
        }
        // (summed a clock later, from a register: the buffer's output feeds no adder)
        self.ip_word.d.next = 0.into();
        if self.sum_ip.val() {
            self.ip_word.d.next = self.summand.val();
        }
        // (the UDP sum adds the words' complements: its sum is the checksum itself)
        self.udp_word.d.next = 0.into();
        if self.sum_udp.val() {
            self.udp_word.d.next = !self.summand.val();
        }
        if self.reset.val() {
            self.ip_word.d.next = 0.into();
            self.udp_word.d.next = 0.into();
        }
        // (every clock: a word of 0 adds the last carry)
        self.ip_sum.clock.next = self.clock.val();
        self.ip_sum.add.next = true;
        self.ip_sum.word.next = self.ip_word.q.val();
        self.ip_sum.restart.next = self.restart.val();
        self.ip_sum.start.next = 0.into();
        self.udp_sum.clock.next = self.clock.val();
        self.udp_sum.add.next = true;
        self.udp_sum.word.next = self.udp_word.q.val();
        self.udp_sum.restart.next = self.restart.val();
        self.udp_sum.start.next = 0.into();
        self.ip_checksum.next = !self.ip_sum.sum.val();
        self.udp_checksum.next = self.udp_sum.sum.val();
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

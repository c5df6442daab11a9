//! HeaderSums: the frame transmitter's IPv4 header checksum, the IPv4 layer's transmit
//! half, and the sum of the destination's words the UDP checksum adds.
//!
//! The destination's IPv4 address and UDP port are read where the transmitter holds them
//! (steady from the take for [`IP_CHECKSUM_CLOCKS`] clocks; its shift register moves them
//! later), and the sums are kept from then on (`hold`). A clock after the take the
//! address's two words are summed, a clock later with the port
//! (`destination_sum`, for the UDP checksum) and with the total length (the IPv4 header's
//! variable words; the constant words' sum is a build-time constant), which is folded once
//! into a register and once more, complemented, into `ip_checksum`: final
//! [`IP_CHECKSUM_CLOCKS`] clocks after the take, from the total length registered a clock
//! after it (long before byte 32 of the frame needs it).

use crate::hdl::*;

/// Clocks from the take (the last `load`) to a final `ip_checksum`.
pub const IP_CHECKSUM_CLOCKS: u64 = 4;

/// The IPv4 header checksum and the destination's sum.
#[derive(LogicBlock)]
pub struct HeaderSums {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The destination's IPv4 address (steady for [`IP_CHECKSUM_CLOCKS`] clocks from the
    /// take).
    pub destination_ip: Signal<In, Bits<32>>,
    /// The destination's UDP port (steady like `destination_ip`).
    pub destination_port: Signal<In, Bits<16>>,
    /// The IPv4 total length (steady from a clock after the take).
    pub total_len: Signal<In, Bits<16>>,
    /// Keep the sums (from [`IP_CHECKSUM_CLOCKS`] clocks after the take to the frame's end).
    pub hold: Signal<In, Bit>,
    /// The sum of the destination address's and port's words (not folded).
    pub destination_sum: Signal<Out, Bits<18>>,
    /// The IPv4 header checksum.
    pub ip_checksum: Signal<Out, Bits<16>>,
    ip_constant_sum: Constant<Bits<32>>,
    ip_words: DFF<Bits<17>>,
    with_port: DFF<Bits<18>>,
    ip_variable: DFF<Bits<18>>,
    ip_fold: DFF<Bits<32>>,
    checksum: DFF<Bits<16>>,
    ip_sum: Signal<Local, Bits<32>>,
}

impl HeaderSums {
    /// The sums of a header whose constant words (all but the total length and the
    /// destination) sum to `ip_constant_sum` (not folded).
    pub fn new(ip_constant_sum: u64) -> Self {
        Self {
            clock: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            total_len: Default::default(),
            hold: Default::default(),
            destination_sum: Default::default(),
            ip_checksum: Default::default(),
            ip_constant_sum: constant(ip_constant_sum),
            ip_words: Default::default(),
            with_port: Default::default(),
            ip_variable: Default::default(),
            ip_fold: Default::default(),
            checksum: Default::default(),
            ip_sum: Default::default(),
        }
    }
}

impl Logic for HeaderSums {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            ip_words,
            with_port,
            ip_variable,
            ip_fold,
            checksum
        );
        self.ip_sum.next =
            self.ip_constant_sum.val() + bit_cast::<32, 18>(self.ip_variable.q.val());
        if !self.hold.val() {
            self.ip_words.d.next = bit_cast::<17, 16>(self.destination_ip.val().get_bits::<16>(16))
                + bit_cast::<17, 16>(self.destination_ip.val().get_bits::<16>(0));
            self.with_port.d.next = bit_cast::<18, 17>(self.ip_words.q.val())
                + bit_cast::<18, 16>(self.destination_port.val());
            self.ip_variable.d.next = bit_cast::<18, 16>(self.total_len.val())
                + bit_cast::<18, 17>(self.ip_words.q.val());
            self.ip_fold.d.next = (self.ip_sum.val() & 0xFFFF) + (self.ip_sum.val() >> 16);
            self.checksum.d.next =
                !bit_cast::<16, 32>((self.ip_fold.q.val() & 0xFFFF) + (self.ip_fold.q.val() >> 16));
        }
        self.destination_sum.next = self.with_port.q.val();
        self.ip_checksum.next = self.checksum.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::wire::checksum::checksum;

    /// Random headers: the checksum is the protocol's over the constant words, the total
    /// length and the destination; the destination's sum is its words' sum.
    #[test]
    fn the_header_checksum_is_the_protocols() {
        let mut rng = TestRng::new(0x1B4);
        for round in 0..200 {
            // the eight constant words of an IPv4 header without options
            let constant: Vec<u8> = (0..16).map(|_| rng.byte()).collect();
            let constant_sum: u64 = constant
                .chunks(2)
                .map(|w| u64::from(u16::from_be_bytes([w[0], w[1]])))
                .sum();
            let mut bench = Bench::new(HeaderSums::new(constant_sum), |b| &mut b.clock);
            let ip = rng.next_u64() as u32;
            let port = rng.next_u64() as u16;
            let total_len = 28 + rng.next_u64() as u16 % 1473;
            let u = &mut bench.uut;
            u.destination_ip.next = (rng.next_u64() & 0xFFFF_FFFF).into();
            u.destination_port.next = (rng.next_u64() & 0xFFFF).into();
            bench.cycle();
            // the take: the destination is steady from here on; the total length follows
            // a clock later
            let u = &mut bench.uut;
            u.destination_ip.next = u64::from(ip).into();
            u.destination_port.next = u64::from(port).into();
            bench.cycle();
            bench.uut.total_len.next = u64::from(total_len).into();
            bench.cycles(IP_CHECKSUM_CLOCKS - 1);
            // the sums are kept while the destination and the total length move on
            let u = &mut bench.uut;
            u.hold.next = true;
            u.destination_ip.next = (rng.next_u64() & 0xFFFF_FFFF).into();
            u.destination_port.next = (rng.next_u64() & 0xFFFF).into();
            u.total_len.next = (rng.next_u64() & 0xFFFF).into();
            bench.cycles(1 + rng.next_u64() % 5);
            bench.uut.hold.next = false;
            let want = checksum(&[&constant, &total_len.to_be_bytes(), &ip.to_be_bytes()]);
            let u = &bench.uut;
            assert_eq!(u.ip_checksum.val().to_u64() as u16, want, "round {round}");
            let words = u64::from(ip >> 16) + u64::from(ip & 0xFFFF) + u64::from(port);
            assert_eq!(u.destination_sum.val().to_u64(), words, "round {round}");
        }
    }
}

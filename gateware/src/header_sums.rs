//! HeaderSums: the frame transmitter's IPv4 header checksum, the IPv4 layer's transmit
//! half, and the sum of the destination's words the UDP checksum adds.
//!
//! The destination's IPv4 address and UDP port are read where the transmitter holds them
//! (steady from the take until `hold`; its shift register moves them later), and the
//! destination's sum is kept from then on (`hold`, at least two clocks after the take): a
//! clock after the take the address's two words are summed, a clock later with the port
//! (`destination_sum`, for the UDP checksum). The IPv4 checksum is one ones'-complement summer
//! ([`OnesComplementSum`]) that restarts from the constant words' folded sum (a build
//! parameter) while no frame goes out (`restart`) and then adds one variable word a clock
//! from a term register: the address's high and low words, then the total length (steady
//! from a clock after the take), then zeros, which fold the last carry in. The checksum is
//! the sum's complement (a wire), final [`IP_CHECKSUM_CLOCKS`] clocks after the take, long
//! before byte 32 of the frame needs it. Cost: 17 + 18 bits of destination sum, 17 of
//! summer, 16 of term and a 2-bit step; one adder a register.

use crate::hdl::*;
use crate::ones_complement_sum::OnesComplementSum;
use skinbox_protocol::wire::checksum::fold;

/// Clocks from the take (the last `restart`) to a final `ip_checksum`: three words
/// registered and added, one clock to fold the last carry.
pub const IP_CHECKSUM_CLOCKS: u64 = 5;

/// The IPv4 header checksum and the destination's sum.
#[derive(LogicBlock)]
pub struct HeaderSums {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// No frame goes out: the checksum starts again (the clock of the take is the last).
    pub restart: Signal<In, Bit>,
    /// The destination's IPv4 address (steady from the take until `hold`).
    pub destination_ip: Signal<In, Bits<32>>,
    /// The destination's UDP port (steady like `destination_ip`).
    pub destination_port: Signal<In, Bits<16>>,
    /// The IPv4 total length (steady from a clock after the take).
    pub total_len: Signal<In, Bits<16>>,
    /// Keep the destination's sum (from two clocks or more after the take to the frame's
    /// end).
    pub hold: Signal<In, Bit>,
    /// The sum of the destination address's and port's words (not folded).
    pub destination_sum: Signal<Out, Bits<18>>,
    /// The IPv4 header checksum.
    pub ip_checksum: Signal<Out, Bits<16>>,
    ip_summer: OnesComplementSum,
    // the constant words' folded sum
    ip_start: Constant<Bits<16>>,
    ip_term: DFF<Bits<16>>,
    // the variable word to register: the address's high word (0), low word (1), the total
    // length (2), none (3)
    ip_step: DFF<Bits<2>>,
    ip_words: DFF<Bits<17>>,
    with_port: DFF<Bits<18>>,
}

impl HeaderSums {
    /// The sums of a header whose constant words (all but the total length and the
    /// destination) sum to `ip_constant_sum` (not folded).
    pub fn new(ip_constant_sum: u64) -> Self {
        Self {
            clock: Default::default(),
            restart: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            total_len: Default::default(),
            hold: Default::default(),
            destination_sum: Default::default(),
            ip_checksum: Default::default(),
            ip_summer: Default::default(),
            ip_start: constant(u64::from(fold(ip_constant_sum))),
            ip_term: Default::default(),
            ip_step: Default::default(),
            ip_words: Default::default(),
            with_port: Default::default(),
        }
    }
}

impl Logic for HeaderSums {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, ip_term, ip_step, ip_words, with_port);
        self.ip_term.d.next = 0.into();
        if self.ip_step.q.val() == 0 {
            self.ip_term.d.next = self.destination_ip.val().get_bits::<16>(16);
        }
        if self.ip_step.q.val() == 1 {
            self.ip_term.d.next = self.destination_ip.val().get_bits::<16>(0);
        }
        if self.ip_step.q.val() == 2 {
            self.ip_term.d.next = self.total_len.val();
        }
        self.ip_step.d.next = self.ip_step.q.val();
        if self.ip_step.q.val() != 3 {
            self.ip_step.d.next = self.ip_step.q.val() + 1;
        }
        if self.restart.val() {
            self.ip_term.d.next = 0.into();
            self.ip_step.d.next = 0.into();
        }
        self.ip_summer.clock.next = self.clock.val();
        self.ip_summer.add.next = true;
        self.ip_summer.word.next = self.ip_term.q.val();
        self.ip_summer.restart.next = self.restart.val();
        self.ip_summer.start.next = self.ip_start.val();
        if !self.hold.val() {
            self.ip_words.d.next = bit_cast::<17, 16>(self.destination_ip.val().get_bits::<16>(16))
                + bit_cast::<17, 16>(self.destination_ip.val().get_bits::<16>(0));
            self.with_port.d.next = bit_cast::<18, 17>(self.ip_words.q.val())
                + bit_cast::<18, 16>(self.destination_port.val());
        }
        self.destination_sum.next = self.with_port.q.val();
        self.ip_checksum.next = !self.ip_summer.sum.val();
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
            u.restart.next = true;
            u.destination_ip.next = (rng.next_u64() & 0xFFFF_FFFF).into();
            u.destination_port.next = (rng.next_u64() & 0xFFFF).into();
            u.total_len.next = (rng.next_u64() & 0xFFFF).into();
            bench.cycles(1 + rng.next_u64() % 3);
            // the take: the destination is steady from here on; the total length follows
            // a clock later
            let u = &mut bench.uut;
            u.destination_ip.next = u64::from(ip).into();
            u.destination_port.next = u64::from(port).into();
            bench.cycle();
            bench.uut.restart.next = false;
            bench.uut.total_len.next = u64::from(total_len).into();
            bench.cycles(IP_CHECKSUM_CLOCKS - 1);
            // the sums are kept while the destination and the total length move on
            let u = &mut bench.uut;
            u.hold.next = true;
            u.destination_ip.next = (rng.next_u64() & 0xFFFF_FFFF).into();
            u.destination_port.next = (rng.next_u64() & 0xFFFF).into();
            u.total_len.next = (rng.next_u64() & 0xFFFF).into();
            bench.cycles(1 + rng.next_u64() % 5);
            let want = checksum(&[&constant, &total_len.to_be_bytes(), &ip.to_be_bytes()]);
            let u = &bench.uut;
            assert_eq!(u.ip_checksum.val().to_u64() as u16, want, "round {round}");
            let words = u64::from(ip >> 16) + u64::from(ip & 0xFFFF) + u64::from(port);
            assert_eq!(u.destination_sum.val().to_u64(), words, "round {round}");
            bench.uut.hold.next = false;
        }
    }
}

//! ReplyFieldBytes: the reply builder's held-field bytes, one chosen per clock.
//!
//! The fields a reply takes from outside the request (the destination now in effect, the
//! last accepted sequence number, the receive or send tick, the echo reply's ICMP
//! checksum, the result and the link state) are four 64-bit words, most significant byte
//! first ([`field_byte`]'s positions: byte `8 w + b` is byte `b` of word `w`). The receive
//! and the send tick are one word: the reply builder holds the request's receive tick
//! until an acknowledgement's take and the send tick from then on. In one clock
//! `byte_index` (b) chooses each word's byte into a register; in the next, `word_index`
//! (w) chooses among those four registers: balanced trees of two-way multiplexers, byte in
//! the word first, which map onto the LUTs and the slices' PFUMX/L6MUX, with a register
//! between the two halves.

use crate::hdl::*;

/// Byte positions of the held fields (four 64-bit words, most significant byte first). The
/// request's own fields (addresses, port, sequence number, host time, opcode) are not
/// among them: the reply builder copies them in the buffer or leaves them where they are.
pub mod field_byte {
    /// The destination MAC (6 bytes).
    pub const DESTINATION_MAC: u8 = 0;
    /// The destination UDP port (2 bytes).
    pub const DESTINATION_PORT: u8 = 6;
    /// The destination IPv4 address (4 bytes).
    pub const DESTINATION_IP: u8 = 8;
    /// The last accepted sequence number (4 bytes).
    pub const LAST_ACCEPTED: u8 = 12;
    /// The request's receive tick (8 bytes), read before an acknowledgement's take.
    pub const RECEIVE_TICK: u8 = 16;
    /// The acknowledgement's send tick (8 bytes): the same word, read after the take.
    pub const SEND_TICK: u8 = RECEIVE_TICK;
    /// The echo reply's ICMP checksum (2 bytes).
    pub const ICMP_CHECKSUM: u8 = 24;
    /// The command's result (1 byte).
    pub const RESULT: u8 = 26;
    /// Link up, 0 or 1 (1 byte).
    pub const LINK_UP: u8 = 27;
    /// The link speed (1 byte).
    pub const LINK_SPEED: u8 = 28;
}

/// The held fields' byte multiplexer.
#[derive(LogicBlock, Default)]
pub struct ReplyFieldBytes {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The byte in each word (0: most significant), registered this clock.
    pub byte_index: Signal<In, Bits<3>>,
    /// The word, a clock after its `byte_index`.
    pub word_index: Signal<In, Bits<2>>,
    /// Word 0: the destination MAC, then its UDP port.
    pub destination_mac: Signal<In, Bits<48>>,
    /// See `destination_mac`.
    pub destination_port: Signal<In, Bits<16>>,
    /// Word 1: the destination IPv4 address, then the last accepted sequence number.
    pub destination_ip: Signal<In, Bits<32>>,
    /// See `destination_ip`.
    pub last_accepted: Signal<In, Bits<32>>,
    /// Word 2: the request's receive tick or the acknowledgement's send tick.
    pub tick: Signal<In, Bits<64>>,
    /// Word 3: the ICMP checksum (the complement of this sum), the result, link up and
    /// link speed, then zeros.
    pub icmp_rest_sum: Signal<In, Bits<16>>,
    /// See `icmp_rest_sum`.
    pub result: Signal<In, Bits<8>>,
    /// See `icmp_rest_sum`.
    pub link_up: Signal<In, Bit>,
    /// See `icmp_rest_sum`.
    pub link_speed: Signal<In, Bits<2>>,
    /// The byte at `word_index` and the registered `byte_index`.
    pub field_byte: Signal<Out, Bits<8>>,
    icmp_checksum: Signal<Local, Bits<16>>,
    field_byte_index: Signal<Local, Bits<3>>,
    word_bytes_0: DFF<Bits<8>>,
    word_bytes_1: DFF<Bits<8>>,
    word_bytes_2: DFF<Bits<8>>,
    word_bytes_3: DFF<Bits<8>>,
}

impl Logic for ReplyFieldBytes {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            word_bytes_0,
            word_bytes_1,
            word_bytes_2,
            word_bytes_3
        );
        // (byte in the word first, then the word: balanced trees of two-way multiplexers,
        // which map onto the LUTs and the slices' PFUMX/L6MUX)
        self.icmp_checksum.next = !self.icmp_rest_sum.val();
        self.field_byte_index.next = self.byte_index.val();
        if self.field_byte_index.val().get_bit(2) {
            if self.field_byte_index.val().get_bit(1) {
                if self.field_byte_index.val().get_bit(0) {
                    self.word_bytes_0.d.next = self.destination_port.val().get_bits::<8>(0);
                    self.word_bytes_1.d.next = self.last_accepted.val().get_bits::<8>(0);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(0);
                    self.word_bytes_3.d.next = 0.into();
                } else {
                    self.word_bytes_0.d.next = self.destination_port.val().get_bits::<8>(8);
                    self.word_bytes_1.d.next = self.last_accepted.val().get_bits::<8>(8);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(8);
                    self.word_bytes_3.d.next = 0.into();
                }
            } else {
                if self.field_byte_index.val().get_bit(0) {
                    self.word_bytes_0.d.next = self.destination_mac.val().get_bits::<8>(0);
                    self.word_bytes_1.d.next = self.last_accepted.val().get_bits::<8>(16);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(16);
                    self.word_bytes_3.d.next = 0.into();
                } else {
                    self.word_bytes_0.d.next = self.destination_mac.val().get_bits::<8>(8);
                    self.word_bytes_1.d.next = self.last_accepted.val().get_bits::<8>(24);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(24);
                    self.word_bytes_3.d.next = bit_cast::<8, 2>(self.link_speed.val());
                }
            }
        } else {
            if self.field_byte_index.val().get_bit(1) {
                if self.field_byte_index.val().get_bit(0) {
                    self.word_bytes_0.d.next = self.destination_mac.val().get_bits::<8>(16);
                    self.word_bytes_1.d.next = self.destination_ip.val().get_bits::<8>(0);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(32);
                    self.word_bytes_3.d.next = bit_cast::<8, 1>(self.link_up.val().into());
                } else {
                    self.word_bytes_0.d.next = self.destination_mac.val().get_bits::<8>(24);
                    self.word_bytes_1.d.next = self.destination_ip.val().get_bits::<8>(8);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(40);
                    self.word_bytes_3.d.next = self.result.val();
                }
            } else {
                if self.field_byte_index.val().get_bit(0) {
                    self.word_bytes_0.d.next = self.destination_mac.val().get_bits::<8>(32);
                    self.word_bytes_1.d.next = self.destination_ip.val().get_bits::<8>(16);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(48);
                    self.word_bytes_3.d.next = self.icmp_checksum.val().get_bits::<8>(0);
                } else {
                    self.word_bytes_0.d.next = self.destination_mac.val().get_bits::<8>(40);
                    self.word_bytes_1.d.next = self.destination_ip.val().get_bits::<8>(24);
                    self.word_bytes_2.d.next = self.tick.val().get_bits::<8>(56);
                    self.word_bytes_3.d.next = self.icmp_checksum.val().get_bits::<8>(8);
                }
            }
        }
        if self.word_index.val().get_bit(1) {
            if self.word_index.val().get_bit(0) {
                self.field_byte.next = self.word_bytes_3.q.val();
            } else {
                self.field_byte.next = self.word_bytes_2.q.val();
            }
        } else if self.word_index.val().get_bit(0) {
            self.field_byte.next = self.word_bytes_1.q.val();
        } else {
            self.field_byte.next = self.word_bytes_0.q.val();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    #[test]
    fn every_field_byte_comes_out_of_its_position() {
        let mut bench = Bench::new(ReplyFieldBytes::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xF1E1D);
        for round in 0..50 {
            let mac = rng.next_u64() >> 16;
            let port = rng.next_u64() as u16;
            let ip = rng.next_u64() as u32;
            let last = rng.next_u64() as u32;
            let tick = rng.next_u64();
            let rest = rng.next_u64() as u16;
            let result = rng.byte();
            let up = rng.chance(0.5);
            let speed = rng.next_u64() % 4;
            // the four words as the reply builder's `field_byte` positions lay them out
            let mut bytes = Vec::new();
            bytes.extend(&mac.to_be_bytes()[2..]);
            bytes.extend(port.to_be_bytes());
            bytes.extend(ip.to_be_bytes());
            bytes.extend(last.to_be_bytes());
            bytes.extend(tick.to_be_bytes());
            bytes.extend((!rest).to_be_bytes());
            bytes.extend([result, u8::from(up), speed as u8, 0, 0, 0]);
            assert_eq!(bytes.len(), 32);
            // the positions the reply builder's programs name
            let at = |p: u8| bytes[usize::from(p)];
            assert_eq!(at(field_byte::DESTINATION_PORT), (port >> 8) as u8);
            assert_eq!(at(field_byte::DESTINATION_IP), (ip >> 24) as u8);
            assert_eq!(at(field_byte::LAST_ACCEPTED), (last >> 24) as u8);
            assert_eq!(at(field_byte::RECEIVE_TICK), (tick >> 56) as u8);
            assert_eq!(at(field_byte::SEND_TICK), (tick >> 56) as u8);
            assert_eq!(at(field_byte::ICMP_CHECKSUM), (!rest >> 8) as u8);
            assert_eq!(at(field_byte::RESULT), result);
            assert_eq!(at(field_byte::LINK_UP), u8::from(up));
            assert_eq!(at(field_byte::LINK_SPEED), speed as u8);
            assert_eq!(at(field_byte::DESTINATION_MAC), (mac >> 40) as u8);
            let u = &mut bench.uut;
            u.destination_mac.next = mac.into();
            u.destination_port.next = u64::from(port).into();
            u.destination_ip.next = u64::from(ip).into();
            u.last_accepted.next = u64::from(last).into();
            u.tick.next = tick.into();
            u.icmp_rest_sum.next = u64::from(rest).into();
            u.result.next = u64::from(result).into();
            u.link_up.next = up;
            u.link_speed.next = speed.into();
            for position in 0..32u64 {
                bench.uut.byte_index.next = (position % 8).into();
                bench.cycle();
                bench.uut.word_index.next = (position / 8).into();
                bench.settle();
                assert_eq!(
                    bench.uut.field_byte.val().to_u64() as u8,
                    bytes[position as usize],
                    "round {round}, position {position}"
                );
            }
        }
    }
}

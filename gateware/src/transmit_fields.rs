//! TransmitFields: the frame transmitter's datagram header fields (flags, sequence number,
//! base tick, entry count) and the box's datagram sequence number.
//!
//! The descriptor's flags, base tick and entry count are read where the datagram's source
//! holds them (on the arbiter's descriptor, from the frame's index 0, the clock after the
//! take, until the body's last beat; the header's field bytes are read before the body),
//! with the sequence number: 15 bytes,
//! most significant first, and a zero byte (the first reserved byte) as two 64-bit words
//! (no word over 64 bits to simulate), no copy held. A position steps through them one
//! byte per clock: once from the frame's index 2 to 17 for the UDP checksum (all 16 bytes;
//! back at 0 after them), and once from index 57 to 71 to send the 15 field bytes;
//! `field_byte` is a register read from the fields at the position (no multiplexer between
//! the position and its use), the field byte of frame index `i` in the clock of index `i`.
//! The read takes two clocks: the four-byte group holding the byte is registered first
//! (from the position two clocks ahead), then the byte from it, so that neither the
//! arbiter's choice of source nor the position runs through a 16-byte multiplexer in one
//! clock. `advance` (a datagram's last clock) steps the sequence number. Cost: the 32-bit
//! sequence number, two 4-bit positions, the step flag, the 32-bit group and the byte
//! register.

use crate::hdl::*;
use crate::transmit_layout::{FIELDS_AT, FIELDS_LEN};

/// The header fields, sent one byte per clock.
#[derive(LogicBlock)]
pub struct TransmitFields {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the sequence number restarts at 0.
    pub reset: Signal<In, Bit>,
    /// The descriptor's flags (steady from the take until the frame's index 72).
    pub flags: Signal<In, Bits<8>>,
    /// The descriptor's base tick (steady like `flags`).
    pub base_tick: Signal<In, Bits<64>>,
    /// The descriptor's entry count (steady like `flags`).
    pub entry_count: Signal<In, Bits<16>>,
    /// A datagram's last clock: the sequence number steps.
    pub advance: Signal<In, Bit>,
    /// The frame goes on after this clock's index.
    pub frame_goes_on: Signal<In, Bit>,
    /// The frame's index in this clock.
    pub index: Signal<In, Bits<11>>,
    /// The field byte of this clock's index.
    pub field_byte: Signal<Out, Bits<8>>,
    // the first field byte and the byte after the fields, each three lower (the field
    // position steps there, tested a clock ahead)
    fields_ahead: Constant<Bits<7>>,
    fields_end_ahead: Constant<Bits<7>>,
    next_sequence: DFF<Bits<32>>,
    // the position of the next clock's field byte
    next_field_position: DFF<Bits<4>>,
    // the position of the field byte two clocks on
    later_field_position: DFF<Bits<4>>,
    // the position steps from two clocks on to three (registered from the index a clock
    // before: between frames the index is 0, whose test is index 0's)
    later_field_steps: DFF<Bit>,
    // the four bytes holding the next clock's field byte
    next_group: DFF<Bits<32>>,
    current_byte: DFF<Bits<8>>,
    // the 16 bytes in two words, most significant first
    fields_high: Signal<Local, Bits<64>>,
    fields_low: Signal<Local, Bits<64>>,
    field_word: Signal<Local, Bits<64>>,
    next_group_shifted: Signal<Local, Bits<32>>,
}

impl Default for TransmitFields {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            flags: Default::default(),
            base_tick: Default::default(),
            entry_count: Default::default(),
            advance: Default::default(),
            frame_goes_on: Default::default(),
            index: Default::default(),
            field_byte: Default::default(),
            fields_ahead: constant((FIELDS_AT - 3) as u64),
            fields_end_ahead: constant((FIELDS_AT + FIELDS_LEN - 3) as u64),
            next_sequence: Default::default(),
            next_field_position: Default::default(),
            later_field_position: Default::default(),
            later_field_steps: Default::default(),
            next_group: Default::default(),
            current_byte: Default::default(),
            fields_high: Default::default(),
            fields_low: Default::default(),
            field_word: Default::default(),
            next_group_shifted: Default::default(),
        }
    }
}

impl Logic for TransmitFields {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            next_sequence,
            next_field_position,
            later_field_position,
            later_field_steps,
            next_group,
            current_byte
        );
        // the group of the field byte two clocks on: byte 0 is the top byte of
        // `fields_high` (the descriptor is steady from index 0 on; the first group is read
        // at index 0)
        self.fields_high.next = (bit_cast::<64, 8>(self.flags.val()) << 56)
            | (bit_cast::<64, 32>(self.next_sequence.q.val()) << 24)
            | bit_cast::<64, 24>(self.base_tick.val().get_bits::<24>(40));
        self.fields_low.next = (bit_cast::<64, 40>(self.base_tick.val().get_bits::<40>(0)) << 24)
            | (bit_cast::<64, 16>(self.entry_count.val()) << 8);
        self.field_word.next = self.fields_high.val();
        if self.later_field_position.q.val().get_bit(3) {
            self.field_word.next = self.fields_low.val();
        }
        self.next_group.d.next = self.field_word.val().get_bits::<32>(32);
        if self.later_field_position.q.val().get_bit(2) {
            self.next_group.d.next = self.field_word.val().get_bits::<32>(0);
        }
        // the field byte of the next clock, from its group
        self.next_group_shifted.next = self.next_group.q.val()
            << (bit_cast::<32, 2>(self.next_field_position.q.val().get_bits::<2>(0)) << 3);
        self.current_byte.d.next = self.next_group_shifted.val().get_bits::<8>(24);
        // (two clocks on from the next clock is index + 3 while the frame goes on)
        self.later_field_steps.d.next = (self.index.val() < 15)
            | ((self.index.val() >= bit_cast::<11, 7>(self.fields_ahead.val()))
                & (self.index.val() < bit_cast::<11, 7>(self.fields_end_ahead.val())));
        // the position goes once round for the checksum (back at 0 after 16 bytes) and
        // then through the first 15 bytes to send them; 0 between frames
        self.next_field_position.d.next = 0.into();
        self.later_field_position.d.next = 0.into();
        if self.frame_goes_on.val() {
            self.next_field_position.d.next = self.later_field_position.q.val();
            self.later_field_position.d.next = self.later_field_position.q.val();
            if self.later_field_steps.q.val() {
                self.later_field_position.d.next = self.later_field_position.q.val() + 1;
            }
        }
        if self.advance.val() {
            self.next_sequence.d.next = self.next_sequence.q.val() + 1;
        }
        if self.reset.val() {
            self.next_field_position.d.next = 0.into();
            self.later_field_position.d.next = 0.into();
            self.next_sequence.d.next = 0.into();
        }
        self.field_byte.next = self.current_byte.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use crate::transmit_layout::BODY_START;
    use skinbox_protocol::datagram::field;

    /// Frames with random fields, as the transmitter runs them (index 0 to 100), the
    /// descriptor steady from index 0 to the body (index 74), noise before and after: the
    /// field bytes are the datagram header's (flags, sequence, base tick, entry count, a
    /// zero) at indices 2 to 17 for the checksum and at their own places, 57 to 71; the
    /// sequence number counts the frames that advance it.
    #[test]
    fn field_bytes_are_the_headers_at_their_indices() {
        let mut rng = TestRng::new(0xF1E);
        let mut bench = Bench::new(TransmitFields::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut sequence = 0u32;
        for round in 0..30 {
            let flags = rng.byte();
            let base_tick = rng.next_u64();
            let entry_count = rng.next_u64() as u16;
            let advance = rng.chance(0.7);
            let drive = |u: &mut TransmitFields, flags: u8, base_tick: u64, entry_count: u16| {
                u.flags.next = u64::from(flags).into();
                u.base_tick.next = base_tick.into();
                u.entry_count.next = u64::from(entry_count).into();
            };
            // the take clock: no frame yet
            drive(
                &mut bench.uut,
                rng.byte(),
                rng.next_u64(),
                rng.byte().into(),
            );
            bench.uut.index.next = 0.into();
            bench.uut.frame_goes_on.next = false;
            bench.cycle();
            let mut header = vec![flags];
            header.extend(sequence.to_be_bytes());
            header.extend(base_tick.to_be_bytes());
            header.extend(entry_count.to_be_bytes());
            header.push(0);
            assert_eq!(header.len(), field::ENTRY_COUNT.end - field::FLAGS + 1);
            let mut seen = Vec::new();
            let last = 100u64;
            for i in 0..=last {
                let u = &mut bench.uut;
                u.index.next = i.into();
                u.frame_goes_on.next = i != last;
                u.advance.next = advance && i == last;
                if i < BODY_START as u64 {
                    drive(u, flags, base_tick, entry_count);
                } else {
                    drive(u, rng.byte(), rng.next_u64(), rng.byte().into());
                }
                bench.settle();
                seen.push(bench.uut.field_byte.val().to_u64() as u8);
                bench.cycle();
            }
            bench.uut.advance.next = false;
            assert_eq!(seen[2..18], header[..], "round {round}");
            let at = FIELDS_AT;
            assert_eq!(
                seen[at..at + FIELDS_LEN],
                header[..FIELDS_LEN],
                "round {round}"
            );
            if advance {
                sequence += 1;
            }
        }
    }
}

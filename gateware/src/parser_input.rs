//! ParserInput: the frame parser's input side: each arriving beat registered with its
//! frame position, its 16-bit checksum word and where it lies (the first byte, the
//! Ethernet source), whether the frame is stored, the sender's MAC and the arrival of a
//! stored frame's last beat.
//!
//! The arriving beat's position is the next-index register itself (`index_in`, 0 between
//! frames: a frame's last beat and the reset set it back), so the listeners' decodes take
//! it straight from a register. The beat, its position, its word (even frame positions are
//! high bytes) and its flags are registered (latency 1: the `beat_*` outputs are the beat
//! that was on the input in the clock before). A frame is stored when the buffer was not
//! locked in the clock its first beat arrived. The Ethernet source (bytes 6..12) is shifted
//! into `source_mac` from the registered beats. `stored_last` says a stored frame's last
//! beat is arriving (the reply builder holds the tick of that clock). Cost: the registered
//! beat (about 40 bits), the 11-bit position and the 48-bit source.

use crate::hdl::*;
use skinbox_protocol::wire::ethernet;

/// The parser's registered beat.
#[derive(LogicBlock)]
pub struct ParserInput {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: between frames.
    pub reset: Signal<In, Bit>,
    /// A beat arrives.
    pub frame_valid: Signal<In, Bit>,
    /// It is the frame's last.
    pub frame_last: Signal<In, Bit>,
    /// The frame's FCS was wrong (with the last beat).
    pub frame_error: Signal<In, Bit>,
    /// The beat's byte.
    pub frame_data: Signal<In, Bits<8>>,
    /// The frame's length was wrong (with the last beat).
    pub length_error: Signal<In, Bit>,
    /// The buffer holds a reply: a frame starting now is not stored.
    pub buffer_locked: Signal<In, Bit>,
    /// The arriving beat's position (0 between frames).
    pub index_in: Signal<Out, Bits<11>>,
    /// The arriving beat as a 16-bit word.
    pub word_in: Signal<Out, Bits<16>>,
    /// A frame's beats are arriving (its first went by).
    pub in_frame: Signal<Out, Bit>,
    /// The frame is stored.
    pub stored: Signal<Out, Bit>,
    /// The registered beat is valid.
    pub beat_valid: Signal<Out, Bit>,
    /// It was its frame's last.
    pub beat_last: Signal<Out, Bit>,
    /// Its FCS error flag.
    pub beat_error: Signal<Out, Bit>,
    /// Its length error flag.
    pub beat_length_error: Signal<Out, Bit>,
    /// Its byte.
    pub beat_data: Signal<Out, Bits<8>>,
    /// Its frame position.
    pub beat_index: Signal<Out, Bits<11>>,
    /// It is the frame's first byte.
    pub beat_first: Signal<Out, Bit>,
    /// Its 16-bit word.
    pub beat_word: Signal<Out, Bits<16>>,
    /// The last frame's Ethernet source.
    pub source_mac: Signal<Out, Bits<48>>,
    /// The arriving beat is a stored frame's last (combinational from the inputs).
    pub stored_last: Signal<Out, Bit>,
    source_mac_at: Constant<Bits<11>>,
    ethertype_at: Constant<Bits<11>>,
    framing: DFF<Bit>,
    next_index: DFF<Bits<11>>,
    storing: DFF<Bit>,
    valid_held: DFF<Bit>,
    last_held: DFF<Bit>,
    error_held: DFF<Bit>,
    length_error_held: DFF<Bit>,
    data_held: DFF<Bits<8>>,
    index_held: DFF<Bits<11>>,
    at_first: DFF<Bit>,
    at_source: DFF<Bit>,
    word_held: DFF<Bits<16>>,
    source: DFF<Bits<48>>,
    word: Signal<Local, Bits<16>>,
}

impl Default for ParserInput {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            frame_valid: Default::default(),
            frame_last: Default::default(),
            frame_error: Default::default(),
            frame_data: Default::default(),
            length_error: Default::default(),
            buffer_locked: Default::default(),
            index_in: Default::default(),
            word_in: Default::default(),
            in_frame: Default::default(),
            stored: Default::default(),
            beat_valid: Default::default(),
            beat_last: Default::default(),
            beat_error: Default::default(),
            beat_length_error: Default::default(),
            beat_data: Default::default(),
            beat_index: Default::default(),
            beat_first: Default::default(),
            beat_word: Default::default(),
            source_mac: Default::default(),
            stored_last: Default::default(),
            source_mac_at: constant(ethernet::field::SOURCE.start as u64),
            ethertype_at: constant(ethernet::field::ETHERTYPE.start as u64),
            framing: Default::default(),
            next_index: Default::default(),
            storing: Default::default(),
            valid_held: Default::default(),
            last_held: Default::default(),
            error_held: Default::default(),
            length_error_held: Default::default(),
            data_held: Default::default(),
            index_held: Default::default(),
            at_first: Default::default(),
            at_source: Default::default(),
            word_held: Default::default(),
            source: Default::default(),
            word: Default::default(),
        }
    }
}

impl Logic for ParserInput {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            framing,
            next_index,
            storing,
            valid_held,
            last_held,
            error_held,
            length_error_held,
            data_held,
            index_held,
            at_first,
            at_source,
            word_held,
            source
        );
        self.valid_held.d.next = self.frame_valid.val();
        self.last_held.d.next = self.frame_valid.val() & self.frame_last.val();
        self.error_held.d.next = self.frame_error.val();
        self.length_error_held.d.next = self.length_error.val();
        self.data_held.d.next = self.frame_data.val();
        // the arriving beat's position: `next_index` is 0 between frames
        self.index_in.next = self.next_index.q.val();
        // position flags of the next registered beat: equality decodes only (a range
        // starts at its first byte and ends at the byte after it or at a frame's start)
        if self.frame_valid.val() {
            self.at_first.d.next = self.next_index.q.val() == 0;
            self.at_source.d.next = (self.next_index.q.val() == self.source_mac_at.val())
                | (self.at_source.q.val()
                    & (self.next_index.q.val() != self.ethertype_at.val())
                    & self.framing.q.val());
        }
        // the byte as a 16-bit word: even frame positions are high bytes
        self.word.next = bit_cast::<16, 8>(self.frame_data.val()) << 8;
        if self.next_index.q.val().get_bit(0) {
            self.word.next = bit_cast::<16, 8>(self.frame_data.val());
        }
        self.word_held.d.next = self.word.val();
        // a stored frame's last beat (only a stored frame is answered, and none is stored
        // while a reply holds the buffer)
        self.stored_last.next = self.frame_valid.val()
            & self.frame_last.val()
            & ((self.framing.q.val() & self.storing.q.val())
                | (!self.framing.q.val() & !self.buffer_locked.val()));
        if self.frame_valid.val() {
            self.index_held.d.next = self.next_index.q.val();
            self.next_index.d.next = self.next_index.q.val() + 1;
            if self.frame_last.val() {
                self.next_index.d.next = 0.into();
            }
            if !self.framing.q.val() {
                self.storing.d.next = !self.buffer_locked.val();
            }
            self.framing.d.next = !self.frame_last.val();
        }
        if self.valid_held.q.val() & self.at_source.q.val() {
            self.source.d.next =
                (self.source.q.val() << 8) | bit_cast::<48, 8>(self.data_held.q.val());
        }
        if self.reset.val() {
            self.framing.d.next = false;
            self.next_index.d.next = 0.into();
            self.valid_held.d.next = false;
            self.last_held.d.next = false;
        }
        self.word_in.next = self.word.val();
        self.in_frame.next = self.framing.q.val();
        self.stored.next = self.storing.q.val();
        self.beat_valid.next = self.valid_held.q.val();
        self.beat_last.next = self.last_held.q.val();
        self.beat_error.next = self.error_held.q.val();
        self.beat_length_error.next = self.length_error_held.q.val();
        self.beat_data.next = self.data_held.q.val();
        self.beat_index.next = self.index_held.q.val();
        self.beat_first.next = self.at_first.q.val();
        self.beat_word.next = self.word_held.q.val();
        self.source_mac.next = self.source.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Frames of random bytes with gaps, some arriving while the buffer is locked: each
    /// beat comes out a clock later with its position, word and flags; a frame is stored
    /// when the buffer was free at its first beat (`stored_last` with its last beat), and
    /// its source MAC is held.
    #[test]
    fn beats_are_registered_with_their_positions() {
        let mut rng = TestRng::new(0x1A9);
        let mut bench = Bench::new(ParserInput::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for round in 0..40 {
            let frame: Vec<u8> = (0..60 + rng.next_u64() % 40).map(|_| rng.byte()).collect();
            let locked = rng.chance(0.3);
            let mut previous: Option<(usize, u8)> = None;
            for clock in 0..frame.len() + 3 {
                let at = clock;
                let u = &mut bench.uut;
                u.frame_valid.next = at < frame.len();
                u.frame_last.next = at + 1 == frame.len();
                u.frame_data.next = u64::from(*frame.get(at).unwrap_or(&0)).into();
                u.buffer_locked.next = locked && at == 0;
                bench.settle();
                let u = &bench.uut;
                let stored_last = at + 1 == frame.len() && !locked;
                assert_eq!(u.stored_last.val(), stored_last, "round {round}");
                if at < frame.len() {
                    assert_eq!(u.index_in.val().to_u64(), at as u64, "round {round}");
                }
                assert_eq!(u.beat_valid.val(), previous.is_some(), "round {round}");
                if let Some((i, byte)) = previous {
                    assert_eq!(u.beat_index.val().to_u64(), i as u64);
                    assert_eq!(u.beat_data.val().to_u64(), u64::from(byte));
                    let word = if i % 2 == 0 {
                        u64::from(byte) << 8
                    } else {
                        u64::from(byte)
                    };
                    assert_eq!(u.beat_word.val().to_u64(), word, "round {round} byte {i}");
                    assert_eq!(u.beat_first.val(), i == 0);
                    assert_eq!(u.beat_last.val(), i + 1 == frame.len());
                    assert_eq!(u.stored.val(), !locked, "round {round}");
                }
                previous = frame.get(at).map(|&b| (at, b));
                bench.cycle();
            }
            let u = &bench.uut;
            assert_eq!(u.source_mac.val().to_u64(), big_endian(&frame[6..12]));
            assert!(!u.in_frame.val());
        }
    }
}

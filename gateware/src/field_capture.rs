//! FieldCapture: the bytes of one frame field, taken from a byte stream by their position.
//!
//! A receive layer instantiates one per field it uses, from the field's byte range in a
//! `protocol` layout table ([`FieldCapture::of`]), so a frame position is written once, in
//! `protocol`. The capture listens to a frame's beats twice: the incoming beat (valid this
//! clock, with its frame position `next_index`, 0 outside a frame) sets or clears the
//! "in the field" flag by equality decodes of the position only (set at the field's first
//! byte; cleared at the byte after its last or at a new frame), and the registered beat one
//! clock later shifts into the value while that flag is set. So `value` holds the field's
//! bytes big-endian (the last captured byte is the low byte) from the clock after the
//! field's last byte was registered until the next frame reaches the field. A frame that
//! ends inside the field leaves the bytes it had shifted in.

use crate::hdl::*;
use crate::stream::FrameBeats;
use skinbox_protocol::Field;

/// One frame field of `W / 8` bytes captured by position; see the module documentation.
#[derive(LogicBlock)]
pub struct FieldCapture<const W: usize> {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The field's bytes, big-endian.
    pub value: Signal<Out, Bits<W>>,
    first_at: Constant<Bits<11>>,
    end_at: Constant<Bits<11>>,
    in_field: DFF<Bit>,
    bytes: DFF<Bits<W>>,
}

impl<const W: usize> FieldCapture<W> {
    /// The capture of frame bytes `field` (`W / 8` of them).
    pub fn of(field: Field) -> Self {
        assert!(
            field.len() * 8 == W && field.end < 1 << 11,
            "field {field:?} does not fill {W} bits"
        );
        Self {
            clock: Default::default(),
            beats: Default::default(),
            value: Default::default(),
            first_at: constant(field.start as u64),
            end_at: constant(field.end as u64),
            in_field: Default::default(),
            bytes: Default::default(),
        }
    }
}

impl<const W: usize> Logic for FieldCapture<W> {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, in_field, bytes);
        if self.beats.next_valid.val() {
            self.in_field.d.next = (self.beats.next_index.val() == self.first_at.val())
                | (self.in_field.q.val()
                    & (self.beats.next_index.val() != self.end_at.val())
                    & self.beats.in_frame.val());
        }
        if self.beats.beat_valid.val() & self.in_field.q.val() {
            self.bytes.d.next =
                (self.bytes.q.val() << 8) | bit_cast::<W, 8>(self.beats.beat_data.val());
        }
        self.value.next = self.bytes.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{send_frame_beats, Bench, TestRng};

    /// Random frames of random lengths (some ending inside the field), beats with random
    /// idle clocks between them: after each frame the capture holds the field's bytes as
    /// far as the frame reached them, shifted in after whatever the previous frame left.
    #[test]
    fn captures_the_fields_bytes_of_every_frame() {
        const FIELD: Field = 5..9;
        let mut rng = TestRng::new(11);
        let mut bench = Bench::new(FieldCapture::<32>::of(FIELD), |b| &mut b.clock);
        let mut expected = 0u32;
        for case in 0..200 {
            let len = 1 + rng.next_u64() as usize % 14;
            let frame: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
            send_frame_beats(
                &mut bench,
                &mut rng,
                &frame,
                0.3,
                |u| &mut u.beats,
                |_, _| {},
            );
            for &b in frame.iter().take(FIELD.end).skip(FIELD.start) {
                expected = expected << 8 | u32::from(b);
            }
            assert_eq!(
                bench.uut.value.val().to_u64(),
                u64::from(expected),
                "case {case}"
            );
        }
    }

    #[test]
    #[should_panic(expected = "does not fill 16 bits")]
    fn a_field_of_another_width_is_refused() {
        let _ = FieldCapture::<16>::of(0..3);
    }
}

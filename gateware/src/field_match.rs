//! FieldMatch: whether the bytes of one frame field equal constant bytes, compared as they
//! pass, with no capture of the field.
//!
//! The field's position comes from a `protocol` layout table ([`FieldMatch::of`]), as a
//! [`crate::field_capture::FieldCapture`]'s does, and the field is at most 8 bytes: the
//! low three bits of a byte's frame position tell which of the field's bytes it is, and
//! choose the expected byte from a table of eight (one LUT4 a bit). The incoming beat sets
//! or clears the "in the field" flag and registers those three bits; the registered beat,
//! while the flag is set, is compared with its expected byte and clears `equals` when it
//! differs. `equals` is set again at a frame's first byte (for a field from position 0:
//! set to that byte's comparison), so after the field's last byte was registered it says
//! whether the frame's field equals the constant; a frame that ends inside the field leaves the result
//! of the bytes it had. Cost: 6 flip-flops, against 8 a byte for a capture.

use crate::hdl::*;
use crate::stream::FrameBeats;
use skinbox_protocol::Field;

/// A frame field compared with constant bytes; see the module documentation.
#[derive(LogicBlock)]
pub struct FieldMatch {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The field's bytes so far equal the constant's.
    pub equals: Signal<Out, Bit>,
    first_at: Constant<Bits<11>>,
    end_at: Constant<Bits<11>>,
    // the expected byte of frame positions 0 to 7 mod 8, 64 bits, position 0 lowest
    expected: Constant<Bits<64>>,
    in_field: DFF<Bit>,
    at_first: DFF<Bit>,
    // the registered beat's byte in `expected`: its position mod 8, times 8
    position: DFF<Bits<6>>,
    equal: DFF<Bit>,
}

impl FieldMatch {
    /// The match of frame bytes `field` with `bytes` (as many as the field has, at most 8).
    pub fn of(field: Field, bytes: &[u8]) -> Self {
        assert!(
            field.len() == bytes.len() && (1..=8).contains(&bytes.len()),
            "field {field:?} cannot be matched with {bytes:?}"
        );
        assert!(field.end < 1 << 11, "field {field:?} lies past 2047");
        let mut expected = 0u64;
        for (i, &b) in bytes.iter().enumerate() {
            expected |= u64::from(b) << (8 * ((field.start + i) % 8));
        }
        Self {
            clock: Default::default(),
            beats: Default::default(),
            equals: Default::default(),
            first_at: constant(field.start as u64),
            end_at: constant(field.end as u64),
            expected: Constant::new(expected.into()),
            in_field: Default::default(),
            at_first: Default::default(),
            position: Default::default(),
            equal: Default::default(),
        }
    }
}

impl Logic for FieldMatch {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, in_field, at_first, position, equal);
        if self.beats.next_valid.val() {
            self.in_field.d.next = (self.beats.next_index.val() == self.first_at.val())
                | (self.in_field.q.val()
                    & (self.beats.next_index.val() != self.end_at.val())
                    & self.beats.in_frame.val());
            self.at_first.d.next = !self.beats.in_frame.val();
            self.position.d.next =
                bit_cast::<6, 3>(self.beats.next_index.val().get_bits::<3>(0)) << 3;
        }
        // (a frame's first byte sets it, unless the field starts there and the byte differs)
        if self.beats.beat_valid.val() & self.at_first.q.val() {
            self.equal.d.next = true;
        }
        if self.beats.beat_valid.val()
            & self.in_field.q.val()
            & (self.beats.beat_data.val()
                != self
                    .expected
                    .val()
                    .get_bits::<8>(self.position.q.val().index()))
        {
            self.equal.d.next = false;
        }
        self.equals.next = self.equal.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{send_frame_beats, Bench, TestRng};

    /// Random frames whose field is the constant, or differs in one byte, or is cut short,
    /// with idle clocks between beats: `equals` is the comparison of the bytes the frame
    /// holds of the field.
    #[test]
    fn matches_exactly_the_frames_whose_field_is_the_constant() {
        for (field, bytes) in [
            (14..22, &[0u8, 1, 8, 0, 6, 4, 0, 1][..]),
            (43..46, &[0xAB, 0, 0x5C]),
            (0..6, &[0x02, 0x11, 0x22, 0x33, 0x44, 0x55]),
        ] {
            let mut rng = TestRng::new(23);
            let mut bench = Bench::new(FieldMatch::of(field.clone(), bytes), |m| &mut m.clock);
            let (mut equal, mut differ) = (0, 0);
            for case in 0..300 {
                let mut frame: Vec<u8> = (0..field.end + 6).map(|_| rng.next_u64() as u8).collect();
                frame[field.clone()].copy_from_slice(bytes);
                match rng.next_u64() % 3 {
                    0 => {
                        frame[field.start + rng.next_u64() as usize % bytes.len()] ^=
                            1 << (rng.next_u64() % 8)
                    }
                    1 => frame.truncate(
                        (field.start + rng.next_u64() as usize % (bytes.len() + 1)).max(1),
                    ),
                    _ => {}
                }
                send_frame_beats(
                    &mut bench,
                    &mut rng,
                    &frame,
                    0.2,
                    |u| &mut u.beats,
                    |_, _| {},
                );
                let held = &frame[field.start.min(frame.len())..field.end.min(frame.len())];
                let expected = held == &bytes[..held.len()];
                assert_eq!(bench.uut.equals.val(), expected, "case {case}: {frame:?}");
                if expected && held.len() == bytes.len() {
                    equal += 1;
                } else if !expected {
                    differ += 1;
                }
            }
            assert!(
                equal > 50 && differ > 50,
                "{equal} equal, {differ} differing"
            );
        }
    }
}

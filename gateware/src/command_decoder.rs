//! CommandDecoder: the command layer of the receive path. It takes the box command header
//! (docs/wire-format.md) and the first [`HELD_ARGUMENT_BYTES`] argument bytes out of a
//! received UDP payload by their frame positions, and checks the header's form for the
//! frame parser's step 16 (`RefusedMalformed`).
//!
//! It listens to the parser's beats (each beat as it arrives with its frame position, and
//! one clock later registered): one [`FieldCapture`] per header field it passes on (box id,
//! opcode, sequence number, argument length), one [`FieldMatch`] per field it only
//! compares with constants (start, flags, reserved), one slot register per
//! argument byte (cleared at the header's last byte; bytes after the IPv4 packet's end are
//! taken as 0, as are bytes a short frame never reached). The argument length is compared
//! with the one the IPv4 payload length leaves (`payload_length`, which the IPv4 layer
//! holds, less the UDP and command headers) when the checks are registered.
//!
//! In the clock after a frame's last beat was registered the checks are registered (the
//! parser's stage 1): `well_formed` is high when the header starts with the command magic,
//! version and kind, its flags and reserved bytes are 0, and its argument length is the
//! one the IPv4 payload leaves. The fields hold the frame's values from then until the
//! next frame's beats reach them (its byte 42 on, at least 42 clocks after its first
//! beat): the command unit reads them from its `command` to its `done`.

use crate::field_capture::FieldCapture;
use crate::field_match::FieldMatch;
use crate::hdl::*;
use crate::stream::FrameBeats;
use skinbox_protocol::command::ARGUMENTS_AT;
use skinbox_protocol::command::{self, field, HEADER_LEN, KIND_COMMAND};
use skinbox_protocol::datagram::{MAGIC, VERSION};
use skinbox_protocol::link::{PAYLOAD_AT, UDP_HEADER_LEN};
use skinbox_protocol::Field;

/// Argument bytes taken from a command (the longest arguments the box accepts).
pub const HELD_ARGUMENT_BYTES: usize = 12;

/// The frame bytes of the command header's field `f`.
const fn in_frame(f: Field) -> Field {
    PAYLOAD_AT + f.start..PAYLOAD_AT + f.end
}

/// The frame byte of the command header's byte `at`.
const fn byte_in_frame(at: usize) -> Field {
    in_frame(at..at + 1)
}

/// The command start: magic, version and kind.
const START: Field = in_frame(field::MAGIC.start..field::KIND + 1);
const _: () = assert!(field::MAGIC.end == field::VERSION && field::VERSION + 1 == field::KIND);

/// The command layer of the receive path; see the module documentation.
#[derive(LogicBlock)]
pub struct CommandDecoder {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The registered beat is a frame's first.
    pub beat_first: Signal<In, Bit>,
    /// The registered beat (from byte 34 on) lies inside the IPv4 packet.
    pub beat_in_packet: Signal<In, Bit>,
    /// The IPv4 payload length, from frame position `PAYLOAD_LENGTH_KNOWN_AT` on.
    pub payload_length: Signal<In, Bits<16>>,
    /// The header is a well-formed command's (registered a clock after the last beat).
    pub well_formed: Signal<Out, Bit>,
    /// The command's box id.
    pub box_id: Signal<Out, Bits<16>>,
    /// Its opcode.
    pub opcode: Signal<Out, Bits<8>>,
    /// Its sequence number.
    pub sequence_number: Signal<Out, Bits<32>>,
    /// Its argument length.
    pub argument_length: Signal<Out, Bits<16>>,
    /// Its first [`HELD_ARGUMENT_BYTES`] argument bytes, the first in the high byte.
    pub arguments: Signal<Out, Bits<96>>,
    start: FieldMatch,
    box_id_field: FieldCapture<16>,
    opcode_field: FieldCapture<8>,
    flags: FieldMatch,
    sequence_field: FieldCapture<32>,
    length_field: FieldCapture<16>,
    reserved: FieldMatch,
    header_last_at: Constant<Bits<11>>,
    udp_and_command_header_len: Constant<Bits<16>>,
    // the argument slots: slot k takes the byte in the clock its bit 11 - k is set
    at_header_last: DFF<Bit>,
    argument_slot: DFF<Bits<12>>,
    argument_byte: Signal<Local, Bits<8>>,
    argument_0: DFF<Bits<8>>,
    argument_1: DFF<Bits<8>>,
    argument_2: DFF<Bits<8>>,
    argument_3: DFF<Bits<8>>,
    argument_4: DFF<Bits<8>>,
    argument_5: DFF<Bits<8>>,
    argument_6: DFF<Bits<8>>,
    argument_7: DFF<Bits<8>>,
    argument_8: DFF<Bits<8>>,
    argument_9: DFF<Bits<8>>,
    argument_10: DFF<Bits<8>>,
    argument_11: DFF<Bits<8>>,
    // the checks, registered
    start_ok: DFF<Bit>,
    zeros_ok: DFF<Bit>,
    length_ok: DFF<Bit>,
    // the argument length the IPv4 payload leaves, registered a clock before its compare
    // (the payload length is steady from the IPv4 header on)
    arguments_left: DFF<Bits<16>>,
}

impl Default for CommandDecoder {
    fn default() -> Self {
        let command_start = [MAGIC[0], MAGIC[1], VERSION, KIND_COMMAND];
        Self {
            clock: Default::default(),
            beats: Default::default(),
            beat_first: Default::default(),
            beat_in_packet: Default::default(),
            payload_length: Default::default(),
            well_formed: Default::default(),
            box_id: Default::default(),
            opcode: Default::default(),
            sequence_number: Default::default(),
            argument_length: Default::default(),
            arguments: Default::default(),
            start: FieldMatch::of(START, &command_start),
            box_id_field: FieldCapture::of(in_frame(field::BOX_ID)),
            opcode_field: FieldCapture::of(byte_in_frame(field::OPCODE)),
            flags: FieldMatch::of(byte_in_frame(field::FLAGS), &[0]),
            sequence_field: FieldCapture::of(in_frame(field::SEQUENCE)),
            length_field: FieldCapture::of(in_frame(field::LENGTH)),
            reserved: FieldMatch::of(in_frame(field::RESERVED), &[0, 0]),
            header_last_at: constant(ARGUMENTS_AT as u64 - 1),
            udp_and_command_header_len: constant((UDP_HEADER_LEN + HEADER_LEN) as u64),
            at_header_last: Default::default(),
            argument_slot: Default::default(),
            argument_byte: Default::default(),
            argument_0: Default::default(),
            argument_1: Default::default(),
            argument_2: Default::default(),
            argument_3: Default::default(),
            argument_4: Default::default(),
            argument_5: Default::default(),
            argument_6: Default::default(),
            argument_7: Default::default(),
            argument_8: Default::default(),
            argument_9: Default::default(),
            argument_10: Default::default(),
            argument_11: Default::default(),
            start_ok: Default::default(),
            zeros_ok: Default::default(),
            length_ok: Default::default(),
            arguments_left: Default::default(),
        }
    }
}

const _: () = assert!(HELD_ARGUMENT_BYTES == 12 && command::HEADER_LEN == 24);

impl Logic for CommandDecoder {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            at_header_last,
            argument_slot,
            argument_0,
            argument_1,
            argument_2,
            argument_3,
            argument_4,
            argument_5,
            argument_6,
            argument_7,
            argument_8,
            argument_9,
            argument_10,
            argument_11,
            start_ok,
            zeros_ok,
            length_ok,
            arguments_left
        );
        // the captures
        self.start.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.start.beats);
        self.box_id_field.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.box_id_field.beats);
        self.opcode_field.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.opcode_field.beats);
        self.flags.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.flags.beats);
        self.sequence_field.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.sequence_field.beats);
        self.length_field.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.length_field.beats);
        self.reserved.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.reserved.beats);

        // the argument bytes: one slot per byte after the header, inside the IPv4 packet
        if self.beats.next_valid.val() {
            self.at_header_last.d.next = self.beats.next_index.val() == self.header_last_at.val();
        }
        self.argument_byte.next = 0.into();
        if self.beat_in_packet.val() {
            self.argument_byte.next = self.beats.beat_data.val();
        }
        // (a frame's first beat only stops the slots a short frame left running: the bytes
        // change no earlier than the next command header's end)
        if self.beats.beat_valid.val() & self.beat_first.val() {
            self.argument_slot.d.next = 0.into();
        }
        if self.beats.beat_valid.val() & !self.beat_first.val() {
            self.argument_slot.d.next = self.argument_slot.q.val() >> 1;
            if self.argument_slot.q.val().get_bit(11) {
                self.argument_0.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(10) {
                self.argument_1.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(9) {
                self.argument_2.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(8) {
                self.argument_3.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(7) {
                self.argument_4.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(6) {
                self.argument_5.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(5) {
                self.argument_6.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(4) {
                self.argument_7.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(3) {
                self.argument_8.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(2) {
                self.argument_9.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(1) {
                self.argument_10.d.next = self.argument_byte.val();
            }
            if self.argument_slot.q.val().get_bit(0) {
                self.argument_11.d.next = self.argument_byte.val();
            }
            if self.at_header_last.q.val() {
                // the header's last byte: the slots start, the bytes of the last command go
                self.argument_slot.d.next = 0x800.into();
                self.argument_0.d.next = 0.into();
                self.argument_1.d.next = 0.into();
                self.argument_2.d.next = 0.into();
                self.argument_3.d.next = 0.into();
                self.argument_4.d.next = 0.into();
                self.argument_5.d.next = 0.into();
                self.argument_6.d.next = 0.into();
                self.argument_7.d.next = 0.into();
                self.argument_8.d.next = 0.into();
                self.argument_9.d.next = 0.into();
                self.argument_10.d.next = 0.into();
                self.argument_11.d.next = 0.into();
            }
        }

        // the checks (registered every clock; read a clock after the last beat)
        self.start_ok.d.next = self.start.equals.val();
        self.zeros_ok.d.next = self.flags.equals.val() & self.reserved.equals.val();
        self.arguments_left.d.next =
            self.payload_length.val() - self.udp_and_command_header_len.val();
        self.length_ok.d.next = self.length_field.value.val() == self.arguments_left.q.val();
        self.well_formed.next =
            self.start_ok.q.val() & self.zeros_ok.q.val() & self.length_ok.q.val();

        self.box_id.next = self.box_id_field.value.val();
        self.opcode.next = self.opcode_field.value.val();
        self.sequence_number.next = self.sequence_field.value.val();
        self.argument_length.next = self.length_field.value.val();
        self.arguments.next = (bit_cast::<96, 8>(self.argument_0.q.val()) << 88)
            | (bit_cast::<96, 8>(self.argument_1.q.val()) << 80)
            | (bit_cast::<96, 8>(self.argument_2.q.val()) << 72)
            | (bit_cast::<96, 8>(self.argument_3.q.val()) << 64)
            | (bit_cast::<96, 8>(self.argument_4.q.val()) << 56)
            | (bit_cast::<96, 8>(self.argument_5.q.val()) << 48)
            | (bit_cast::<96, 8>(self.argument_6.q.val()) << 40)
            | (bit_cast::<96, 8>(self.argument_7.q.val()) << 32)
            | (bit_cast::<96, 8>(self.argument_8.q.val()) << 24)
            | (bit_cast::<96, 8>(self.argument_9.q.val()) << 16)
            | (bit_cast::<96, 8>(self.argument_10.q.val()) << 8)
            | bit_cast::<96, 8>(self.argument_11.q.val());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{send_frame_beats, Bench, TestRng};
    use skinbox_protocol::command::{Command, CommandRepr, Request};
    use skinbox_protocol::link::{IPV4_AT, IPV4_HEADER_LEN};
    use skinbox_protocol::wire::ipv4;

    /// Random command frames, good and with a header byte, the argument length or the IPv4
    /// length changed: `well_formed` is the protocol's `Command::new_checked` of the UDP
    /// payload, and the fields and argument bytes are the frame's (0 past the packet).
    #[test]
    fn fields_and_form_match_the_protocols_command_view() {
        let mut rng = TestRng::new(29);
        let mut bench = Bench::new(CommandDecoder::default(), |d| &mut d.clock);
        let (mut good, mut bad) = (0, 0);
        for case in 0..400 {
            let arguments = rng.next_u64() as usize % 17;
            let mut payload = CommandRepr {
                box_id: rng.next_u64() as u16,
                sequence: rng.next_u64() as u32,
                host_time: rng.next_u64(),
                request: Request::StatusNow,
            }
            .to_bytes();
            payload.extend((0..arguments).map(|_| rng.next_u64() as u8));
            payload[field::LENGTH].copy_from_slice(&(arguments as u16).to_be_bytes());
            match rng.next_u64() % 4 {
                0 => payload[rng.next_u64() as usize % HEADER_LEN] ^= 1 << (rng.next_u64() % 8),
                1 => payload[field::LENGTH.end - 1] ^= 1 << (rng.next_u64() % 3),
                _ => {}
            }
            let mut total = IPV4_HEADER_LEN + UDP_HEADER_LEN + payload.len();
            if rng.chance(0.15) {
                total = total - 3 + rng.next_u64() as usize % 7;
            }
            let mut frame = vec![0u8; PAYLOAD_AT];
            frame[IPV4_AT + ipv4::field::TOTAL_LEN.start..IPV4_AT + ipv4::field::TOTAL_LEN.end]
                .copy_from_slice(&(total as u16).to_be_bytes());
            frame.extend(&payload);
            frame.extend((0..4 + rng.next_u64() % 8).map(|_| rng.next_u64() as u8));
            let packet_end = IPV4_AT + total;
            bench.uut.payload_length.next = ((total - IPV4_HEADER_LEN) as u64).into();
            send_frame_beats(
                &mut bench,
                &mut rng,
                &frame,
                0.2,
                |u| &mut u.beats,
                |u, r| {
                    u.beat_first.next = r == Some(0);
                    u.beat_in_packet.next = r.is_some_and(|i| (34..packet_end).contains(&i));
                },
            );

            let udp_payload = &frame[PAYLOAD_AT..packet_end.min(frame.len())];
            let expected = Command::new_checked(udp_payload).is_ok();
            let u = &bench.uut;
            assert_eq!(u.well_formed.val(), expected, "case {case}");
            if expected {
                good += 1;
            } else {
                bad += 1;
            }
            let at = |f: Field| {
                frame[in_frame(f)]
                    .iter()
                    .fold(0u64, |v, &b| v << 8 | u64::from(b))
            };
            assert_eq!(u.box_id.val().to_u64(), at(field::BOX_ID), "case {case}");
            assert_eq!(
                u.opcode.val().to_u64(),
                u64::from(frame[PAYLOAD_AT + field::OPCODE])
            );
            assert_eq!(
                u.sequence_number.val().to_u64(),
                at(field::SEQUENCE),
                "case {case}"
            );
            assert_eq!(
                u.argument_length.val().to_u64(),
                at(field::LENGTH),
                "case {case}"
            );
            let mut held = [0u8; HELD_ARGUMENT_BYTES];
            for (k, h) in held.iter_mut().enumerate() {
                let i = ARGUMENTS_AT + k;
                if i < packet_end && i < frame.len() {
                    *h = frame[i];
                }
            }
            let args = u.arguments.val();
            let seen: Vec<u8> = (0..HELD_ARGUMENT_BYTES)
                .map(|k| args.get_bits::<8>(88 - 8 * k).to_u8())
                .collect();
            assert_eq!(seen, held, "case {case}: arguments");
        }
        assert!(good > 100 && bad > 100, "{good} good and {bad} bad cases");
    }
}

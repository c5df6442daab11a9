//! FrameParser: checks every received frame against the rules of docs/control.md (steps 1
//! to 16) on the fly, one beat per clock, and writes it into the reply frame buffer.
//!
//! The frame arrives from the MAC receiver (destination MAC to FCS; `error` and
//! `length_error` with the last beat). Each beat is registered first, with flags saying
//! where it lies in the frame (set and cleared by equality decodes of the beat index, so no
//! range compare sits in front of the per-beat logic) and its 16-bit checksum word. The
//! registered beat (index `i` from 0) is written into the frame buffer at address `i` one
//! clock after it was on `frame` when the frame is STORED (`buffer_locked` was low in the
//! clock its first beat was on `frame`), and feeds:
//!
//! - the layers that listen to the same beats ([`crate::stream::FrameBeats`]): the
//!   Ethernet layer ([`EthernetDemux`]: destination MAC and EtherType, steps 3-5), the ARP
//!   layer ([`ArpReceiver`]: a request for the box's address, step 4), the IPv4 layer
//!   ([`Ipv4Receiver`]: version, header checksum, total length, fragments, destination,
//!   protocol and the sender's subnet, steps 6-10 and 15, and the payload's extent) and
//!   the command layer ([`CommandDecoder`]: the command header's fields, the first
//!   argument bytes and the header's form for step 16);
//! - the sender's MAC (Ethernet source, for the command unit) captured (the transport
//!   layer captures the UDP source port and compares the rest of its header as it passes);
//! - two ones'-complement sums, one byte per clock with an end-around carry: the transport
//!   message (ICMP, or UDP with its pseudo header) and the ICMP message from its byte 4
//!   (the echo reply's checksum is its complement). They stop at the IPv4 payload's end
//!   (the IPv4 layer's `in_payload`): later bytes are Ethernet padding or the FCS, and a
//!   packet longer than the frame is found by whether the first FCS byte was still inside.
//!
//! After the last beat the captured fields are compared with the build-time constants (one
//! clock), and the rule table ([`ReceiveRules`]) applies the checks in the model's order
//! and drives `decided` for one clock with `action` (`receive_rules::ACTION_*`) and
//! `fate`, exactly [`DECISION_LATENCY`] clocks after the last beat was on `frame`. A frame
//! that passed steps 1-16 but was not stored gets action NONE and fate `ReplyBusy`.
//!
//! The outputs for the reply builder and the command unit are the captures themselves,
//! with no second copy: they show the last frame's fields from the clock before `decided`
//! until the next frame reaches them. The command unit's (`peer_*`, `command_*`) hold until
//! the next frame's byte 6 is registered (at least [`DECISION_LATENCY`] + 7 clocks after
//! the last beat), which covers the command unit's `command` to `done`;
//! `ip_total_length` until its byte 16, `icmp_rest_sum` until the clock after its first
//! beat was registered (at least [`DECISION_LATENCY`] + 2 clocks after the last beat),
//! which covers the reply builder's reads after `start_echo`
//! ([`crate::reply_builder::echo_fields_read`]). The reply builder holds the receive tick
//! itself: `receive_tick_now` says a stored frame's last beat is on `frame`.
//!
//! Frames must be at least [`DECISION_LATENCY`] clocks apart (last beat to next first beat),
//! and [`DECISION_LATENCY`] + [`crate::reply_builder::echo_fields_read`] - 1 for the echo
//! reply's ICMP sum (the MAC's are at least 20: preamble, SFD and the inter-frame gap).
//! `ready` is always high.

use crate::arp_receiver::ArpReceiver;
use crate::command_decoder::CommandDecoder;
use crate::ethernet_demux::EthernetDemux;
use crate::frame_end_checks::FrameEndChecks;
use crate::hdl::*;
use crate::ipv4_receiver::Ipv4Receiver;
use crate::parser_input::ParserInput;
use crate::receive_rules::{ReceiveRules, RULES_LATENCY};
use crate::stream::ByteStreamSink;
use crate::transport_receiver::TransportReceiver;
use skinbox_protocol::link::{LinkConfig, ARP_AT, IPV4_AT, MIN_FRAME_LEN};
use skinbox_protocol::wire::{arp, ethernet};

/// Clocks from the last beat on `frame` (clock `c`) to `decided` (high in clock `c +
/// DECISION_LATENCY`).
pub const DECISION_LATENCY: u64 = 3 + RULES_LATENCY;

// one decode ends a capture and starts the next where the fields are adjacent
const _: () = assert!(ethernet::field::ETHERTYPE.end == IPV4_AT && IPV4_AT == ARP_AT);
// the ARP body ends inside the 60 bytes every frame has
const _: () = assert!(ARP_AT + arp::PACKET_LEN <= MIN_FRAME_LEN);

/// Checks received frames (steps 1-16 of docs/control.md) and writes them into the frame
/// buffer; see the module documentation.
#[derive(LogicBlock)]
pub struct FrameParser {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: forgets the frame in progress and the decisions in flight.
    pub reset: Signal<In, Bit>,
    /// The received frame from the MAC (`ready` is always high).
    pub frame: ByteStreamSink,
    /// With the last beat: the frame's length was outside 64..=1518 bytes.
    pub length_error: Signal<In, Bit>,
    /// The frame buffer holds a reply: a frame whose first beat comes now is not written.
    pub buffer_locked: Signal<In, Bit>,
    /// Write a stored frame's byte into the frame buffer.
    pub buffer_write_enable: Signal<Out, Bit>,
    /// Its address: the beat index from 0 (one clock after the beat was on `frame`).
    pub buffer_write_address: Signal<Out, Bits<11>>,
    /// Its byte.
    pub buffer_write_data: Signal<Out, Bits<8>>,
    /// One clock, [`DECISION_LATENCY`] clocks after each frame's last beat.
    pub decided: Signal<Out, Bit>,
    /// With `decided`: `ACTION_*`.
    pub action: Signal<Out, Bits<2>>,
    /// With `decided`: the frame's `BoxCounter` index (0 for `ACTION_COMMAND`: the command
    /// unit decides).
    pub fate: Signal<Out, Bits<5>>,
    /// ARP: the sender hardware address; else the Ethernet source.
    pub peer_mac: Signal<Out, Bits<48>>,
    /// ARP: the sender protocol address; else the IPv4 source.
    pub peer_ip: Signal<Out, Bits<32>>,
    /// The UDP source port.
    pub peer_port: Signal<Out, Bits<16>>,
    /// A stored frame's last beat is on `frame` (combinational from `frame` and
    /// `buffer_locked`): the box tick of this clock is its receive tick.
    pub receive_tick_now: Signal<Out, Bit>,
    /// The IPv4 total length.
    pub ip_total_length: Signal<Out, Bits<16>>,
    /// Folded ones'-complement sum of the ICMP message from its byte 4 (odd length padded).
    pub icmp_rest_sum: Signal<Out, Bits<16>>,
    /// Command box id.
    pub command_box_id: Signal<Out, Bits<16>>,
    /// Command opcode.
    pub command_opcode: Signal<Out, Bits<8>>,
    /// Command sequence number.
    pub command_sequence: Signal<Out, Bits<32>>,
    /// Command argument length.
    pub command_argument_length: Signal<Out, Bits<16>>,
    /// The first 12 argument bytes, the first in bits 95..88; bytes past the arguments 0.
    pub command_arguments: Signal<Out, Bits<96>>,

    // the registered beat, its position and flags, the stored flag and the sender's MAC
    beats_in: ParserInput,
    // the layers, and the IPv4 header's fields
    ethernet: EthernetDemux,
    arp: ArpReceiver,
    ipv4: Ipv4Receiver,
    transport: TransportReceiver,
    command: CommandDecoder,
    // the rule table
    rules: ReceiveRules,
    // the checks of the frame's end, staged for the rule table
    end_checks: FrameEndChecks,
}

impl FrameParser {
    /// A parser for the box at `link`'s MAC, IP and port, taking commands from its host
    /// subnet.
    pub fn new(link: &LinkConfig) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            frame: Default::default(),
            length_error: Default::default(),
            buffer_locked: Default::default(),
            buffer_write_enable: Default::default(),
            buffer_write_address: Default::default(),
            buffer_write_data: Default::default(),
            decided: Default::default(),
            action: Default::default(),
            fate: Default::default(),
            peer_mac: Default::default(),
            peer_ip: Default::default(),
            peer_port: Default::default(),
            receive_tick_now: Default::default(),
            ip_total_length: Default::default(),
            icmp_rest_sum: Default::default(),
            command_box_id: Default::default(),
            command_opcode: Default::default(),
            command_sequence: Default::default(),
            command_argument_length: Default::default(),
            command_arguments: Default::default(),
            beats_in: Default::default(),
            ethernet: EthernetDemux::new(link.box_mac),
            arp: ArpReceiver::new(link.box_ip),
            ipv4: Ipv4Receiver::new(link.box_ip, link.host_subnet, link.host_subnet_prefix_len),
            transport: TransportReceiver::new(link.box_port),
            command: Default::default(),
            rules: Default::default(),
            end_checks: Default::default(),
        }
    }
}

impl Default for FrameParser {
    fn default() -> Self {
        Self::new(&LinkConfig::DEFAULT)
    }
}

impl Logic for FrameParser {
    #[hdl_gen]
    fn update(&mut self) {
        self.frame.ready.next = true;

        // ---- input side: the beat registered with its position, the lock sampled at the
        // first beat ----
        self.beats_in.clock.next = self.clock.val();
        self.beats_in.reset.next = self.reset.val();
        self.beats_in.frame_valid.next = self.frame.valid.val();
        self.beats_in.frame_last.next = self.frame.last.val();
        self.beats_in.frame_error.next = self.frame.error.val();
        self.beats_in.frame_data.next = self.frame.data.val();
        self.beats_in.length_error.next = self.length_error.val();
        self.beats_in.buffer_locked.next = self.buffer_locked.val();

        // ---- the registered beat: buffer write ----
        self.buffer_write_enable.next = self.beats_in.beat_valid.val() & self.beats_in.stored.val();
        self.buffer_write_address.next = self.beats_in.beat_index.val();
        self.buffer_write_data.next = self.beats_in.beat_data.val();

        // ---- captures by byte position ----
        // the layers listen to the beats
        self.ethernet.clock.next = self.clock.val();
        self.ethernet.beats.next_valid.next = self.frame.valid.val();
        self.ethernet.beats.next_index.next = self.beats_in.index_in.val();
        self.ethernet.beats.in_frame.next = self.beats_in.in_frame.val();
        self.ethernet.beats.beat_valid.next = self.beats_in.beat_valid.val();
        self.ethernet.beats.beat_data.next = self.beats_in.beat_data.val();
        self.ethernet.beat_first.next = self.beats_in.beat_first.val();
        self.arp.clock.next = self.clock.val();
        self.arp.beats.next_valid.next = self.frame.valid.val();
        self.arp.beats.next_index.next = self.beats_in.index_in.val();
        self.arp.beats.in_frame.next = self.beats_in.in_frame.val();
        self.arp.beats.beat_valid.next = self.beats_in.beat_valid.val();
        self.arp.beats.beat_data.next = self.beats_in.beat_data.val();
        self.ipv4.clock.next = self.clock.val();
        self.ipv4.beats.next_valid.next = self.frame.valid.val();
        self.ipv4.beats.next_index.next = self.beats_in.index_in.val();
        self.ipv4.beats.in_frame.next = self.beats_in.in_frame.val();
        self.ipv4.beats.beat_valid.next = self.beats_in.beat_valid.val();
        self.ipv4.beats.beat_data.next = self.beats_in.beat_data.val();
        self.ipv4.beat_first.next = self.beats_in.beat_first.val();
        self.ipv4.beat_word.next = self.beats_in.beat_word.val();
        self.command.clock.next = self.clock.val();
        self.command.beats.next_valid.next = self.frame.valid.val();
        self.command.beats.next_index.next = self.beats_in.index_in.val();
        self.command.beats.in_frame.next = self.beats_in.in_frame.val();
        self.command.beats.beat_valid.next = self.beats_in.beat_valid.val();
        self.command.beats.beat_data.next = self.beats_in.beat_data.val();
        self.command.beat_first.next = self.beats_in.beat_first.val();
        self.command.beat_in_packet.next = self.ipv4.in_payload.val();
        self.command.payload_length.next = self.ipv4.payload_length.val();
        self.transport.clock.next = self.clock.val();
        self.transport.beats.next_valid.next = self.frame.valid.val();
        self.transport.beats.next_index.next = self.beats_in.index_in.val();
        self.transport.beats.in_frame.next = self.beats_in.in_frame.val();
        self.transport.beats.beat_valid.next = self.beats_in.beat_valid.val();
        self.transport.beats.beat_data.next = self.beats_in.beat_data.val();
        self.transport.beat_first.next = self.beats_in.beat_first.val();
        self.transport.next_word.next = self.beats_in.word_in.val();
        self.transport.carries_udp.next = self.ipv4.carries_udp.val();
        self.transport.in_payload.next = self.ipv4.in_payload.val();
        self.transport.payload_length.next = self.ipv4.payload_length.val();

        // ---- the frame's end: its flags, then the total length's compares ----
        self.end_checks.clock.next = self.clock.val();
        self.end_checks.reset.next = self.reset.val();
        self.end_checks.beat_valid.next = self.beats_in.beat_valid.val();
        self.end_checks.beat_last.next = self.beats_in.beat_last.val();
        self.end_checks.beat_error.next = self.beats_in.beat_error.val();
        self.end_checks.beat_length_error.next = self.beats_in.beat_length_error.val();
        self.end_checks.stored.next = self.beats_in.stored.val();
        self.end_checks.fits.next = self.ipv4.fits.val();
        self.end_checks.total_length.next = self.ipv4.total_length.val();

        // ---- the rule table (steps 1-16a) over the checks ----
        self.rules.clock.next = self.clock.val();
        self.rules.reset.next = self.reset.val();
        self.rules.check.next = self.end_checks.check.val();
        self.rules.bad_length.next = self.end_checks.bad_length.val();
        self.rules.bad_fcs.next = self.end_checks.bad_fcs.val();
        self.rules.not_to_box.next = !(self.ethernet.to_box.val() | self.ethernet.broadcast.val());
        self.rules.arp.next = self.ethernet.is_arp.val();
        self.rules.arp_for_box.next = self.arp.request_for_box.val();
        self.rules.ipv4.next = self.ethernet.ipv4.val() & !self.ethernet.broadcast.val();
        self.rules.bad_version.next = self.ipv4.bad_version.val();
        self.rules.options.next = self.ipv4.options.val();
        self.rules.bad_header.next =
            self.ipv4.bad_header.val() | !self.end_checks.packet_fits.val();
        self.rules.fragment.next = self.ipv4.fragment.val();
        self.rules.ip_not_to_box.next = !self.ipv4.to_box.val();
        self.rules.icmp.next = self.ipv4.icmp.val();
        self.rules.icmp_bad.next =
            !self.end_checks.total_from_28.val() | !self.transport.sum_ok.val();
        self.rules.echo_request.next = self.transport.echo_request.val();
        self.rules.udp.next = self.ipv4.udp.val();
        self.rules.udp_bad.next = !self.end_checks.total_from_28.val()
            | !self.transport.udp_length_ok.val()
            | (!self.transport.udp_no_checksum.val() & !self.transport.sum_ok.val());
        self.rules.other_port.next = !self.transport.to_box_port.val();
        self.rules.foreign.next = !self.ipv4.from_subnet.val();
        self.rules.malformed.next =
            !(self.end_checks.total_from_52.val() & self.command.well_formed.val());
        self.rules.stored.next = self.end_checks.end_stored.val();
        self.decided.next = self.rules.decided.val();
        self.action.next = self.rules.action.val();
        self.fate.next = self.rules.fate.val();
        self.peer_mac.next = self.beats_in.source_mac.val();
        self.peer_ip.next = self.ipv4.source.val();
        self.peer_port.next = self.transport.source_port.val();
        self.receive_tick_now.next = self.beats_in.stored_last.val();
        self.ip_total_length.next = self.ipv4.total_length.val();
        self.icmp_rest_sum.next = self.transport.icmp_rest_sum.val();
        self.command_box_id.next = self.command.box_id.val();
        self.command_opcode.next = self.command.opcode.val();
        self.command_sequence.next = self.command.sequence_number.val();
        self.command_argument_length.next = self.command.argument_length.val();
        self.command_arguments.next = self.command.arguments.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::receive_rules::{ACTION_ARP, ACTION_COMMAND, ACTION_ECHO, ACTION_NONE};
    use crate::testbench::{Bench, TestRng};
    use etherparse::checksum::Sum16BitWords;
    use etherparse::{Ipv4Header, PacketBuilder};
    use skinbox_protocol::box_counters::BoxCounter;
    use skinbox_protocol::command::{Command, CommandRepr, Destination, Request};

    const LINK: LinkConfig = LinkConfig::DEFAULT;
    const HOST_MAC: [u8; 6] = [0x02, 0x00, 0x5E, 0x10, 0x20, 0x30];
    const HOST_IP: [u8; 4] = [192, 0, 2, 1];
    const OTHER_IP: [u8; 4] = [192, 0, 2, 77];
    const FOREIGN_IP: [u8; 4] = [198, 51, 100, 7];
    const HOST_PORT: u16 = 40000;
    const TICK_BASE: u64 = 0x0123_4567_0000_0000;

    /// etherparse's sums work on native-endian words; these give the checksum as a number.
    trait Numeric {
        fn numeric(&self) -> u16;
        fn numeric_no_zero(&self) -> u16;
    }

    impl Numeric for Sum16BitWords {
        fn numeric(&self) -> u16 {
            u16::from_be_bytes(self.ones_complement().to_ne_bytes())
        }
        fn numeric_no_zero(&self) -> u16 {
            u16::from_be_bytes(self.to_ones_complement_with_no_zero().to_ne_bytes())
        }
    }

    /// The MAC's frames are at least this many clocks apart (last beat to next first beat).
    const MAC_FRAME_GAP: u64 = 20;

    /// The reply builder reads an echo request's ICMP sum before the next frame restarts it
    /// (in the clock after its first beat was registered).
    #[test]
    fn the_echo_fields_hold_until_the_reply_builder_reads_them() {
        let read = crate::reply_builder::echo_fields_read();
        assert!(DECISION_LATENCY + read <= MAC_FRAME_GAP + 1, "{read}");
    }

    /// A change to a command's bytes.
    type Mutation = Box<dyn Fn(&mut Vec<u8>)>;

    /// The MAC's view of an Ethernet frame: padded to 60 bytes, then the FCS.
    fn with_fcs(mut ethernet: Vec<u8>) -> Vec<u8> {
        ethernet.resize(ethernet.len().max(60), 0);
        let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&ethernet);
        ethernet.extend_from_slice(&fcs.to_le_bytes());
        ethernet
    }

    fn fcs_ok(frame: &[u8]) -> bool {
        let (body, fcs) = frame.split_at(frame.len() - 4);
        crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC)
            .checksum(body)
            .to_le_bytes()
            == fcs
    }

    fn arp(
        destination: [u8; 6],
        operation: u16,
        sender: ([u8; 6], [u8; 4]),
        target_ip: [u8; 4],
    ) -> Vec<u8> {
        let mut f = destination.to_vec();
        f.extend_from_slice(&sender.0);
        f.extend_from_slice(&[0x08, 0x06, 0, 1, 0x08, 0x00, 6, 4]);
        f.extend_from_slice(&operation.to_be_bytes());
        f.extend_from_slice(&sender.0);
        f.extend_from_slice(&sender.1);
        f.extend_from_slice(&[0; 6]);
        f.extend_from_slice(&target_ip);
        with_fcs(f)
    }

    fn echo(destination: [u8; 6], source_ip: [u8; 4], target_ip: [u8; 4], data: &[u8]) -> Vec<u8> {
        let b = PacketBuilder::ethernet2(HOST_MAC, destination)
            .ipv4(source_ip, target_ip, 64)
            .icmpv4_echo_request(0x1234, 7);
        let mut f = Vec::new();
        b.write(&mut f, data).unwrap();
        with_fcs(f)
    }

    fn udp(source_ip: [u8; 4], destination_port: u16, payload: &[u8]) -> Vec<u8> {
        let b = PacketBuilder::ethernet2(HOST_MAC, LINK.box_mac)
            .ipv4(source_ip, LINK.box_ip, 64)
            .udp(HOST_PORT, destination_port);
        let mut f = Vec::new();
        b.write(&mut f, payload).unwrap();
        with_fcs(f)
    }

    fn command(request: Request, sequence: u32) -> Vec<u8> {
        CommandRepr {
            box_id: 0x0102,
            sequence,
            host_time: 0x1122_3344_5566_7788,
            request,
        }
        .to_bytes()
    }

    fn stream_to() -> Request {
        Request::StreamTo {
            to: Some(Destination {
                mac: [0x02, 0xAA, 0xBB, 0xCC, 0xDD, 0xEE],
                ip: [10, 1, 2, 3],
                port: 0x4455,
            }),
        }
    }

    /// Recomputes the FCS after a change to the frame.
    fn fix_fcs(frame: &mut Vec<u8>) {
        let n = frame.len() - 4;
        frame.truncate(n);
        let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(frame);
        frame.extend_from_slice(&fcs.to_le_bytes());
    }

    /// What the parser said about one frame.
    #[derive(Debug, Clone, PartialEq)]
    struct Seen {
        action: u8,
        fate: usize,
        peer_mac: u64,
        peer_ip: u32,
        peer_port: u16,
        /// The tick of the clock with `receive_tick_now`.
        receive_tick: Option<u64>,
        total_length: u16,
        icmp_rest_sum: u16,
        box_id: u16,
        opcode: u8,
        sequence: u32,
        argument_length: u16,
        arguments: [u8; 12],
        writes: Vec<(usize, u8)>,
        last_tick: u64,
    }

    struct Harness {
        bench: Bench<FrameParser>,
    }

    impl Harness {
        fn new() -> Self {
            let mut bench = Bench::new(FrameParser::new(&LINK), |p| &mut p.clock);
            bench.uut.reset.next = true;
            bench.cycle();
            bench.uut.reset.next = false;
            bench.cycles(3);
            Harness { bench }
        }

        fn drive_tick(&mut self) -> u64 {
            TICK_BASE + self.bench.cycles * 3
        }

        fn collect(&self, writes: &mut Vec<(usize, u8)>) {
            let u = &self.bench.uut;
            if u.buffer_write_enable.val() {
                writes.push((
                    u.buffer_write_address.val().index(),
                    u.buffer_write_data.val().to_u8(),
                ));
            }
        }

        /// Sends one frame as the MAC would (`error` as the MAC's FCS check says, unless
        /// forced), then 20 idle clocks; checks `decided` comes once, DECISION_LATENCY
        /// clocks after the last beat.
        fn send(&mut self, frame: &[u8], locked: bool) -> Seen {
            let length_error = !(64..=1518).contains(&frame.len());
            let error = length_error || !fcs_ok(frame);
            self.send_flags(frame, locked, error, length_error)
        }

        fn send_flags(
            &mut self,
            frame: &[u8],
            locked: bool,
            error: bool,
            length_error: bool,
        ) -> Seen {
            let mut writes = vec![];
            let mut last_tick = 0;
            let mut receive_tick = None;
            for (i, &b) in frame.iter().enumerate() {
                let last = i + 1 == frame.len();
                let t = self.drive_tick();
                let u = &mut self.bench.uut;
                u.frame.valid.next = true;
                u.frame.data.next = u64::from(b).into();
                u.frame.last.next = last;
                u.frame.error.next = last && error;
                u.length_error.next = last && length_error;
                u.buffer_locked.next = locked;
                self.bench.settle();
                assert!(self.bench.uut.frame.ready.val());
                assert!(!self.bench.uut.decided.val());
                if last {
                    last_tick = t;
                }
                if self.bench.uut.receive_tick_now.val() {
                    assert!(receive_tick.is_none(), "one receive tick");
                    receive_tick = Some(t);
                }
                self.bench.cycle();
                self.collect(&mut writes);
            }
            let u = &mut self.bench.uut;
            u.frame.valid.next = false;
            u.frame.last.next = false;
            u.frame.error.next = false;
            u.length_error.next = false;
            let mut seen = None;
            for k in 1..=20u64 {
                self.drive_tick();
                self.bench.settle();
                let u = &self.bench.uut;
                assert!(!u.receive_tick_now.val(), "a receive tick between frames");
                if u.decided.val() {
                    assert_eq!(
                        k, DECISION_LATENCY,
                        "decided {k} clocks after the last beat"
                    );
                    assert!(seen.is_none(), "decided twice");
                    let args = u.command_arguments.val();
                    let mut arguments = [0u8; 12];
                    for (j, a) in arguments.iter_mut().enumerate() {
                        *a = args.get_bits::<8>(88 - 8 * j).to_u8();
                    }
                    seen = Some(Seen {
                        action: u.action.val().to_u8(),
                        fate: u.fate.val().index(),
                        peer_mac: u.peer_mac.val().to_u64(),
                        peer_ip: u.peer_ip.val().to_u32(),
                        peer_port: u.peer_port.val().to_u16(),
                        receive_tick,
                        total_length: u.ip_total_length.val().to_u16(),
                        icmp_rest_sum: u.icmp_rest_sum.val().to_u16(),
                        box_id: u.command_box_id.val().to_u16(),
                        opcode: u.command_opcode.val().to_u8(),
                        sequence: u.command_sequence.val().to_u32(),
                        argument_length: u.command_argument_length.val().to_u16(),
                        arguments,
                        writes: vec![],
                        last_tick,
                    });
                }
                self.bench.cycle();
                self.collect(&mut writes);
            }
            let mut seen = seen.expect("decided");
            seen.writes = writes;
            seen
        }
    }

    /// The rule table of docs/control.md, steps 1-16, written over the bytes (etherparse
    /// for the IPv4 header and the checksums, the protocol crate for the command header):
    /// (action, fate) of a frame as the MAC delivers it.
    fn reference(frame: &[u8], locked: bool) -> (u8, BoxCounter) {
        let (action, fate) = reference_unlocked(frame);
        if action != ACTION_NONE && locked {
            (ACTION_NONE, BoxCounter::ReplyBusy)
        } else {
            (action, fate)
        }
    }

    fn reference_unlocked(frame: &[u8]) -> (u8, BoxCounter) {
        use BoxCounter::*;
        let none = |f| (ACTION_NONE, f);
        if !(64..=1518).contains(&frame.len()) {
            return none(BadLength);
        }
        if !fcs_ok(frame) {
            return none(BadFcs);
        }
        let body = &frame[..frame.len() - 4];
        let broadcast = body[0..6] == [0xFF; 6];
        if body[0..6] != LINK.box_mac && !broadcast {
            return none(NotForUs);
        }
        let ethertype = u16::from_be_bytes([body[12], body[13]]);
        let payload = &body[14..];
        if ethertype == 0x0806 {
            return if payload[..8] == [0, 1, 8, 0, 6, 4, 0, 1] && payload[24..28] == LINK.box_ip {
                (ACTION_ARP, ArpAnswered)
            } else {
                none(NotForUs)
            };
        }
        if ethertype != 0x0800 || broadcast {
            return none(NotForUs);
        }
        if payload[0] >> 4 != 4 || payload[0] & 15 < 5 {
            return none(Ipv4BadHeader);
        }
        if payload[0] & 15 > 5 {
            return none(Ipv4Options);
        }
        let Ok((ip, _)) = Ipv4Header::from_slice(payload) else {
            return none(Ipv4BadHeader);
        };
        let total = usize::from(ip.total_len);
        // the sum over the raw header (etherparse drops the reserved flag bit)
        let header_sum = Sum16BitWords::new().add_slice(&payload[..20]).numeric();
        if total < 20 || header_sum != 0 || total > payload.len() {
            return none(Ipv4BadHeader);
        }
        if ip.more_fragments || ip.fragment_offset.value() != 0 {
            return none(Ipv4Fragment);
        }
        if ip.destination != LINK.box_ip {
            return none(NotForUs);
        }
        let message = &payload[20..total];
        match ip.protocol.0 {
            1 => {
                if message.len() < 8 || Sum16BitWords::new().add_slice(message).numeric() != 0 {
                    none(BadTransport)
                } else if message[0] == 8 && message[1] == 0 {
                    (ACTION_ECHO, PingsAnswered)
                } else {
                    none(NotForUs)
                }
            }
            17 => {
                if message.len() < 8
                    || usize::from(u16::from_be_bytes([message[4], message[5]])) != message.len()
                {
                    return none(BadTransport);
                }
                let sum = Sum16BitWords::new()
                    .add_4bytes(ip.source)
                    .add_4bytes(ip.destination)
                    .add_2bytes([0, 17])
                    .add_2bytes((message.len() as u16).to_be_bytes())
                    .add_slice(message)
                    .numeric();
                if message[6..8] != [0, 0] && sum != 0 {
                    return none(BadTransport);
                }
                if u16::from_be_bytes([message[2], message[3]]) != LINK.box_port {
                    return none(UnknownUdpPort);
                }
                let mask = u32::MAX << (32 - u32::from(LINK.host_subnet_prefix_len));
                if (u32::from_be_bytes(ip.source) ^ u32::from_be_bytes(LINK.host_subnet)) & mask
                    != 0
                {
                    return none(RefusedForeignSubnet);
                }
                if Command::new_checked(&message[8..]).is_err() {
                    return none(RefusedMalformed);
                }
                (ACTION_COMMAND, FramesReceived)
            }
            _ => none(NotForUs),
        }
    }

    fn be_u64(b: &[u8]) -> u64 {
        b.iter().fold(0, |v, &x| v << 8 | u64::from(x))
    }

    /// Checks a decision against the reference, and, for a stored frame, the buffer writes
    /// and the held fields against the frame's bytes.
    fn check(seen: &Seen, frame: &[u8], locked: bool, what: &str) {
        let (action, fate) = reference(frame, locked);
        assert_eq!(
            (seen.action, seen.fate),
            (action, fate as usize),
            "{what}: action, fate ({fate:?})"
        );
        if locked {
            assert!(
                seen.writes.is_empty(),
                "{what}: a frame arriving while locked is written"
            );
            assert_eq!(seen.receive_tick, None, "{what}: receive tick");
            return;
        }
        let expected: Vec<(usize, u8)> = frame.iter().copied().enumerate().collect();
        assert_eq!(seen.writes, expected, "{what}: buffer writes");
        assert_eq!(
            seen.receive_tick,
            Some(seen.last_tick),
            "{what}: receive tick"
        );
        if frame.len() >= 64 {
            // the sender as the command unit reads it (an ARP reply takes the sender's
            // addresses from the request in the buffer)
            assert_eq!(seen.peer_mac, be_u64(&frame[6..12]), "{what}: peer MAC");
            assert_eq!(
                u64::from(seen.peer_ip),
                be_u64(&frame[26..30]),
                "{what}: peer IP"
            );
            assert_eq!(
                u64::from(seen.total_length),
                be_u64(&frame[16..18]),
                "{what}: total length"
            );
        }
        if action == ACTION_ECHO || action == ACTION_COMMAND {
            let total = usize::from(seen.total_length);
            let message = &frame[34..14 + total];
            if action == ACTION_ECHO {
                let rest = !Sum16BitWords::new().add_slice(&message[4..]).numeric();
                assert_eq!(seen.icmp_rest_sum, rest, "{what}: ICMP rest sum");
            } else {
                assert_eq!(
                    u64::from(seen.peer_port),
                    be_u64(&message[0..2]),
                    "{what}: peer port"
                );
                let c = Command::new_checked(&message[8..]).unwrap();
                assert_eq!(seen.box_id, c.box_id(), "{what}: box id");
                assert_eq!(seen.opcode, c.opcode(), "{what}: opcode");
                assert_eq!(seen.sequence, c.sequence(), "{what}: sequence");
                assert_eq!(
                    usize::from(seen.argument_length),
                    c.arguments().len(),
                    "{what}: argument length"
                );
                let mut args = [0u8; 12];
                let n = c.arguments().len().min(12);
                args[..n].copy_from_slice(&c.arguments()[..n]);
                assert_eq!(seen.arguments, args, "{what}: arguments");
            }
        }
    }

    fn run(h: &mut Harness, frame: &[u8], locked: bool, what: &str) -> Seen {
        let seen = h.send(frame, locked);
        check(&seen, frame, locked, what);
        seen
    }

    /// Recomputes the IPv4 header checksum (IHL 5), the ICMP or UDP checksum (when the
    /// packet fits the frame) and the FCS, as a sender would.
    fn fix_checksums(frame: &mut Vec<u8>) {
        let body_len = frame.len() - 4;
        if body_len >= 34 && frame[12..14] == [8, 0] && frame[14] & 15 == 5 {
            frame[24..26].fill(0);
            let sum = Sum16BitWords::new().add_slice(&frame[14..34]).numeric();
            frame[24..26].copy_from_slice(&sum.to_be_bytes());
            let total = usize::from(u16::from_be_bytes([frame[16], frame[17]]));
            if (28..=body_len - 14).contains(&total) {
                let end = 14 + total;
                if frame[23] == 1 {
                    frame[36..38].fill(0);
                    let sum = Sum16BitWords::new().add_slice(&frame[34..end]).numeric();
                    frame[36..38].copy_from_slice(&sum.to_be_bytes());
                } else if frame[23] == 17 {
                    frame[40..42].fill(0);
                    let sum = Sum16BitWords::new()
                        .add_slice(&frame[26..34])
                        .add_2bytes([0, 17])
                        .add_2bytes(((total - 20) as u16).to_be_bytes())
                        .add_slice(&frame[34..end])
                        .numeric_no_zero();
                    frame[40..42].copy_from_slice(&sum.to_be_bytes());
                }
            }
        }
        fix_fcs(frame);
    }

    fn good_command() -> Vec<u8> {
        udp(HOST_IP, LINK.box_port, &command(stream_to(), 5))
    }

    fn good_echo() -> Vec<u8> {
        echo(
            LINK.box_mac,
            HOST_IP,
            LINK.box_ip,
            b"skinbox echo data 0123456789",
        )
    }

    /// Every ARP case: a request for the box's IP (broadcast or to the box's MAC) is
    /// answered with the sender's addresses held; another target or a reply is not for us.
    #[test]
    fn arp_requests_for_the_box_are_answered() {
        let mut h = Harness::new();
        let requester = ([0x02, 0x11, 0x22, 0x33, 0x44, 0x55], [192, 0, 2, 99]);
        for (frame, what, action) in [
            (
                arp([0xFF; 6], 1, requester, LINK.box_ip),
                "broadcast request",
                ACTION_ARP,
            ),
            (
                arp(LINK.box_mac, 1, requester, LINK.box_ip),
                "unicast request",
                ACTION_ARP,
            ),
            (
                arp([0xFF; 6], 1, requester, OTHER_IP),
                "request for another IP",
                ACTION_NONE,
            ),
            (
                arp(LINK.box_mac, 2, requester, LINK.box_ip),
                "reply",
                ACTION_NONE,
            ),
            (
                arp([0x02, 0, 0, 0, 0, 9], 1, requester, LINK.box_ip),
                "to another MAC",
                ACTION_NONE,
            ),
        ] {
            let seen = run(&mut h, &frame, false, what);
            assert_eq!(seen.action, action, "{what}");
        }
        // an ARP header with another hardware type is not for us
        let mut f = arp([0xFF; 6], 1, requester, LINK.box_ip);
        f[15] = 6;
        fix_fcs(&mut f);
        assert_eq!(
            run(&mut h, &f, false, "hardware 6").fate,
            BoxCounter::NotForUs as usize
        );
    }

    /// Steps 1-2 and 5-10: lengths, FCS, EtherType and every IPv4 header rule.
    #[test]
    fn ipv4_header_rules_in_the_model_order() {
        use BoxCounter::*;
        let mut h = Harness::new();
        let good = good_echo();
        let mut cases: Vec<(Vec<u8>, &str, BoxCounter)> =
            vec![(good.clone(), "good echo", PingsAnswered)];
        let mutated = |f: &dyn Fn(&mut Vec<u8>), fix: bool| {
            let mut x = good.clone();
            f(&mut x);
            if fix {
                fix_checksums(&mut x);
            } else {
                fix_fcs(&mut x);
            }
            x
        };
        cases.push((mutated(&|f| f[14] = 0x65, true), "version 6", Ipv4BadHeader));
        cases.push((mutated(&|f| f[14] = 0x44, true), "IHL 4", Ipv4BadHeader));
        cases.push((
            mutated(&|f| f[24] ^= 1, false),
            "bad header checksum",
            Ipv4BadHeader,
        ));
        let body = good.len() - 4 - 14;
        cases.push((
            mutated(
                &|f| f[16..18].copy_from_slice(&((body + 1) as u16).to_be_bytes()),
                true,
            ),
            "total beyond the frame",
            Ipv4BadHeader,
        ));
        cases.push((
            mutated(&|f| f[16..18].copy_from_slice(&19u16.to_be_bytes()), true),
            "total 19",
            Ipv4BadHeader,
        ));
        cases.push((mutated(&|f| f[20] |= 0x20, true), "MF set", Ipv4Fragment));
        cases.push((
            mutated(&|f| f[21] = 0x08, true),
            "fragment offset",
            Ipv4Fragment,
        ));
        cases.push((mutated(&|f| f[20] = 0x40, true), "DF set", PingsAnswered));
        cases.push((
            echo(LINK.box_mac, HOST_IP, OTHER_IP, b"x"),
            "other destination IP",
            NotForUs,
        ));
        cases.push((
            echo([0xFF; 6], HOST_IP, LINK.box_ip, b"x"),
            "broadcast IPv4",
            NotForUs,
        ));
        cases.push((
            mutated(&|f| f[12..14].copy_from_slice(&[0x86, 0xDD]), false),
            "IPv6 EtherType",
            NotForUs,
        ));
        cases.push((mutated(&|f| f[23] = 6, true), "TCP", NotForUs));
        // IHL 6: a 4-byte option inserted after the header, all lengths and sums right
        let mut options = good[..34].to_vec();
        options.extend_from_slice(&[1, 1, 1, 0]);
        options.extend_from_slice(&good[34..good.len() - 4]);
        options[14] = 0x46;
        let total = u16::from_be_bytes([options[16], options[17]]) + 4;
        options[16..18].copy_from_slice(&total.to_be_bytes());
        options[24..26].fill(0);
        let sum = Sum16BitWords::new().add_slice(&options[14..38]).numeric();
        options[24..26].copy_from_slice(&sum.to_be_bytes());
        cases.push((with_fcs(options), "IHL 6 with options", Ipv4Options));
        let mut short = good.clone();
        short.truncate(63);
        cases.push((short, "63 bytes", BadLength));
        let mut bad_fcs = good.clone();
        bad_fcs[good.len() - 2] ^= 0x10;
        cases.push((bad_fcs, "bad FCS", BadFcs));
        // the longest frame the MAC takes: 1518 bytes, a 1480-byte ICMP message
        let longest = echo(LINK.box_mac, HOST_IP, LINK.box_ip, &[0xA5; 1472]);
        assert_eq!(longest.len(), 1518);
        cases.push((longest, "1518 bytes", PingsAnswered));
        for (frame, what, fate) in &cases {
            let seen = run(&mut h, frame, false, what);
            assert_eq!(seen.fate, *fate as usize, "{what}");
        }
        // a frame longer than 1518: the MAC stops at 1518 beats and adds a 1519th, data 0,
        // with error and length_error
        let mut long = echo(LINK.box_mac, HOST_IP, LINK.box_ip, &[0x5A; 1472]);
        long.truncate(1518);
        long.push(0);
        let seen = h.send_flags(&long, false, true, true);
        assert_eq!((seen.action, seen.fate), (ACTION_NONE, BadLength as usize));
    }

    /// Steps 11-12: ICMP short, bad checksum, echo with odd and even data, other types,
    /// Ethernet padding after a short packet; the held rest sum against an independent
    /// checksum.
    #[test]
    fn icmp_rules_and_the_rest_sum() {
        use BoxCounter::*;
        let mut h = Harness::new();
        for len in [0usize, 1, 2, 3, 17, 18, 33, 64, 255] {
            let data: Vec<u8> = (0..len).map(|i| (i * 37 + 11) as u8).collect();
            let f = echo(LINK.box_mac, HOST_IP, LINK.box_ip, &data);
            let seen = run(&mut h, &f, false, &format!("echo with {len} data bytes"));
            assert_eq!(seen.fate, PingsAnswered as usize);
            assert_eq!(usize::from(seen.total_length), 28 + len);
        }
        // a 4-byte ICMP message (total 24), its checksum right: too short
        let mut f = good_echo();
        f[16..18].copy_from_slice(&24u16.to_be_bytes());
        f[36..38].fill(0);
        let sum = Sum16BitWords::new().add_slice(&f[34..38]).numeric();
        f[36..38].copy_from_slice(&sum.to_be_bytes());
        let n = f.len();
        f[24..26].fill(0);
        let sum = Sum16BitWords::new().add_slice(&f[14..34]).numeric();
        f[24..26].copy_from_slice(&sum.to_be_bytes());
        fix_fcs(&mut f);
        assert_eq!(f.len(), n);
        assert_eq!(
            run(&mut h, &f, false, "ICMP 4 bytes").fate,
            BadTransport as usize
        );
        let mut f = good_echo();
        f[50] ^= 0x40;
        fix_fcs(&mut f);
        assert_eq!(
            run(&mut h, &f, false, "bad ICMP checksum").fate,
            BadTransport as usize
        );
        for (t, c, what) in [
            (13u8, 0u8, "timestamp"),
            (8, 1, "echo code 1"),
            (0, 0, "echo reply"),
        ] {
            let mut f = good_echo();
            f[34] = t;
            f[35] = c;
            fix_checksums(&mut f);
            assert_eq!(
                run(&mut h, &f, false, what).fate,
                NotForUs as usize,
                "{what}"
            );
        }
        // padding bytes after a short packet are not part of the ICMP message
        let mut f = echo(LINK.box_mac, HOST_IP, LINK.box_ip, b"abc");
        assert_eq!(f.len(), 64);
        f[14 + 31..60].fill(0xEE);
        fix_fcs(&mut f);
        assert_eq!(
            run(&mut h, &f, false, "padding 0xEE").fate,
            PingsAnswered as usize
        );
    }

    /// Steps 13-16: UDP short, length mismatch, bad checksum, checksum 0, other port,
    /// foreign subnet, every malformed command header, and well-formed commands with their
    /// held fields.
    #[test]
    fn udp_and_command_rules() {
        use BoxCounter::*;
        let mut h = Harness::new();
        let good = good_command();
        let fate = |h: &mut Harness, f: &Vec<u8>, what: &str| run(h, f, false, what).fate;
        assert_eq!(fate(&mut h, &good, "stream-to"), 0);
        let mut f = good.clone();
        f[40..42].fill(0);
        fix_fcs(&mut f);
        let seen = run(&mut h, &f, false, "checksum 0");
        assert_eq!(seen.action, ACTION_COMMAND);
        let mut f = good.clone();
        f[70] ^= 1;
        fix_fcs(&mut f);
        assert_eq!(fate(&mut h, &f, "bad UDP checksum"), BadTransport as usize);
        let mut f = good.clone();
        f[39] += 1;
        fix_checksums(&mut f);
        assert_eq!(
            fate(&mut h, &f, "UDP length mismatch"),
            BadTransport as usize
        );
        // a 6-byte UDP "header": total 26
        let mut f = udp(HOST_IP, LINK.box_port, &[]);
        f[16..18].copy_from_slice(&26u16.to_be_bytes());
        f[38..40].copy_from_slice(&6u16.to_be_bytes());
        fix_checksums(&mut f);
        assert_eq!(fate(&mut h, &f, "UDP short"), BadTransport as usize);
        assert_eq!(
            fate(
                &mut h,
                &udp(HOST_IP, 53, &command(stream_to(), 5)),
                "other port"
            ),
            UnknownUdpPort as usize
        );
        assert_eq!(
            fate(
                &mut h,
                &udp(FOREIGN_IP, LINK.box_port, &command(stream_to(), 5)),
                "foreign subnet"
            ),
            RefusedForeignSubnet as usize
        );
        let base = command(Request::SetFlushTimeout { ticks: 1000 }, 9);
        let malformed: Vec<(&str, Mutation)> = vec![
            ("magic", Box::new(|c| c[0] = b'X')),
            ("version 2", Box::new(|c| c[2] = 2)),
            ("kind 4", Box::new(|c| c[3] = 4)),
            ("flags", Box::new(|c| c[7] = 1)),
            ("reserved", Box::new(|c| c[23] = 1)),
            ("argument length + 1", Box::new(|c| c[21] += 1)),
            ("argument length - 1", Box::new(|c| c[21] -= 1)),
            ("argument length + 65536 - 1", Box::new(|c| c[20] = 0xFF)),
            ("short header", Box::new(|c| c.truncate(23))),
            ("one byte", Box::new(|c| c.truncate(1))),
            ("empty", Box::new(|c| c.clear())),
        ];
        for (what, m) in &malformed {
            let mut c = base.clone();
            m(&mut c);
            assert_eq!(
                fate(&mut h, &udp(HOST_IP, LINK.box_port, &c), what),
                RefusedMalformed as usize,
                "{what}"
            );
        }
        // well-formed headers: the parser does not check opcodes or arguments
        let cell = Request::CellCommand {
            port: 1,
            packet: [0x5A; skinbox_protocol::cell::PACKET_LEN],
        };
        for (what, c) in [
            ("status now", command(Request::StatusNow, 1)),
            ("set flush timeout", base.clone()),
            (
                "stream to sender",
                command(Request::StreamTo { to: None }, 0xFFFF_FFFF),
            ),
            ("cell command", command(cell, 3)),
        ] {
            let seen = run(&mut h, &udp(HOST_IP, LINK.box_port, &c), false, what);
            assert_eq!(seen.action, ACTION_COMMAND, "{what}");
            assert_eq!(seen.peer_port, HOST_PORT, "{what}");
            assert_eq!(seen.peer_mac, be_u64(&HOST_MAC), "{what}");
            assert_eq!(seen.peer_ip, u32::from_be_bytes(HOST_IP), "{what}");
        }
        // an odd-length payload: unknown opcode 200 with 3 argument bytes (well-formed)
        let mut c = base.clone();
        c[6] = 200;
        c.truncate(27);
        c[21] = 3;
        let seen = run(
            &mut h,
            &udp(HOST_IP, LINK.box_port, &c),
            false,
            "odd length",
        );
        assert_eq!(seen.action, ACTION_COMMAND);
        assert_eq!(seen.arguments[..4], [c[24], c[25], c[26], 0]);
    }

    /// Frames arriving while the buffer is locked are not written; those to be answered
    /// get ReplyBusy and no receive tick (the reply builder keeps the last stored frame's).
    #[test]
    fn a_locked_buffer_is_not_written_and_replies_are_busy() {
        use BoxCounter::*;
        let mut h = Harness::new();
        let stored = run(&mut h, &good_echo(), false, "stored echo");
        assert!(stored.receive_tick.is_some());
        let requester = ([0x02, 0x11, 0x22, 0x33, 0x44, 0x55], [192, 0, 2, 99]);
        for (frame, what, fate) in [
            (arp([0xFF; 6], 1, requester, LINK.box_ip), "ARP", ReplyBusy),
            (good_command(), "command", ReplyBusy),
            (
                echo(LINK.box_mac, [192, 0, 2, 55], LINK.box_ip, b"other"),
                "echo",
                ReplyBusy,
            ),
            (udp(HOST_IP, 53, b"dns"), "other port", UnknownUdpPort),
        ] {
            let seen = run(&mut h, &frame, true, what);
            assert_eq!(
                (seen.action, seen.fate),
                (ACTION_NONE, fate as usize),
                "{what}"
            );
            // (the other fields follow the frame: they are read between a stored frame's
            // decision and the next frame only)
            assert_eq!(seen.receive_tick, None, "{what}: receive tick");
        }
        // the lock counts at the first beat only: raised after it, the frame is stored
        let f = good_command();
        let mut writes = vec![];
        for (i, &b) in f.iter().enumerate() {
            let u = &mut h.bench.uut;
            u.frame.valid.next = true;
            u.frame.data.next = u64::from(b).into();
            u.frame.last.next = i + 1 == f.len();
            u.buffer_locked.next = i > 0;
            h.bench.cycle();
            h.collect(&mut writes);
        }
        h.bench.uut.frame.valid.next = false;
        h.bench.uut.frame.last.next = false;
        for _ in 0..DECISION_LATENCY {
            h.bench.settle();
            if h.bench.uut.decided.val() {
                assert_eq!(h.bench.uut.action.val().to_u8(), ACTION_COMMAND);
            }
            h.bench.cycle();
            h.collect(&mut writes);
        }
        assert_eq!(writes.len(), f.len());
    }

    /// 400 random mutations of good ARP, echo and command frames, and random lengths,
    /// checked against the reference; 20 % of them while the buffer is locked.
    #[test]
    fn random_frames_match_the_reference() {
        let mut h = Harness::new();
        let mut rng = TestRng::new(0x5EED);
        let mut fates = std::collections::BTreeMap::new();
        let requester = ([0x02, 0x11, 0x22, 0x33, 0x44, 0x55], [192, 0, 2, 99]);
        for n in 0..400 {
            let mut f = match rng.next_u64() % 4 {
                0 => arp(
                    if rng.chance(0.5) {
                        [0xFF; 6]
                    } else {
                        LINK.box_mac
                    },
                    1,
                    requester,
                    LINK.box_ip,
                ),
                1 => {
                    let len = if rng.chance(0.05) {
                        1472
                    } else {
                        (rng.next_u64() % 80) as usize
                    };
                    let data: Vec<u8> = (0..len).map(|_| rng.byte()).collect();
                    echo(LINK.box_mac, HOST_IP, LINK.box_ip, &data)
                }
                _ => {
                    let request = match rng.next_u64() % 4 {
                        0 => stream_to(),
                        1 => Request::SetStatusPeriod {
                            ticks: rng.next_u64() as u32,
                        },
                        2 => Request::ReadTick,
                        _ => Request::CellCommand {
                            port: rng.byte(),
                            packet: [rng.byte(); skinbox_protocol::cell::PACKET_LEN],
                        },
                    };
                    let source = if rng.chance(0.9) { HOST_IP } else { FOREIGN_IP };
                    udp(
                        source,
                        LINK.box_port,
                        &command(request, rng.next_u64() as u32),
                    )
                }
            };
            // mutate 0-3 bytes, mostly in the headers
            for _ in 0..rng.next_u64() % 4 {
                let at = if rng.chance(0.8) {
                    (rng.next_u64() % 80) as usize
                } else {
                    (rng.next_u64() as usize) % f.len()
                };
                let at = at.min(f.len() - 1);
                match rng.next_u64() % 3 {
                    0 => f[at] ^= 1 << (rng.next_u64() % 8),
                    1 => f[at] = rng.byte(),
                    _ => f[at] = f[at].wrapping_add(1),
                }
            }
            if rng.chance(0.1) {
                // another length: cut or extend (padding or a packet beyond the frame)
                let len = (f.len() as i64 + (rng.next_u64() % 17) as i64 - 8).max(20) as usize;
                f.resize(len, rng.byte());
            }
            if rng.chance(0.6) {
                fix_checksums(&mut f);
            } else if rng.chance(0.9) {
                fix_fcs(&mut f);
            }
            let locked = rng.chance(0.2);
            let what = format!("random frame {n}: {f:02x?}");
            let seen = run(&mut h, &f, locked, &what);
            *fates.entry(seen.fate).or_insert(0) += 1;
        }
        // the mutations reach most fates
        assert!(fates.len() >= 12, "fates reached: {fates:?}");
    }

    /// The block's Verilog passes Verilator's lint with the box's waivers.
    #[test]
    fn verilog_lints_clean() {
        let mut uut = FrameParser::new(&LINK);
        uut.connect_all();
        let text = generate_verilog(&uut);
        let dir = std::env::temp_dir().join(format!("skinbox-frame-parser-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&text, &dir).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}

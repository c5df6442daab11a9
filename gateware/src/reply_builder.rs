//! ReplyBuilder: writes the box's reply to a received frame (ARP reply, ICMP echo reply or
//! command acknowledgement) into the frame buffer that holds the request, and sends it as
//! a raw frame.
//!
//! It owns the frame buffer (2 KB of block RAM): the frame parser writes every stored frame
//! into it through the receive write port, which is shut while `locked`. `reserve` locks
//! it (a reply will follow, the request must stay); `start_arp`, `start_echo` or
//! `start_ack` then builds the reply in place, one byte per clock, from the request
//! itself, the parser's and the command unit's fields (those that change with the next
//! frame read first in a program), the receive or send tick it holds and constants. The
//! request's own fields are not taken from the parser: the sender's MAC, IPv4 address and
//! UDP port and the command's opcode are copied inside the buffer (read two clocks before they are
//! written), the command's sequence number and host time and the echo request's total
//! length stay where they are (at the same place in the reply) and are read to be summed.
//! So the peer_* and command_sequence/host_time fields of the parser need not reach this
//! block; a 64-byte field multiplexer would cost more LUTs than the copies.
//!
//! - ARP reply (RFC 826): all 60 bytes.
//! - Echo reply: bytes 0..38 (MACs, the IPv4 header anew with identification 0, don't
//!   fragment, TTL 64 and its checksum; ICMP type 0, code 0 and the checksum
//!   `!icmp_rest_sum`); identifier, sequence and data stay where they were received, and
//!   the bytes from 14 + total length up to 60 are zeroed (the received padding may not be).
//! - Acknowledgement: the whole UDP frame to the command's sender, as
//!   `skinbox_protocol::command::AckRepr::emit` lays out the payload, with the destination
//!   now in effect (stream-to ok) or the box counter block (status-now ok) after the fixed
//!   body. Its send tick and UDP checksum are written when the descriptor is taken.
//!
//! The builder is a sequencer stepping through a program in a ROM (one step per clock:
//! a frame position, and a constant byte, a held-field byte, a counter byte, a checksum
//! byte or a byte of the buffer); a byte goes through three registers (the ROM's output,
//! the ROM word's parts or the byte in each field word, the written byte) and is summed into
//! the IPv4 or UDP checksum as it is written (a running sum with an end-around carry); the
//! checksums are complemented into a register and written last. Build
//! durations: [`build_clocks`] (64 clocks for ARP, 60 for an echo of any length, 90, 102
//! and 174 for acknowledgements without a reply, with a destination, with the counters).
//! The counters are read one per four clocks from `counters_address` 0 on (a read's data
//! is taken four clocks after its address: a counter file with the block RAM's two-clock
//! latency fits).
//!
//! Then it offers a descriptor of kind [`RAW_FRAME_KIND`] with the frame's length (padded
//! to 60). The take (valid & ready at an edge, tick T in that clock) is registered; a
//! clock later the offer ends (`valid` stays high that one clock after the take: the
//! arbiter holds the granted body open and takes no descriptor then), its [`BodyReader`]
//! starts reading the frame from byte 0, and for an acknowledgement the
//! patch program writes the send tick T + [`TAKE_TO_FIRST_BYTE`] (8 bytes) and the UDP
//! checksum, which are done [`patch_margin_clocks`] clocks before the reader can reach the
//! first of them. `locked` falls the clock after the last body beat was taken.
//!
//! Use: `reserve`, then one `start_*` (a `start_*` while a reply is under way is ignored;
//! a `reserve` must always be followed by a `start_*`, or the buffer stays locked). For
//! a status-now acknowledgement the command must have been counted in the box counter
//! file before `start_ack` (the block says "this command counted").

use crate::block_ram::BlockRam;
use crate::body_reader::{BodyReader, BODY_ADDRESS_BITS};
use crate::frame_transmitter::TAKE_TO_FIRST_BYTE;
use crate::hdl::*;
use crate::reply_checksums::{CHECKSUM_CLOCKS, UDP_SUM_BYTES};
use crate::reply_field_bytes::{field_byte, ReplyFieldBytes};
use crate::reply_sequencer::{ProgramStarts, ReplySequencer, ROM_ADDRESS_BITS, START_TO_WORD};
pub use crate::reply_sizing::AckReplyKind;
use crate::reply_sizing::ReplySizing;
use crate::reply_stages::ReplyStages;
use crate::stream::{DatagramSource, RAW_FRAME_KIND};
use skinbox_protocol::box_counters::{self, BoxCounter};
use skinbox_protocol::command::{self, ack_field, destination_field, ACK_FIXED_LEN, KIND_ACK};
use skinbox_protocol::datagram::{MAGIC, VERSION};
use skinbox_protocol::link::*;
use skinbox_protocol::wire::{arp, ethernet, icmp, ipv4, udp};

/// Frame positions of the request's Ethernet source, IPv4 source and destination.
const ETHERNET_SOURCE_AT: usize = ethernet::field::SOURCE.start;
const IP_SOURCE_AT: usize = IPV4_AT + ipv4::field::SOURCE.start;
const IP_DESTINATION_AT: usize = IPV4_AT + ipv4::field::DESTINATION.start;
const MAC_LEN: usize = ethernet::field::SOURCE.end - ethernet::field::SOURCE.start;
const IP_LEN: usize = ipv4::field::SOURCE.end - ipv4::field::SOURCE.start;

/// Frame positions (from the destination MAC).
const IP_CHECKSUM_AT: usize = IPV4_AT + IPV4_CHECKSUM.start;
const UDP_CHECKSUM_AT: usize = UDP_AT + UDP_CHECKSUM.start;
/// The acknowledgement's header: the UDP payload.
const ACK_AT: usize = PAYLOAD_AT;
const ACK_BODY_AT: usize = ACK_AT + command::HEADER_LEN;
// The send tick is the tick loaded by `send_tick_now`: the patch starts a clock after the
// take, and two registers later the tick is that of the clock `TAKE_TO_FIRST_BYTE` after it.
const _: () = assert!(TAKE_TO_FIRST_BYTE == 3);

/// Frame position of an acknowledgement's send tick.
pub const SEND_TICK_AT: usize = ACK_BODY_AT + ack_field::SEND_TICK.start;
const REPLY_AT: usize = ACK_BODY_AT + ACK_FIXED_LEN;

/// Clocks from a `start_*` to the first step's ROM word (the step register, the ROM's
/// two-clock read).
const START_TO_STEP: u64 = START_TO_WORD;

/// Steps from the last step summed into a checksum to a step that writes it: the byte is
/// summed after stage 5 and the checksum is final [`CHECKSUM_CLOCKS`] clocks later (at
/// most); the checksum byte is taken in stage 4.
const CHECKSUM_DISTANCE: usize = CHECKSUM_CLOCKS as usize + 1;

/// Where a step's byte comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Source {
    /// The step's value.
    Constant = 0,
    /// The held-field byte the value names ([`field_byte`]).
    Field = 1,
    /// Byte `value & 3` (0 = most significant) of the counter read; byte 0 loads the
    /// counter and reads the next.
    Counter = 2,
    /// A checksum byte: value bit 1 the UDP checksum (else IPv4), bit 0 the low byte.
    Checksum = 3,
}

/// One step of a build program: a ROM word.
#[derive(Debug, Clone, Copy)]
struct Step {
    address: usize,
    value: u8,
    /// The buffer address read (with `from_buffer`).
    read: usize,
    /// The byte is the buffer's at `read` (the source is ignored): a copy, or with
    /// `write` false a byte left in place and summed.
    from_buffer: bool,
    source: Source,
    write: bool,
    sum_ip: bool,
    sum_udp: bool,
    pad: bool,
    end: bool,
}

/// The parts of a ROM word (`reply_sequencer::STEP_BITS`, 35 bits): address 0..8, value
/// 8..16, read 16..24, source 24..26, write 26, sum_ip 27, sum_udp 28, pad 29, end 30,
/// from_buffer 31, and the next step's held-field byte index 32..35 ([`link_steps`]).
const READ_AT: usize = 16;
const SOURCE_AT: usize = 24;
const WRITE_BIT: usize = 26;
const SUM_IP_BIT: usize = 27;
const SUM_UDP_BIT: usize = 28;
const PAD_BIT: usize = 29;
const END_BIT: usize = 30;
const FROM_BUFFER_BIT: usize = 31;
const NEXT_FIELD_BYTE_AT: usize = 32;
// (the sequencer's and the stages' logic spells these bit numbers out)
const _: () = assert!(
    crate::reply_sequencer::STEP_BITS == 35
        && NEXT_FIELD_BYTE_AT == 32
        && READ_AT == 16
        && SOURCE_AT == 24
        && WRITE_BIT == 26
        && SUM_IP_BIT == 27
        && SUM_UDP_BIT == 28
        && PAD_BIT == 29
        && END_BIT == 30
        && FROM_BUFFER_BIT == 31
);

impl Step {
    /// The byte's place in its held-field word, for a held-field step.
    fn field_byte_index(&self) -> Option<u8> {
        (self.source == Source::Field && !self.from_buffer).then_some(self.value % 8)
    }

    fn word(&self) -> u64 {
        assert!(self.address < 256, "step address {}", self.address);
        assert!(self.read < 256, "step read address {}", self.read);
        self.address as u64
            | u64::from(self.value) << 8
            | (self.read as u64) << READ_AT
            | (self.source as u64) << SOURCE_AT
            | u64::from(self.write) << WRITE_BIT
            | u64::from(self.sum_ip) << SUM_IP_BIT
            | u64::from(self.sum_udp) << SUM_UDP_BIT
            | u64::from(self.pad) << PAD_BIT
            | u64::from(self.end) << END_BIT
            | u64::from(self.from_buffer) << FROM_BUFFER_BIT
    }
}

/// Which checksums a written byte is summed into.
#[derive(Clone, Copy)]
enum Sum {
    None,
    Ip,
    Udp,
    Both,
}

/// A build program under construction.
#[derive(Default)]
struct Program {
    steps: Vec<Step>,
    last_summed: Option<usize>,
}

impl Program {
    fn push(&mut self, address: usize, value: u8, source: Source, sum: Sum) {
        let (sum_ip, sum_udp) = match sum {
            Sum::None => (false, false),
            Sum::Ip => (true, false),
            Sum::Udp => (false, true),
            Sum::Both => (true, true),
        };
        if sum_ip || sum_udp {
            self.last_summed = Some(self.steps.len());
        }
        self.steps.push(Step {
            address,
            value,
            read: 0,
            from_buffer: false,
            source,
            write: true,
            sum_ip,
            sum_udp,
            pad: false,
            end: false,
        });
    }

    fn constants(&mut self, at: usize, bytes: &[u8], sum: Sum) {
        for (i, &b) in bytes.iter().enumerate() {
            self.push(at + i, b, Source::Constant, sum);
        }
    }

    fn fields(&mut self, at: usize, first: u8, len: usize, sum: Sum) {
        for i in 0..len {
            self.push(at + i, first + i as u8, Source::Field, sum);
        }
    }

    /// Copies `len` bytes of the request from `from` to `at` (`at == from` and no
    /// `write`: leaves them in place, to be summed).
    fn copy(&mut self, at: usize, from: usize, len: usize, sum: Sum, write: bool) {
        for i in 0..len {
            self.push(at + i, 0, Source::Constant, sum);
            let step = self.steps.last_mut().expect("pushed");
            step.read = from + i;
            step.from_buffer = true;
            step.write = write;
        }
    }

    /// A byte summed into the UDP checksum only (the pseudo header), not written; `at`
    /// says its place in a 16-bit word (even: high byte).
    fn udp_sum_only(&mut self, at: usize, byte: u8) {
        self.push(at, byte, Source::Constant, Sum::Udp);
        self.steps.last_mut().expect("pushed").write = false;
    }

    /// Writes a checksum (`udp` or IPv4) at `at`, after idle steps until it is final.
    fn checksum(&mut self, at: usize, udp: bool) {
        if let Some(last) = self.last_summed {
            while self.steps.len() < last + CHECKSUM_DISTANCE {
                self.steps.push(Step {
                    address: 0,
                    value: 0,
                    read: 0,
                    from_buffer: false,
                    source: Source::Constant,
                    write: false,
                    sum_ip: false,
                    sum_udp: false,
                    pad: false,
                    end: false,
                });
            }
        }
        for low in [false, true] {
            self.push(
                at + usize::from(low),
                u8::from(udp) << 1 | u8::from(low),
                Source::Checksum,
                Sum::None,
            );
        }
    }

    fn end(mut self) -> Vec<Step> {
        // a byte of the request is read before any step writes over it
        for (i, r) in self.steps.iter().enumerate().filter(|(_, r)| r.from_buffer) {
            assert!(
                !self.steps[..i]
                    .iter()
                    .any(|w| w.write && w.address == r.read),
                "step {i} reads byte {} after it was written",
                r.read
            );
        }
        self.steps.push(Step {
            address: 0,
            value: 0,
            read: 0,
            from_buffer: false,
            source: Source::Constant,
            write: false,
            sum_ip: false,
            sum_udp: false,
            pad: false,
            end: true,
        });
        self.steps
    }
}

/// A reply the builder makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplyKind {
    /// ARP reply.
    Arp,
    /// ICMP echo reply.
    Echo,
    /// Command acknowledgement.
    Ack(AckReplyKind),
}

fn arp_program(link: &LinkConfig) -> Vec<Step> {
    let mut p = Program::default();
    let sender_mac = ARP_AT + arp::field::SENDER_MAC.start;
    let sender_ip = ARP_AT + arp::field::SENDER_IP.start;
    let target_mac = ARP_AT + arp::field::TARGET_MAC.start;
    // the requester's addresses (the request's sender) become the Ethernet destination
    // and the target
    let destination_mac = ethernet::field::DESTINATION.start;
    p.copy(destination_mac, sender_mac, MAC_LEN, Sum::None, true);
    p.copy(target_mac, sender_mac, MAC_LEN + IP_LEN, Sum::None, true);
    ethernet_header(&mut p, link, ETHERTYPE_ARP);
    p.constants(ARP_AT, &ARP_REPLY_HEADER, Sum::None);
    p.constants(sender_mac, &link.box_mac, Sum::None);
    p.constants(sender_ip, &link.box_ip, Sum::None);
    let end = ARP_AT + arp::PACKET_LEN;
    p.constants(end, &vec![0; MIN_FRAME_LEN - end], Sum::None);
    p.end()
}

/// The IPv4 header's bytes except the checksum: `total_len` None takes the held total
/// length; the destination is the peer's IP. `peer_sum` says what the peer IP and the box
/// IP are summed into (the UDP pseudo header has them too).
fn ipv4_header(
    p: &mut Program,
    link: &LinkConfig,
    protocol: u8,
    total_len: Option<u16>,
    peer_sum: Sum,
) {
    use ipv4::field;
    let header = {
        let mut b = [0; IPV4_HEADER_LEN];
        box_ipv4_header(protocol, link.box_ip, [0; 4], 0).emit(&mut b);
        b
    };
    // version and IHL, DSCP and ECN
    p.constants(IPV4_AT, &header[..field::TOTAL_LEN.start], Sum::Ip);
    let total_at = IPV4_AT + field::TOTAL_LEN.start;
    match total_len {
        Some(len) => p.constants(total_at, &len.to_be_bytes(), Sum::Ip),
        None => p.copy(total_at, total_at, 2, Sum::Ip, false),
    }
    // identification, flags and fragment offset, TTL, protocol
    let fixed = field::IDENTIFICATION.start..field::CHECKSUM.start;
    p.constants(IPV4_AT + fixed.start, &header[fixed], Sum::Ip);
    p.constants(IP_SOURCE_AT, &header[field::SOURCE], peer_sum);
}

/// The request's sender becomes the destination: the first steps of an IPv4 reply.
fn copy_addresses(p: &mut Program, peer_sum: Sum) {
    let destination_mac = ethernet::field::DESTINATION.start;
    p.copy(
        destination_mac,
        ETHERNET_SOURCE_AT,
        MAC_LEN,
        Sum::None,
        true,
    );
    p.copy(IP_DESTINATION_AT, IP_SOURCE_AT, IP_LEN, peer_sum, true);
}

fn ethernet_header(p: &mut Program, link: &LinkConfig, ethertype: u16) {
    p.constants(ETHERNET_SOURCE_AT, &link.box_mac, Sum::None);
    let ethertype_at = ethernet::field::ETHERTYPE.start;
    p.constants(ethertype_at, &ethertype.to_be_bytes(), Sum::None);
}

fn echo_program(link: &LinkConfig) -> Vec<Step> {
    let mut p = Program::default();
    // the ICMP checksum first: the parser's sum is read before the next frame restarts it
    // ([`echo_fields_read`])
    let checksum_at = ICMP_AT + icmp::field::CHECKSUM.start;
    p.fields(checksum_at, field_byte::ICMP_CHECKSUM, 2, Sum::None);
    copy_addresses(&mut p, Sum::Ip);
    ethernet_header(&mut p, link, ETHERTYPE_IPV4);
    ipv4_header(&mut p, link, IP_PROTOCOL_ICMP, None, Sum::Ip);
    // type and code; the identifier, sequence number and data stay
    p.constants(ICMP_AT, &[ICMP_ECHO_REPLY, 0], Sum::None);
    // zero padding to the minimum frame, written where the request ended before it
    let shortest_end = ICMP_AT + icmp::HEADER_LEN;
    for at in shortest_end..MIN_FRAME_LEN {
        p.constants(at, &[0], Sum::None);
        p.steps.last_mut().expect("pushed").pad = true;
    }
    p.checksum(IP_CHECKSUM_AT, false);
    p.end()
}

fn ack_program(link: &LinkConfig, box_id: u16, port_count: u8, reply: AckReplyKind) -> Vec<Step> {
    let mut p = Program::default();
    let udp_len = (UDP_HEADER_LEN + reply.payload_len()) as u16;
    use command::field;
    // the opcode first (a program's first held field must be at byte 0 of its word:
    // [`link_steps`]), then the command unit's fields: its last accepted sequence number
    // holds from `LAST_ACCEPTED_AFTER_DONE` to `LAST_ACCEPTED_HOLDS` clocks after
    // `start_ack` ([`ack_fields_read`])
    let opcode_at = ACK_BODY_AT + ack_field::OPCODE;
    p.copy(opcode_at, ACK_AT + field::OPCODE, 1, Sum::Udp, true);
    p.fields(
        ACK_BODY_AT + ack_field::RESULT,
        field_byte::RESULT,
        1,
        Sum::Udp,
    );
    let last_accepted = ACK_BODY_AT + ack_field::LAST_ACCEPTED.start;
    p.fields(last_accepted, field_byte::LAST_ACCEPTED, 4, Sum::Udp);
    // the request's fields kept: its sender, source port and opcode are copied, its
    // sequence number and host time stay where they are (the same place in the ack)
    copy_addresses(&mut p, Sum::Both);
    let destination_port = UDP_AT + udp::field::DESTINATION_PORT.start;
    let source_port = UDP_AT + udp::field::SOURCE_PORT.start;
    p.copy(destination_port, source_port, 2, Sum::Udp, true);
    let sequence_at = ACK_AT + field::SEQUENCE.start;
    p.copy(sequence_at, sequence_at, 4, Sum::Udp, false);
    let host_time_at = ACK_AT + field::HOST_TIME.start;
    p.copy(host_time_at, host_time_at, 8, Sum::Udp, false);
    ethernet_header(&mut p, link, ETHERTYPE_IPV4);
    ipv4_header(
        &mut p,
        link,
        IP_PROTOCOL_UDP,
        Some(IPV4_HEADER_LEN as u16 + udp_len),
        Sum::Both,
    );
    // the rest of the pseudo header (zero, protocol, UDP length) is the one word
    // protocol + UDP length; a zero byte adds nothing and takes no step
    let pseudo = u16::from(IP_PROTOCOL_UDP) + udp_len;
    for (at, byte) in pseudo.to_be_bytes().into_iter().enumerate() {
        if byte != 0 {
            p.udp_sum_only(at, byte);
        }
    }
    p.constants(source_port, &link.box_port.to_be_bytes(), Sum::Udp);
    p.constants(UDP_AT + UDP_LEN.start, &udp_len.to_be_bytes(), Sum::Udp);
    // (the UDP checksum and the send tick are written at the take)
    p.constants(ACK_AT + field::MAGIC.start, &MAGIC, Sum::Udp);
    p.constants(ACK_AT + field::VERSION, &[VERSION, KIND_ACK], Sum::Udp);
    p.constants(
        ACK_AT + field::BOX_ID.start,
        &box_id.to_be_bytes(),
        Sum::Udp,
    );
    p.constants(ACK_AT + ack_field::PORT_COUNT, &[port_count, 0], Sum::Udp);
    let body_len = (ACK_FIXED_LEN + reply.len()) as u16;
    p.constants(
        ACK_AT + field::LENGTH.start,
        &body_len.to_be_bytes(),
        Sum::Udp,
    );
    p.constants(ACK_AT + field::RESERVED.start, &[0, 0], Sum::Udp);
    p.constants(ACK_BODY_AT + ack_field::RESERVED.start, &[0, 0], Sum::Udp);
    let receive_tick = ACK_BODY_AT + ack_field::RECEIVE_TICK.start;
    p.fields(receive_tick, field_byte::RECEIVE_TICK, 8, Sum::Udp);
    match reply {
        AckReplyKind::None => {}
        AckReplyKind::Destination => {
            let at = |f: std::ops::Range<usize>| REPLY_AT + f.start;
            p.fields(
                at(destination_field::MAC),
                field_byte::DESTINATION_MAC,
                6,
                Sum::Udp,
            );
            p.fields(
                at(destination_field::IP),
                field_byte::DESTINATION_IP,
                4,
                Sum::Udp,
            );
            p.fields(
                at(destination_field::PORT),
                field_byte::DESTINATION_PORT,
                2,
                Sum::Udp,
            );
        }
        AckReplyKind::Counters => {
            use box_counters::field as block;
            p.fields(REPLY_AT + block::LINK_UP, field_byte::LINK_UP, 1, Sum::Udp);
            p.fields(
                REPLY_AT + block::LINK_SPEED,
                field_byte::LINK_SPEED,
                1,
                Sum::Udp,
            );
            p.constants(REPLY_AT + block::RESERVED.start, &[0, 0], Sum::Udp);
            // counter c is read at address c (the reads start at 0 with the program)
            for counter in BoxCounter::ALL {
                let at = REPLY_AT + counter.bytes().start;
                for k in 0..4 {
                    p.push(at + k, k as u8, Source::Counter, Sum::Udp);
                }
            }
        }
    }
    p.checksum(IP_CHECKSUM_AT, false);
    p.end()
}

/// Writes the send tick and then the UDP checksum (the build summed everything else).
fn patch_program() -> Vec<Step> {
    let mut p = Program::default();
    p.fields(SEND_TICK_AT, field_byte::SEND_TICK, 8, Sum::Udp);
    p.checksum(UDP_CHECKSUM_AT, true);
    p.end()
}

/// Steps of the build program of a reply (its last step the end marker).
fn program(kind: ReplyKind) -> Vec<Step> {
    let link = LinkConfig::DEFAULT;
    match kind {
        ReplyKind::Arp => arp_program(&link),
        ReplyKind::Echo => echo_program(&link),
        ReplyKind::Ack(reply) => ack_program(&link, 0, 1, reply),
    }
}

/// Clocks from `start_echo` (high in clock s) to the last clock in which the echo reply's
/// fields from the parser are read: `ip_total_length` in clock s, `icmp_rest_sum` from
/// clock s + 1 to s + this (a field step's byte is chosen in the clock of its ROM word).
pub fn echo_fields_read() -> u64 {
    let last_field = echo_program(&LinkConfig::DEFAULT)
        .iter()
        .rposition(|s| s.source == Source::Field && !s.from_buffer)
        .expect("the ICMP checksum");
    START_TO_STEP + last_field as u64
}

/// Clocks from `start_ack` (high in clock s) to the first and the last clock in which
/// an acknowledgement reads `last_accepted`: the same for every acknowledgement.
pub fn ack_fields_read() -> (u64, u64) {
    let link = LinkConfig::DEFAULT;
    let program = ack_program(&link, 0, 1, AckReplyKind::None);
    let reads = |s: &Step| {
        s.source == Source::Field
            && (field_byte::LAST_ACCEPTED..field_byte::LAST_ACCEPTED + 4).contains(&s.value)
    };
    let first = program.iter().position(reads);
    let last = program.iter().rposition(reads);
    let (first, last) = first.zip(last).expect("the last accepted sequence number");
    (START_TO_STEP + first as u64, START_TO_STEP + last as u64)
}

/// Clocks from the clock the reply's last body beat is taken to the first clock `locked`
/// is low (the clock after).
pub const UNLOCK_AFTER_LAST_TAKE: u64 = 1;

/// Clocks from a `start_*` (high in clock s) to the descriptor's `valid` (high from clock
/// s + this on). The same for every length of an echo request.
pub fn build_clocks(kind: ReplyKind) -> u64 {
    START_TO_STEP + program(kind).len() as u64
}

/// Clocks from the take (clock T) to the patch's last write (the UDP checksum's low byte
/// is written at the edge ending clock T + this): the registered take, a step's ROM word,
/// then two registers, for every step but the end marker.
pub fn patch_clocks() -> u64 {
    START_TO_STEP + patch_program().len() as u64 + 1
}

/// The earliest clock (counted from the take's) in which the body reader puts the first
/// patched byte's address (the UDP checksum's; the send tick comes after it) on the
/// buffer: the take is registered, the reader starts a clock later and reads from the
/// clock after that, one address per clock from 0.
pub const FIRST_PATCHED_READ: u64 = 3 + UDP_CHECKSUM_AT as u64;

/// Clocks to spare between the patch's last write and the reader's first read of a
/// patched byte, under the fastest take and read (a read sees writes of earlier clocks).
pub fn patch_margin_clocks() -> u64 {
    FIRST_PATCHED_READ - patch_clocks() - 1
}

/// The ROM of every program, with the start address of each.
struct Rom {
    words: Vec<u64>,
    starts: ProgramStarts,
}

/// The ROM words of a program: each step's word carries the held-field byte index of the
/// step after it, which the stages register while the step's word is out, so the field
/// multiplexer's select comes from a register, not from the block RAM. Before a
/// program's first word that register is 0: a program that starts with a held field
/// starts at byte 0 of its word.
fn link_steps(steps: &[Step]) -> Vec<u64> {
    assert!(
        steps[0].field_byte_index().unwrap_or(0) == 0,
        "a program's first held-field byte is not at byte 0 of its word"
    );
    steps
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let next = steps.get(i + 1).and_then(Step::field_byte_index);
            s.word() | u64::from(next.unwrap_or(0)) << NEXT_FIELD_BYTE_AT
        })
        .collect()
}

fn rom(link: &LinkConfig, box_id: u16, port_count: u8) -> Rom {
    let mut words = vec![];
    let mut add = |steps: Vec<Step>| {
        let at = words.len();
        words.extend(link_steps(&steps));
        at
    };
    let arp = add(arp_program(link));
    let echo = add(echo_program(link));
    let ack = [
        AckReplyKind::None,
        AckReplyKind::Destination,
        AckReplyKind::Counters,
    ]
    .map(|r| add(ack_program(link, box_id, port_count, r)));
    let patch = add(patch_program());
    assert!(
        words.len() <= 1 << ROM_ADDRESS_BITS,
        "{} steps",
        words.len()
    );
    Rom {
        words,
        starts: ProgramStarts {
            arp,
            echo,
            ack,
            patch,
        },
    }
}

/// Builds the box's replies in the frame buffer and sends them as raw frames.
#[derive(LogicBlock)]
pub struct ReplyBuilder {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: abandons a reply and unlocks the buffer.
    pub reset: Signal<In, Bit>,
    /// Box time.
    pub tick: Signal<In, Bits<64>>,
    /// The parser writes a received byte (ignored while `locked`).
    pub receive_write_enable: Signal<In, Bit>,
    /// Its frame position.
    pub receive_write_address: Signal<In, Bits<BODY_ADDRESS_BITS>>,
    /// The byte.
    pub receive_write_data: Signal<In, Bits<8>>,
    /// One clock: a reply follows; the buffer is locked from the next clock.
    pub reserve: Signal<In, Bit>,
    /// One clock: build an ARP reply.
    pub start_arp: Signal<In, Bit>,
    /// One clock: build an ICMP echo reply.
    pub start_echo: Signal<In, Bit>,
    /// One clock: build a command acknowledgement.
    pub start_ack: Signal<In, Bit>,
    /// A stored request's last byte arrives: `tick` is its receive tick (held until an
    /// acknowledgement's take; never high from a `reserve` until `locked` falls).
    pub receive_tick_now: Signal<In, Bit>,
    /// The echo request's IPv4 total length (read with `start_echo`).
    pub ip_total_length: Signal<In, Bits<16>>,
    /// Folded ones'-complement sum of the echo request's ICMP message from byte 4 (read
    /// up to [`echo_fields_read`] clocks after `start_echo`).
    pub icmp_rest_sum: Signal<In, Bits<16>>,
    /// The command's result (`AckResult`).
    pub result: Signal<In, Bits<8>>,
    /// The command was an accepted stream-to: the acknowledgement carries the destination.
    pub accepted_stream_to: Signal<In, Bit>,
    /// The command was an accepted status-now: the acknowledgement carries the counters.
    pub accepted_status_now: Signal<In, Bit>,
    /// The last sequence number accepted from the command's sender.
    pub last_accepted: Signal<In, Bits<32>>,
    /// The datagrams' destination now in effect: MAC...
    pub destination_mac: Signal<In, Bits<48>>,
    /// ...IPv4 address...
    pub destination_ip: Signal<In, Bits<32>>,
    /// ...and UDP port.
    pub destination_port: Signal<In, Bits<16>>,
    /// The PHY reports the link up.
    pub link_up: Signal<In, Bit>,
    /// The link speed (`LinkSpeed` wire value).
    pub link_speed: Signal<In, Bits<2>>,
    /// Box counter to read (`BoxCounter` index).
    pub counters_address: Signal<Out, Bits<5>>,
    /// The counter, two clocks after its address.
    pub counters_data: Signal<In, Bits<32>>,
    /// The buffer holds a request or a reply: the parser must not store a frame.
    pub locked: Signal<Out, Bit>,
    /// The replies, raw frames.
    pub replies: DatagramSource,
    buffer: BlockRam<8, BODY_ADDRESS_BITS>,
    reader: BodyReader,
    // the phases and the program ROM
    sequencer: ReplySequencer,
    // the reply's length
    sizing: ReplySizing,
    // the step pipeline: a ROM word's byte written and summed
    stages: ReplyStages,
    // the held fields' byte multiplexer
    fields: ReplyFieldBytes,
    raw_frame_kind: Constant<Bits<8>>,
    locked_now: DFF<Bit>,
    // the patch started a clock ago; two clocks ago: the tick is the send tick now
    patch_started: DFF<Bit>,
    send_tick_now: DFF<Bit>,
    // the request's receive tick, set at its last byte; then the send tick, the tick of
    // the clock `TAKE_TO_FIRST_BYTE` after the take (loaded then: no adder on the tick)
    field_tick: DFF<Bits<64>>,
}

impl ReplyBuilder {
    /// A builder for the box at `link`'s addresses with box id `box_id` and `port_count`
    /// ports (both in acknowledgements).
    pub fn new(link: &LinkConfig, box_id: u16, port_count: u8) -> Self {
        let rom_contents = rom(link, box_id, port_count);
        // the longest reply's UDP part (header and acknowledgement with the counters) and
        // the pseudo header's 12 bytes fit the checksum's UDP sum
        assert!(AckReplyKind::Counters.frame_len() - UDP_AT + 12 <= UDP_SUM_BYTES);
        Self {
            clock: Default::default(),
            reset: Default::default(),
            tick: Default::default(),
            receive_write_enable: Default::default(),
            receive_write_address: Default::default(),
            receive_write_data: Default::default(),
            reserve: Default::default(),
            start_arp: Default::default(),
            start_echo: Default::default(),
            start_ack: Default::default(),
            receive_tick_now: Default::default(),
            ip_total_length: Default::default(),
            icmp_rest_sum: Default::default(),
            result: Default::default(),
            accepted_stream_to: Default::default(),
            accepted_status_now: Default::default(),
            last_accepted: Default::default(),
            destination_mac: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            link_up: Default::default(),
            link_speed: Default::default(),
            counters_address: Default::default(),
            counters_data: Default::default(),
            locked: Default::default(),
            replies: Default::default(),
            buffer: Default::default(),
            reader: Default::default(),
            sequencer: ReplySequencer::new(&rom_contents.words, rom_contents.starts),
            sizing: Default::default(),
            stages: Default::default(),
            fields: Default::default(),
            raw_frame_kind: constant((usize::from(RAW_FRAME_KIND)) as u64),
            locked_now: Default::default(),
            patch_started: Default::default(),
            send_tick_now: Default::default(),
            field_tick: Default::default(),
        }
    }
}

impl Logic for ReplyBuilder {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            locked_now,
            patch_started,
            send_tick_now,
            field_tick
        );
        self.buffer.clock.next = self.clock.val();
        self.reader.clock.next = self.clock.val();
        self.reader.reset.next = self.reset.val();

        // The phases: a start (only when no reply is under way) runs its program, one ROM
        // word per clock; then the descriptor is offered; at its take an acknowledgement's
        // patch runs.
        self.sequencer.clock.next = self.clock.val();
        self.sequencer.reset.next = self.reset.val();
        self.sequencer.start_arp.next = self.start_arp.val();
        self.sequencer.start_echo.next = self.start_echo.val();
        self.sequencer.start_ack.next = self.start_ack.val();
        self.sequencer.accepted_stream_to.next = self.accepted_stream_to.val();
        self.sequencer.accepted_status_now.next = self.accepted_status_now.val();
        self.sequencer.reader_busy.next = self.reader.busy.val();
        self.sequencer.ready.next = self.replies.ready.val();
        // The reply's length, a clock after the start from its registered kind.
        self.sizing.clock.next = self.clock.val();
        self.sizing.reset.next = self.reset.val();
        self.sizing.start.next = self.sequencer.starting.val();
        self.sizing.start_arp.next = self.start_arp.val();
        self.sizing.start_echo.next = self.start_echo.val();
        self.sizing.accepted_stream_to.next = self.accepted_stream_to.val();
        self.sizing.accepted_status_now.next = self.accepted_status_now.val();
        self.sizing.ip_total_length.next = self.ip_total_length.val();

        // The step pipeline: each ROM word's byte (a constant, a held field's byte, a
        // counter byte, a checksum byte or a copy from the buffer) written and summed.
        self.stages.clock.next = self.clock.val();
        self.stages.reset.next = self.reset.val();
        self.stages.restart.next = self.sequencer.starting.val();
        self.stages.word_valid.next = self.sequencer.word_valid.val();
        self.stages.word.next = self.sequencer.word.val();
        self.stages.frame_end.next = self.sizing.frame_end.val();
        self.stages.buffer_data.next = self.buffer.read_data.val();
        self.stages.counters_data.next = self.counters_data.val();
        self.stages.field_byte.next = self.fields.field_byte.val();
        self.counters_address.next = self.stages.counters_address.val();
        // (the held fields' byte: each word's byte in stage 3, the word in stage 4)
        self.fields.clock.next = self.clock.val();
        self.fields.byte_index.next = self.stages.field_byte_index.val();
        self.fields.word_index.next = self.stages.field_word_index.val();
        self.fields.destination_mac.next = self.destination_mac.val();
        self.fields.destination_port.next = self.destination_port.val();
        self.fields.destination_ip.next = self.destination_ip.val();
        self.fields.last_accepted.next = self.last_accepted.val();
        self.fields.tick.next = self.field_tick.q.val();
        self.fields.icmp_rest_sum.next = self.icmp_rest_sum.val();
        self.fields.result.next = self.result.val();
        self.fields.link_up.next = self.link_up.val();
        self.fields.link_speed.next = self.link_speed.val();
        // the buffer: the parser's writes unless locked, the steps' writes
        self.buffer.write_enable.next = self.receive_write_enable.val() & !self.locked_now.q.val();
        self.buffer.write_address.next = self.receive_write_address.val();
        self.buffer.write_data.next = self.receive_write_data.val();
        if self.stages.write.val() {
            self.buffer.write_enable.next = true;
            self.buffer.write_address.next =
                bit_cast::<BODY_ADDRESS_BITS, 8>(self.stages.write_address.val());
            self.buffer.write_data.next = self.stages.write_data.val();
        }

        // The descriptor; a clock after its take the reader starts and an
        // acknowledgement's patch, with the send tick.
        self.replies.valid.next = self.sequencer.offering.val();
        self.replies.kind.next = self.raw_frame_kind.val();
        self.replies.flags.next = 0.into();
        self.replies.entry_count.next = 0.into();
        self.replies.base_tick.next = 0.into();
        self.replies.body_len.next = self.sizing.body_len.val();
        self.replies.body_sum.next = 0.into();
        self.reader.start.next = self.sequencer.took.val();
        self.reader.length.next = self.sizing.body_len.val();
        // (the patch starts a clock after the take: the send tick is two clocks later)
        self.patch_started.d.next = self.sequencer.patch_starts.val();
        self.send_tick_now.d.next = self.patch_started.q.val();
        if self.receive_tick_now.val() | self.send_tick_now.q.val() {
            self.field_tick.d.next = self.tick.val();
        }

        // The body, straight from the reader.
        // (the reader reads from the clock after the take on; a build reads before)
        self.buffer.read_address.next = self.reader.read_address.val();
        if !self.reader.busy.val() {
            self.buffer.read_address.next =
                bit_cast::<BODY_ADDRESS_BITS, 8>(self.stages.read_address.val());
        }
        self.reader.read_data.next = self.buffer.read_data.val();
        self.replies.body.valid.next = self.reader.body.valid.val();
        self.replies.body.data.next = self.reader.body.data.val();
        self.replies.body.last.next = self.reader.body.last.val();
        self.replies.body.error.next = self.reader.body.error.val();
        self.reader.body.ready.next = self.replies.body.ready.val();

        // Locked from the clock after `reserve` until the clock after the last beat moved.
        self.locked.next = self.locked_now.q.val();
        if self.reader.body.valid.val()
            & self.reader.body.last.val()
            & self.replies.body.ready.val()
        {
            self.locked_now.d.next = false;
        }
        if self.reserve.val() {
            self.locked_now.d.next = true;
        }
        if self.reset.val() {
            self.locked_now.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use etherparse::{
        ArpPacket, Icmpv4Type, NetHeaders, PacketBuilder, PacketHeaders, TransportHeader,
    };
    use skinbox_protocol::box_counters::{BoxCounters, LinkSpeed};
    use skinbox_protocol::command::{
        AckReply, AckRepr, AckResult, CommandRepr, Destination, Opcode, Request,
    };

    const BOX_ID: u16 = 0x0102;
    const PORTS: u8 = 8;
    const PEER_MAC: [u8; 6] = [0x3C, 0x7C, 0x3F, 0x01, 0x02, 0x03];
    const PEER_IP: [u8; 4] = [192, 0, 2, 77];

    fn number(bytes: &[u8]) -> u64 {
        bytes.iter().fold(0, |n, &b| n << 8 | u64::from(b))
    }

    /// Folded ones'-complement sum of big-endian words, odd length padded (RFC 1071).
    fn ones_sum(bytes: &[u8]) -> u16 {
        let mut sum: u64 = bytes
            .chunks(2)
            .map(|w| u64::from(w[0]) << 8 | u64::from(*w.get(1).unwrap_or(&0)))
            .sum();
        while sum > 0xFFFF {
            sum = (sum & 0xFFFF) + (sum >> 16);
        }
        sum as u16
    }

    /// What the test drives besides the request: the parser's and the command unit's
    /// held fields, the run-time destination, the link and the box counters.
    #[derive(Clone)]
    struct Held {
        peer_port: u16,
        ip_total_length: u16,
        icmp_rest_sum: u16,
        command: Option<CommandRepr>,
        opcode: u8,
        result: AckResult,
        last_accepted: u32,
        receive_tick: u64,
        destination: Destination,
        counters: BoxCounters,
    }

    impl Held {
        fn new(rng: &mut TestRng) -> Held {
            let mut counts = [0u32; BoxCounter::ALL.len()];
            for c in &mut counts {
                *c = rng.next_u64() as u32;
            }
            Held {
                peer_port: rng.next_u64() as u16,
                ip_total_length: 0,
                icmp_rest_sum: 0,
                command: None,
                opcode: 0,
                result: AckResult::Ok,
                last_accepted: rng.next_u64() as u32,
                receive_tick: rng.next_u64() >> 8,
                destination: Destination {
                    mac: [0x02, 0, 0, 0, rng.byte(), rng.byte()],
                    ip: [10, rng.byte(), rng.byte(), rng.byte()],
                    port: rng.next_u64() as u16,
                },
                counters: BoxCounters {
                    link_up: rng.chance(0.5),
                    link_speed: [
                        LinkSpeed::Mbit10,
                        LinkSpeed::Mbit100,
                        LinkSpeed::Mbit1000,
                        LinkSpeed::Unknown,
                    ][(rng.next_u64() % 4) as usize],
                    counts,
                },
            }
        }
    }

    /// What one reply run saw.
    struct Run {
        frame: Vec<u8>,
        tick_at_take: u64,
        build_clocks: u64,
        /// Clocks from the take to the last write of a patched byte, and to the first read
        /// of one (fastest take and read only).
        last_patch_write: Option<u64>,
        first_patched_read: Option<u64>,
    }

    /// Writes `request` through the receive port, sets the held fields, reserves and
    /// starts; takes the descriptor after a random delay (none with `fastest`) and reads
    /// the body with random `ready` (always with `fastest`). Meanwhile the receive port
    /// writes garbage (the buffer is locked), the echo fields change after
    /// [`echo_fields_read`] clocks and the last accepted sequence number after
    /// [`ack_fields_read`], and `locked` is checked clock by clock.
    fn run(kind: ReplyKind, request: &[u8], held: &Held, seed: u64, fastest: bool) -> Run {
        let link = LinkConfig::DEFAULT;
        let mut rng = TestRng::new(seed);
        let mut bench = Bench::new(ReplyBuilder::new(&link, BOX_ID, PORTS), |b| &mut b.clock);
        let tick_base = rng.next_u64() >> 4;
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for (a, &b) in request.iter().enumerate() {
            let last = a + 1 == request.len();
            bench.uut.receive_write_enable.next = true;
            bench.uut.receive_write_address.next = (a as u64).into();
            bench.uut.receive_write_data.next = u64::from(b).into();
            // (the parser's signal comes with the byte before it is written)
            bench.uut.receive_tick_now.next = last;
            bench.uut.tick.next = if last {
                held.receive_tick
            } else {
                rng.next_u64()
            }
            .into();
            bench.cycle();
            assert!(!bench.uut.locked.val());
        }
        bench.uut.receive_write_enable.next = false;
        bench.uut.receive_tick_now.next = false;
        let u = &mut bench.uut;
        u.ip_total_length.next = u64::from(held.ip_total_length).into();
        u.icmp_rest_sum.next = u64::from(held.icmp_rest_sum).into();
        u.result.next = u64::from(held.result as u8).into();
        let accepted = |opcode: Opcode| held.opcode == opcode as u8 && held.result == AckResult::Ok;
        u.accepted_stream_to.next = accepted(Opcode::StreamTo);
        u.accepted_status_now.next = accepted(Opcode::StatusNow);
        u.last_accepted.next = u64::from(held.last_accepted).into();
        u.destination_mac.next = number(&held.destination.mac).into();
        u.destination_ip.next = number(&held.destination.ip).into();
        u.destination_port.next = u64::from(held.destination.port).into();
        u.link_up.next = held.counters.link_up;
        u.link_speed.next = u64::from(held.counters.link_speed as u8).into();
        for _ in 0..rng.next_u64() % 3 {
            bench.cycle();
        }
        bench.uut.reserve.next = true;
        bench.cycle();
        bench.uut.reserve.next = false;
        assert!(bench.uut.locked.val(), "locked the clock after reserve");
        bench.cycle();
        match kind {
            ReplyKind::Arp => bench.uut.start_arp.next = true,
            ReplyKind::Echo => bench.uut.start_echo.next = true,
            ReplyKind::Ack(_) => bench.uut.start_ack.next = true,
        }
        let start = bench.cycles;
        let take_delay = if fastest { 0 } else { rng.next_u64() % 20 };
        let take_p = if fastest {
            1.0
        } else {
            [1.0, 0.7, 0.2][(seed % 3) as usize]
        };
        let mut counter_addresses = [0usize; 2];
        let mut valid_at = None;
        let mut take_at = None;
        let mut tick_at_take = 0;
        let mut frame = vec![];
        let mut last_patch_write = None;
        let mut first_patched_read = None;
        let patched = |a: usize| {
            (UDP_CHECKSUM_AT..UDP_CHECKSUM_AT + 2).contains(&a)
                || (SEND_TICK_AT..SEND_TICK_AT + 8).contains(&a)
        };
        loop {
            let clock = bench.cycles;
            let u = &mut bench.uut;
            u.tick.next = (tick_base + clock).into();
            // the parser's echo fields change with the next frame, the last accepted
            // sequence number with the next command's sender, and it is right only from
            // a clock after `start_ack` (the command unit's `done`)
            if clock > start + echo_fields_read() {
                u.ip_total_length.next = u64::from(rng.next_u64() as u16).into();
                u.icmp_rest_sum.next = u64::from(rng.next_u64() as u16).into();
            }
            let (first_read, last_read) = ack_fields_read();
            if clock > start + last_read || (start..start + first_read).contains(&clock) {
                u.last_accepted.next = u64::from(rng.next_u64() as u32).into();
            } else {
                u.last_accepted.next = u64::from(held.last_accepted).into();
            }
            u.counters_data.next = u64::from(held.counters.counts[counter_addresses[0]]).into();
            // the parser keeps writing: the lock must keep it out
            u.receive_write_enable.next = rng.chance(0.5);
            u.receive_write_address.next = (rng.next_u64() % 256).into();
            u.receive_write_data.next = u64::from(rng.byte()).into();
            let take = rng.chance(take_p);
            let offered_for = valid_at.map_or(0, |v| clock - v);
            // (as the arbiter: no descriptor taken while the body is open)
            u.replies.ready.next =
                take_at.is_none() && valid_at.is_some() && offered_for >= take_delay && take;
            u.replies.body.ready.next = take;
            bench.settle();
            let u = &bench.uut;
            assert!(u.locked.val(), "locked until the last beat was taken");
            if let Some(t) = take_at {
                assert!(
                    !u.replies.valid.val() || clock == t + 1,
                    "the offer ends the clock after the take"
                );
            }
            if u.replies.valid.val() {
                valid_at.get_or_insert(clock);
                assert_eq!(u.replies.kind.val().to_u8(), RAW_FRAME_KIND);
                if u.replies.ready.val() {
                    assert!(take_at.is_none(), "one descriptor");
                    take_at = Some(clock);
                    tick_at_take = tick_base + clock;
                }
            }
            if let Some(t) = take_at {
                if u.buffer.write_enable.val() && patched(u.buffer.write_address.val().index()) {
                    last_patch_write = Some(clock - t);
                }
                if u.reader.busy.val() && patched(u.buffer.read_address.val().index()) {
                    first_patched_read.get_or_insert(clock - t);
                }
            }
            // while locked only the builder writes
            assert!(
                !u.buffer.write_enable.val() || u.stages.write.val(),
                "clock {clock}"
            );
            let beat = u.replies.body.valid.val() && u.replies.body.ready.val();
            let last = beat && u.replies.body.last.val();
            if beat {
                assert!(take_at.is_some(), "no body before the take");
                frame.push(u.replies.body.data.val().to_u8());
                assert_eq!(last, frame.len() == u.replies.body_len.val().index());
            }
            counter_addresses = [counter_addresses[1], u.counters_address.val().index() % 20];
            bench.cycle();
            let u = &mut bench.uut;
            u.start_arp.next = false;
            u.start_echo.next = false;
            u.start_ack.next = false;
            if last {
                break;
            }
            assert!(clock - start < 10_000, "no reply");
        }
        assert!(!bench.uut.locked.val(), "unlocked after the last beat");
        Run {
            frame,
            tick_at_take,
            build_clocks: valid_at.expect("offered") - start,
            last_patch_write,
            first_patched_read,
        }
    }

    fn check_ipv4(frame: &[u8], protocol: u8) -> (PacketHeaders<'_>, etherparse::Ipv4Header) {
        let headers = PacketHeaders::from_ethernet_slice(frame).expect("an Ethernet frame");
        let eth = headers
            .link
            .clone()
            .unwrap()
            .ethernet2()
            .expect("Ethernet II");
        assert_eq!(eth.source, link().box_mac);
        assert_eq!(eth.destination, PEER_MAC);
        let Some(NetHeaders::Ipv4(ip, ext)) = &headers.net else {
            panic!("IPv4")
        };
        assert!(ext.is_empty());
        assert_eq!(ip.protocol.0, protocol);
        assert_eq!(ip.source, link().box_ip);
        assert_eq!(ip.destination, PEER_IP);
        assert_eq!(
            (ip.identification, ip.dont_fragment, ip.more_fragments),
            (0, true, false)
        );
        assert_eq!(ip.time_to_live, IPV4_TTL);
        assert_eq!(
            ip.header_checksum,
            ip.calc_header_checksum(),
            "IPv4 checksum"
        );
        // and with our own sum
        assert_eq!(ones_sum(&frame[IPV4_AT..IPV4_AT + IPV4_HEADER_LEN]), 0xFFFF);
        let ip = ip.clone();
        (headers, ip)
    }

    fn link() -> LinkConfig {
        LinkConfig::DEFAULT
    }

    fn arp_request(rng: &mut TestRng) -> Vec<u8> {
        let mut f = vec![0xFF; 6];
        f.extend(PEER_MAC);
        f.extend(ETHERTYPE_ARP.to_be_bytes());
        f.extend([0, 1, 8, 0, 6, 4, 0, 1]);
        f.extend(PEER_MAC);
        f.extend(PEER_IP);
        f.extend([0; 6]);
        f.extend(link().box_ip);
        f.extend((0..22).map(|_| rng.byte()));
        f
    }

    #[test]
    fn arp_replies_answer_the_requester() {
        for seed in 0..6 {
            let mut rng = TestRng::new(seed);
            let held = Held::new(&mut rng);
            let request = arp_request(&mut rng);
            let r = run(ReplyKind::Arp, &request, &held, seed, seed == 0);
            assert_eq!(r.build_clocks, build_clocks(ReplyKind::Arp));
            assert_eq!(r.frame.len(), MIN_FRAME_LEN);
            let (eth, rest) = etherparse::Ethernet2Header::from_slice(&r.frame).unwrap();
            assert_eq!(eth.destination, PEER_MAC);
            assert_eq!(eth.source, link().box_mac);
            assert_eq!(eth.ether_type.0, ETHERTYPE_ARP);
            let arp = ArpPacket::from_slice(rest).unwrap();
            let arp = arp.try_eth_ipv4().expect("Ethernet/IPv4 ARP");
            assert_eq!(arp.operation, etherparse::ArpOperation::REPLY);
            assert_eq!(arp.sender_mac, link().box_mac);
            assert_eq!(arp.sender_ipv4, link().box_ip);
            assert_eq!(arp.target_mac, PEER_MAC);
            assert_eq!(arp.target_ipv4, PEER_IP);
            assert!(
                r.frame[ETHERNET_HEADER_LEN + 28..].iter().all(|&b| b == 0),
                "padding"
            );
        }
    }

    #[test]
    fn echo_replies_of_every_edge_length_carry_the_data_and_zero_padding() {
        for (k, data_len) in [0usize, 1, 17, 18, 1472].into_iter().enumerate() {
            for fastest in [true, false] {
                let seed = k as u64 * 2 + u64::from(fastest);
                let mut rng = TestRng::new(seed);
                let mut held = Held::new(&mut rng);
                let data: Vec<u8> = (0..data_len).map(|_| rng.byte()).collect();
                let (id, seq) = (rng.next_u64() as u16, rng.next_u64() as u16);
                let mut request = vec![];
                PacketBuilder::ethernet2(PEER_MAC, link().box_mac)
                    .ipv4(PEER_IP, link().box_ip, 55)
                    .icmpv4_echo_request(id, seq)
                    .write(&mut request, &data)
                    .unwrap();
                // a short request's padding is not zero, then the FCS (any bytes here)
                while request.len() < MIN_FRAME_LEN {
                    request.push(0xA5);
                }
                request.extend([0x11, 0x22, 0x33, 0x44]);
                let icmp = &request[ICMP_AT..ICMP_AT + 8 + data_len];
                held.ip_total_length = (IPV4_HEADER_LEN + 8 + data_len) as u16;
                held.icmp_rest_sum = ones_sum(&icmp[4..]);
                let r = run(ReplyKind::Echo, &request, &held, seed, fastest);
                assert_eq!(r.build_clocks, build_clocks(ReplyKind::Echo), "{data_len}");
                let end = ICMP_AT + 8 + data_len;
                assert_eq!(r.frame.len(), end.max(MIN_FRAME_LEN), "{data_len}");
                let (headers, ip) = check_ipv4(&r.frame, IP_PROTOCOL_ICMP);
                assert_eq!(usize::from(ip.total_len), end - IPV4_AT);
                let Some(TransportHeader::Icmpv4(h)) = &headers.transport else {
                    panic!("ICMP")
                };
                let Icmpv4Type::EchoReply(echo) = h.icmp_type else {
                    panic!("an echo reply: {:?}", h.icmp_type)
                };
                assert_eq!((echo.id, echo.seq), (id, seq));
                assert_eq!(h.checksum, h.icmp_type.calc_checksum(&data), "{data_len}");
                assert_eq!(ones_sum(&r.frame[ICMP_AT..end]), 0xFFFF, "ICMP checksum");
                assert_eq!(&r.frame[ICMP_AT + 8..end], data);
                assert!(r.frame[end..].iter().all(|&b| b == 0), "padding {data_len}");
            }
        }
    }

    fn command_frame(c: &CommandRepr, port: u16) -> Vec<u8> {
        let mut f = vec![];
        PacketBuilder::ethernet2(PEER_MAC, link().box_mac)
            .ipv4(PEER_IP, link().box_ip, 64)
            .udp(port, link().box_port)
            .write(&mut f, &c.to_bytes())
            .unwrap();
        f.extend([0; 4]);
        f
    }

    /// Acknowledgements of every result and reply, read back by the protocol crate.
    #[test]
    fn acknowledgements_carry_every_field_and_their_send_tick() {
        let cases = [
            (
                Request::StreamTo { to: None },
                AckResult::Ok,
                AckReplyKind::Destination,
            ),
            (Request::StatusNow, AckResult::Ok, AckReplyKind::Counters),
            (
                Request::SetFlushTimeout { ticks: 99 },
                AckResult::Ok,
                AckReplyKind::None,
            ),
            (Request::StatusNow, AckResult::Replay, AckReplyKind::None),
            (
                Request::StreamTo { to: None },
                AckResult::OtherBox,
                AckReplyKind::None,
            ),
            (
                Request::ReadTick,
                AckResult::BadArgument,
                AckReplyKind::None,
            ),
        ];
        for (k, (request, result, reply)) in cases.into_iter().enumerate() {
            for fastest in [true, false] {
                let seed = 100 + k as u64 * 2 + u64::from(fastest);
                let mut rng = TestRng::new(seed);
                let mut held = Held::new(&mut rng);
                let command = CommandRepr {
                    box_id: BOX_ID,
                    sequence: rng.next_u64() as u32,
                    host_time: rng.next_u64(),
                    request,
                };
                held.opcode = request.opcode() as u8;
                held.result = result;
                held.command = Some(command);
                // the command unit's rule: every result but a replay and another box's takes
                // the command's sequence number
                if !matches!(result, AckResult::Replay | AckResult::OtherBox) {
                    held.last_accepted = command.sequence;
                }
                let frame = command_frame(&command, held.peer_port);
                let kind = ReplyKind::Ack(reply);
                let r = run(kind, &frame, &held, seed, fastest);
                assert_eq!(r.build_clocks, build_clocks(kind), "{k}");
                assert_eq!(r.frame.len(), reply.frame_len());
                let (headers, ip) = check_ipv4(&r.frame, IP_PROTOCOL_UDP);
                let Some(TransportHeader::Udp(udp)) = &headers.transport else {
                    panic!("UDP")
                };
                let payload = headers.payload.slice();
                assert_eq!(
                    (udp.source_port, udp.destination_port),
                    (link().box_port, held.peer_port)
                );
                assert_eq!(usize::from(udp.length), UDP_HEADER_LEN + payload.len());
                assert_eq!(
                    udp.checksum,
                    udp.calc_checksum_ipv4(&ip, payload).unwrap(),
                    "UDP checksum {k}"
                );
                let ack = skinbox_protocol::command::Ack::new_checked(payload).expect("an ack");
                assert_eq!(ack.send_tick(), r.tick_at_take + TAKE_TO_FIRST_BYTE);
                let expected = AckRepr {
                    box_id: BOX_ID,
                    port_count: PORTS,
                    sequence: command.sequence,
                    host_time: command.host_time,
                    opcode: held.opcode,
                    result,
                    last_accepted: held.last_accepted,
                    receive_tick: held.receive_tick,
                    send_tick: r.tick_at_take + TAKE_TO_FIRST_BYTE,
                    reply: match reply {
                        AckReplyKind::None => AckReply::None,
                        AckReplyKind::Destination => AckReply::Destination(held.destination),
                        AckReplyKind::Counters => AckReply::Counters(held.counters),
                    },
                };
                assert_eq!(AckRepr::parse(payload).expect("parses"), expected, "{k}");
                assert_eq!(payload, expected.to_bytes());
                if fastest {
                    let write = r.last_patch_write.expect("patched");
                    let read = r.first_patched_read.expect("read");
                    assert_eq!(write, patch_clocks());
                    assert_eq!(read, FIRST_PATCHED_READ);
                    assert!(write < read, "patch done before the reader reaches it");
                    assert_eq!(read - write - 1, patch_margin_clocks());
                }
            }
        }
    }

    /// The command unit's last accepted sequence number holds while an acknowledgement
    /// reads it.
    #[test]
    fn the_last_accepted_sequence_number_holds_while_it_is_read() {
        use crate::command_unit::{LAST_ACCEPTED_AFTER_DONE, LAST_ACCEPTED_HOLDS};
        let (first, last) = ack_fields_read();
        assert!(
            first >= LAST_ACCEPTED_AFTER_DONE && last < LAST_ACCEPTED_HOLDS,
            "{first} {last}"
        );
    }

    #[test]
    fn build_durations_and_margin() {
        // the figures of the module doc
        let clocks = [
            ReplyKind::Arp,
            ReplyKind::Echo,
            ReplyKind::Ack(AckReplyKind::None),
            ReplyKind::Ack(AckReplyKind::Destination),
            ReplyKind::Ack(AckReplyKind::Counters),
        ]
        .map(build_clocks);
        assert_eq!(clocks, [64, 60, 90, 102, 174]);
        assert_eq!((patch_clocks(), patch_margin_clocks()), (20, 22));
    }

    #[test]
    fn verilog_lints_clean() {
        let mut uut = ReplyBuilder::new(&LinkConfig::DEFAULT, BOX_ID, PORTS);
        uut.connect_all();
        let text = generate_verilog(&uut);
        let dir = std::env::temp_dir().join(format!("skinbox-reply-lint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&text, &dir).expect("verilator runs");
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}

//! The timing contract between the gateware and its models: every latency of the box's
//! register structure the models use, in clocks of the 125 MHz box clock (one clock is one
//! box tick, 8 ns), and the sizes that timing depends on.
//!
//! The numbers are written here so that the contract reads in one place; the gateware
//! defines each one again where it is built, and the tests at the end of this module hold
//! the two equal, so that a change on either side fails a test until both agree. The
//! latencies that depend on the box's parameters (baud, ports) are the gateware's own
//! functions, re-exported here.
//!
//! "Clock `c`" is the clock period ending at rising edge `c`; "cycle" counts clocks from
//! the start of a run, when reset is asserted; "tick" counts from tick 0
//! ([`TICK_ZERO_CYCLE`]).

// ---- reset and start ----

/// Clocks a run holds the box's `reset` pin high before releasing it (the harness and the
/// reference model start every run so).
pub const RESET_CYCLES: u64 = 4;

/// Clocks from the `reset` pin going low to the blocks leaving reset (one register): box
/// tick 0 is the clock `RESET_LATENCY` after the pin goes low
/// (`interface_box::RESET_LATENCY`).
pub const RESET_LATENCY: u64 = 1;

/// The cycle of box tick 0: the reset and the reset register. A stamp of tick `t` means
/// the edge of cycle `t + TICK_ZERO_CYCLE`.
pub const TICK_ZERO_CYCLE: u64 = RESET_CYCLES + RESET_LATENCY;

/// Clocks the port counter file clears its memory after tick 0 (`ready` low), one address
/// per clock (`counter_file::CLEAR_CLOCKS`).
pub const PORT_COUNTERS_CLEAR_CLOCKS: u64 = 512;

/// The first cycle the box's ports see their pins: after tick 0, the port counters'
/// clearing and a clock. A packet whose start edge comes earlier is cut: the box sees only
/// its tail.
pub const PORTS_READY_CYCLE: u64 = TICK_ZERO_CYCLE + PORT_COUNTERS_CLEAR_CLOCKS + 1;

// ---- uplink: ports, packet store, counters ----

/// Clocks from a port's visit by the deframing engine to the clock of the engine's decision
/// about it (`cell_deframer::DECISION_CLOCKS`).
pub const DEFRAMER_DECISION_CLOCKS: u64 = 3;

/// Edges from the clock a counter increment is offered to the edge that writes it: a read
/// whose address is taken at a later edge sees the new value
/// (`counter_file::INCREMENT_WRITE_EDGE`).
pub const INCREMENT_WRITE_EDGE: u64 = 4;

/// Clocks from a datagram source's `valid` to the datagram arbiter offering its descriptor
/// to the transmitter (`datagram_arbiter::OFFER_LATENCY`).
pub const ARBITER_OFFER_LATENCY: u64 = 1;

// ---- transmitter ----

/// Clocks from the clock the transmitter takes a descriptor to the clock the frame's first
/// preamble byte is on `gmii_txd` (`frame_transmitter::TAKE_TO_FIRST_BYTE`).
pub const TAKE_TO_FIRST_BYTE: u64 = 3;

/// Clocks from the clock a raw frame's descriptor (a reply's) is taken to the clock its
/// first body beat is taken: the preamble and SFD, then one beat per clock
/// (`frame_transmitter::TAKE_TO_RAW_BODY`).
pub const TAKE_TO_RAW_BODY: u64 = 9;

/// Byte of a datagram frame, counted from its first preamble byte, where the datagram
/// body starts (preamble, Ethernet, IPv4, UDP and box headers); the transmitter takes body
/// beats from that clock on (`frame_transmitter::BODY_START`).
pub const BODY_START: u64 = 74;

// ---- status reporter ----

/// Clocks per 32-bit word of a status body: the address, the memory read, its register,
/// the word into the shift register, four bytes out (`status_reporter::CLOCKS_PER_WORD`).
pub const STATUS_CLOCKS_PER_WORD: u64 = 7;

/// Clock of a status word, from its first, in which the reporter takes the batcher's
/// counts; counters come from the memory, read at the address of the word's first clock
/// (`status_reporter::WORD_VALUE_CLOCK`).
pub const STATUS_WORD_VALUE_CLOCK: u64 = 1;

/// Words of a status page before the port counters: boot id, datagrams, records, first
/// port (`status_reporter::HEADER_WORDS`).
pub const STATUS_HEADER_WORDS: usize = 4;

/// Words of the box counter block after a status datagram's port counters
/// (`status_reporter::BOX_COUNTER_WORDS`).
pub const STATUS_BOX_COUNTER_WORDS: usize = 21;

// ---- receive path ----

/// Clocks from a byte on `gmii_rxd` (sampled at rising edge `k`) to its beat out of the
/// MAC: valid after edge `k + MAC_LATENCY` (`mac_receiver::MAC_LATENCY`).
pub const MAC_LATENCY: u64 = 2;

/// Clocks from the edge that samples a received frame's last byte to the clock whose tick
/// is the frame's receive tick, the tick a command's acknowledgement carries
/// (`interface_box::RECEIVE_TICK_LAG`).
pub const RECEIVE_TICK_LAG: u64 = 2;

/// Clocks from the frame parser's last beat of a frame (clock `c`) to its `decided` (high
/// in clock `c + PARSER_DECISION_LATENCY`) (`frame_parser::DECISION_LATENCY`).
pub const PARSER_DECISION_LATENCY: u64 = 6;

/// Clocks from the command unit's `command` to its `done`, the clock its registers hold
/// the new configuration (`command_unit::COMMAND_LATENCY`).
pub const COMMAND_LATENCY: u64 = 4;

/// Clocks from the command unit's `command` to its `downlink_offer`, the clock a cell
/// command is offered to the downlink (`command_unit::DOWNLINK_OFFER_AFTER_COMMAND`).
pub const DOWNLINK_OFFER_AFTER_COMMAND: u64 = 3;

/// Clocks from a command's receive tick to the clock in which the command unit offers a
/// cell command to the downlink: the parser's decision, then the command unit's pipeline
/// up to the clock before `done`.
pub const DOWNLINK_OFFER_AFTER_RECEIVE_TICK: u64 =
    PARSER_DECISION_LATENCY + DOWNLINK_OFFER_AFTER_COMMAND;

/// Clocks from a `count` of the box counter file (high in clock `c`) to the first clock
/// whose read sees `frames_received` counted
/// (`box_counter_file::FRAMES_RECEIVED_VISIBLE_AFTER`).
pub const FRAMES_RECEIVED_VISIBLE_AFTER: u64 = 4;

/// As [`FRAMES_RECEIVED_VISIBLE_AFTER`], for the counter of the frame's fate, read a clock
/// later (`box_counter_file::FATE_VISIBLE_AFTER`).
pub const FATE_VISIBLE_AFTER: u64 = 5;

/// Clocks the reply builder takes to build an ARP reply, from the clock it starts to the
/// clock the reply is ready (`reply_builder::build_clocks(ReplyKind::Arp)`).
pub const BUILD_ARP_CLOCKS: u64 = 64;

/// As [`BUILD_ARP_CLOCKS`], for an ICMP echo reply.
pub const BUILD_ECHO_CLOCKS: u64 = 60;

/// As [`BUILD_ARP_CLOCKS`], for a command acknowledgement carrying nothing after its fixed
/// body, a destination (stream-to) and the box counter block (status-now), in that order.
pub const BUILD_ACK_CLOCKS: [u64; 3] = [90, 102, 174];

/// Clocks from the clock the transmitter takes a reply's last body beat to the first clock
/// the reply builder is unlocked (`reply_builder::UNLOCK_AFTER_LAST_TAKE`).
pub const UNLOCK_AFTER_LAST_TAKE: u64 = 1;

// ---- downlink ----

/// Clocks from a downlink port's refill visit to its byte register: the read position RAM,
/// then the queue RAM, each two clocks, and the load (`cell_downlink::REFILL_LATENCY`).
pub const DOWNLINK_REFILL_LATENCY: u64 = 5;

// ---- sizes the timing depends on ----

/// Packets a port's buffer in the packet store holds (`geometry::SLOTS`).
pub const SLOTS: usize = 2;

/// Entries of the FIFO between the packet store's reader and the framer
/// (`packet_store::FIFO_DEPTH`).
pub const STORE_FIFO_DEPTH: usize = 4;

/// Beats of a record out of the packet store: port, flags, tick and cell bytes
/// (`packet_store::RECORD_BEATS`).
pub const RECORD_BEATS: usize = 26;

/// Ports per status datagram (`status_reporter::PORTS_PER_STATUS`).
pub const PORTS_PER_STATUS: usize = 32;

/// Cell packets each downlink port can hold (`cell_downlink::QUEUE_PACKETS`).
pub const DOWNLINK_QUEUE_PACKETS: u64 = 2;

// ---- latencies that depend on the box's parameters ----

/// Cycles from the first edge that sampled a start bit low to the cycle each of its ten
/// bits (start, eight data, stop) is sampled, for a clock and a baud rate.
pub use skinbox_gateware::uart_rx::bit_middles;

/// Clocks between two visits of one port by the deframing engine, for a port count.
pub use skinbox_gateware::cell_deframer::scan_period;

/// Clocks from a byte's stop-bit sample to the deframer's closing of a packet whose next
/// byte did not complete (`10 + idle_gap_bits` bit times).
pub use skinbox_gateware::cell_deframer::truncation_clocks;

/// Clocks from a downlink frame's start to the start of its bit `bit`, for a clock and a
/// baud rate.
pub use skinbox_gateware::cell_downlink::bit_start;

/// Bits of a downlink UART frame for a port count (start, eight data bits, stop, and the
/// stop bits the shared frame timer adds).
pub use skinbox_gateware::cell_downlink::frame_bits;

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_gateware as g;
    use skinbox_gateware::reply_builder::{build_clocks, AckReplyKind, ReplyKind};

    /// Every number of the contract is the gateware's.
    #[test]
    fn the_numbers_are_the_gateware_s() {
        let pairs: [(&str, u64, u64); 30] = [
            (
                "RESET_LATENCY",
                RESET_LATENCY,
                g::interface_box::RESET_LATENCY,
            ),
            (
                "PORT_COUNTERS_CLEAR_CLOCKS",
                PORT_COUNTERS_CLEAR_CLOCKS,
                g::counter_file::CLEAR_CLOCKS,
            ),
            (
                "DEFRAMER_DECISION_CLOCKS",
                DEFRAMER_DECISION_CLOCKS,
                g::cell_deframer::DECISION_CLOCKS,
            ),
            (
                "INCREMENT_WRITE_EDGE",
                INCREMENT_WRITE_EDGE,
                g::counter_file::INCREMENT_WRITE_EDGE,
            ),
            (
                "ARBITER_OFFER_LATENCY",
                ARBITER_OFFER_LATENCY,
                g::datagram_arbiter::OFFER_LATENCY,
            ),
            (
                "TAKE_TO_FIRST_BYTE",
                TAKE_TO_FIRST_BYTE,
                g::frame_transmitter::TAKE_TO_FIRST_BYTE,
            ),
            (
                "TAKE_TO_RAW_BODY",
                TAKE_TO_RAW_BODY,
                g::frame_transmitter::TAKE_TO_RAW_BODY,
            ),
            (
                "BODY_START",
                BODY_START,
                g::frame_transmitter::BODY_START as u64,
            ),
            (
                "STATUS_CLOCKS_PER_WORD",
                STATUS_CLOCKS_PER_WORD,
                g::status_reporter::CLOCKS_PER_WORD,
            ),
            (
                "STATUS_WORD_VALUE_CLOCK",
                STATUS_WORD_VALUE_CLOCK,
                g::status_reporter::WORD_VALUE_CLOCK,
            ),
            (
                "STATUS_HEADER_WORDS",
                STATUS_HEADER_WORDS as u64,
                g::status_reporter::HEADER_WORDS as u64,
            ),
            (
                "STATUS_BOX_COUNTER_WORDS",
                STATUS_BOX_COUNTER_WORDS as u64,
                g::status_reporter::BOX_COUNTER_WORDS as u64,
            ),
            ("MAC_LATENCY", MAC_LATENCY, g::mac_receiver::MAC_LATENCY),
            (
                "RECEIVE_TICK_LAG",
                RECEIVE_TICK_LAG,
                g::interface_box::RECEIVE_TICK_LAG,
            ),
            (
                "PARSER_DECISION_LATENCY",
                PARSER_DECISION_LATENCY,
                g::frame_parser::DECISION_LATENCY,
            ),
            (
                "COMMAND_LATENCY",
                COMMAND_LATENCY,
                g::command_unit::COMMAND_LATENCY,
            ),
            (
                "DOWNLINK_OFFER_AFTER_COMMAND",
                DOWNLINK_OFFER_AFTER_COMMAND,
                g::command_unit::DOWNLINK_OFFER_AFTER_COMMAND,
            ),
            (
                "FRAMES_RECEIVED_VISIBLE_AFTER",
                FRAMES_RECEIVED_VISIBLE_AFTER,
                g::box_counter_file::FRAMES_RECEIVED_VISIBLE_AFTER,
            ),
            (
                "FATE_VISIBLE_AFTER",
                FATE_VISIBLE_AFTER,
                g::box_counter_file::FATE_VISIBLE_AFTER,
            ),
            (
                "BUILD_ARP_CLOCKS",
                BUILD_ARP_CLOCKS,
                build_clocks(ReplyKind::Arp),
            ),
            (
                "BUILD_ECHO_CLOCKS",
                BUILD_ECHO_CLOCKS,
                build_clocks(ReplyKind::Echo),
            ),
            (
                "BUILD_ACK_CLOCKS[0]",
                BUILD_ACK_CLOCKS[0],
                build_clocks(ReplyKind::Ack(AckReplyKind::None)),
            ),
            (
                "BUILD_ACK_CLOCKS[1]",
                BUILD_ACK_CLOCKS[1],
                build_clocks(ReplyKind::Ack(AckReplyKind::Destination)),
            ),
            (
                "BUILD_ACK_CLOCKS[2]",
                BUILD_ACK_CLOCKS[2],
                build_clocks(ReplyKind::Ack(AckReplyKind::Counters)),
            ),
            (
                "UNLOCK_AFTER_LAST_TAKE",
                UNLOCK_AFTER_LAST_TAKE,
                g::reply_builder::UNLOCK_AFTER_LAST_TAKE,
            ),
            (
                "DOWNLINK_REFILL_LATENCY",
                DOWNLINK_REFILL_LATENCY,
                g::cell_downlink::REFILL_LATENCY,
            ),
            ("SLOTS", SLOTS as u64, g::geometry::SLOTS as u64),
            (
                "STORE_FIFO_DEPTH",
                STORE_FIFO_DEPTH as u64,
                g::packet_store::FIFO_DEPTH as u64,
            ),
            (
                "RECORD_BEATS",
                RECORD_BEATS as u64,
                g::packet_store::RECORD_BEATS as u64,
            ),
            (
                "PORTS_PER_STATUS",
                PORTS_PER_STATUS as u64,
                g::status_reporter::PORTS_PER_STATUS as u64,
            ),
        ];
        let wrong: Vec<String> = pairs
            .iter()
            .filter(|(_, model, gateware)| model != gateware)
            .map(|(name, model, gateware)| {
                format!("{name}: {model} here, {gateware} in the gateware")
            })
            .collect();
        assert!(wrong.is_empty(), "{}", wrong.join("\n"));
        assert_eq!(DOWNLINK_QUEUE_PACKETS, g::cell_downlink::QUEUE_PACKETS);
    }
}

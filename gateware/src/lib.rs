//! The skinbox interface box, described in rust-hdl.
//!
//! One 125 MHz clock domain with a synchronous, active-high `reset` input on every block.
//! A cell packet travels through the blocks in this order, one file each:
//!
//! 1. [`uart_rx::UartRx`], one per pin: samples the asynchronous UART pin and holds each
//!    byte with the low bits of its strobe tick (bit level: all a port keeps in registers);
//! 2. [`cell_deframer::CellDeframer`]: one engine for all ports, visiting one per clock with
//!    their state in block RAM: finds 20-byte cell packets in each port's bytes, stamps
//!    them, rejects broken ones and counts each cause;
//! 3. [`packet_store::PacketStore`]: holds every port's whole packets in shared block RAM
//!    and merges the ports, one whole record at a time;
//! 4. [`record_batcher::RecordBatcher`]: batches the records into records datagrams;
//! 5. [`datagram_arbiter::DatagramArbiter`]: merges them with the
//!    [`status_reporter::StatusReporter`]'s datagrams, whole datagrams round robin;
//! 6. [`frame_transmitter::FrameTransmitter`]: sends each as an Ethernet frame on GMII.
//!
//! [`cell_uplink::CellUplink`] holds 1 to 3 and the ports' counters.
//!
//! [`timestamp::TimestampCounter`] gives every block the box time. Blocks exchange packets
//! over the interfaces of [`stream`]: bytes, and datagrams (a descriptor, then bytes).
//!
//! The receive path (docs/control.md): GMII receive (on the board, RGMII through
//! [`rx_clock_crossing::RxClockCrossing`] into the box clock) -> [`mac_receiver::MacReceiver`]
//! -> [`frame_parser::FrameParser`] -> [`command_unit::CommandUnit`]; the fates counted in
//! [`box_counter_file::BoxCounterFile`]; ARP, echo and command replies built by
//! [`reply_builder::ReplyBuilder`] and sent as the datagram arbiter's third source.
//!
//! The downlink to the cells: [`cell_downlink::CellDownlink`] queues cell command packets
//! per port and sends them on every port's pin in one shared bit time and frame.

pub mod arp_receiver;
pub mod async_fifo;
pub mod batch_close;
pub mod block_ram;
pub mod board;
pub mod body_reader;
pub mod box_configuration;
pub mod box_counter_file;
pub mod cell_deframer;
pub mod cell_downlink;
pub mod cell_uplink;
pub mod command_arguments;
pub mod command_checks;
pub mod command_decoder;
pub mod command_unit;
pub mod counter_file;
pub mod counting_ram;
pub mod crc32;
pub mod datagram_arbiter;
pub mod datagram_checksum;
pub mod datagram_offer;
pub mod decision_inputs;
pub mod decision_outputs;
pub mod deframer_decision;
pub mod deframer_scan;
pub mod downlink_frame_timer;
pub mod downlink_next_position;
pub mod downlink_packet_copy;
pub mod downlink_pin_scan;
pub mod downlink_refill;
pub mod downlink_sync_bytes;
pub mod ethernet_demux;
pub mod fcs_output;
pub mod field_capture;
pub mod field_match;
pub mod flush_deadline;
pub mod frame_end_checks;
pub mod frame_parser;
pub mod frame_transmitter;
pub mod geometry;
pub mod hdl;
pub mod header_sums;
pub mod host_table;
pub mod interface_box;
pub mod ipv4_receiver;
pub mod lut_ram;
pub mod mac_receiver;
pub mod mdio;
pub mod ones_complement_sum;
pub mod packet_store;
pub mod parser_input;
pub mod payload_writer;
pub mod pending_events;
pub mod port_slots;
pub mod receive_rules;
pub mod record_arbiter;
pub mod record_batcher;
pub mod record_position;
pub mod replica_register;
pub mod reply_builder;
pub mod reply_checksums;
pub mod reply_field_bytes;
pub mod reply_sequencer;
pub mod reply_sizing;
pub mod reply_stages;
pub mod report_timer;
pub mod rx_clock_crossing;
pub mod status_page_writer;
pub mod status_pages;
pub mod status_reporter;
pub mod status_words;
pub mod stream;
pub mod stream_fifo;
pub mod sync_generator;
pub mod timestamp;
pub mod transmit_fields;
pub mod transmit_geometry;
pub mod transmit_layout;
pub mod transmit_sequence;
pub mod transmit_source;
pub mod transport_receiver;
pub mod uart_rx;
pub mod verilog;

#[cfg(test)]
pub(crate) mod testbench;

/// Clock of the box: the GMII transmit clock, one tick of the box time per clock.
pub const CLOCK_HZ: u64 = skinbox_protocol::TICKS_PER_SECOND;
/// UART rate of the skin cells.
pub const CELL_BAUD: u64 = skinbox_protocol::cell::UART_BAUD;

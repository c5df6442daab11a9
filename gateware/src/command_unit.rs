//! CommandUnit: steps 17-22 of the box's control rules (docs/control.md,
//! `cosim::control`) for a well-formed command from the host subnet, and the run-time
//! configuration the accepted commands set.
//!
//! The frame parser raises `command` for one clock with the command's fields on its
//! outputs. The unit checks, in this order: the box id (the box's or `ANY_BOX`, else
//! `OtherBox`); the sequence number against the last one accepted from the sender's IPv4
//! address, in a table of `HOST_SLOTS` hosts ("newer" in serial-number arithmetic,
//! `(sequence - last) as i32 > 0`; a host not in the table may start anywhere), else
//! `Replay`; then the sequence number is taken (the host's slot, or for a new host the
//! slot of the host accepted longest ago) whatever the opcode and arguments say; an
//! unknown opcode and bad arguments (as `skinbox_protocol::command::Request::parse`) are
//! refused; a cell command is refused as `DownlinkFull` when the downlink is `busy` or a
//! target port's queue is full (`downlink_full_ports`, any bit for `ALL_PORTS`), as they
//! are in the clock before `done`, else offered to it (`downlink_offer` in that clock,
//! with `downlink_port`); everything else is carried out.
//!
//! The hosts are a [`HostTable`], which looks `peer_ip` up while the frame arrives. The
//! work is a pipeline of registers, one stage per clock: the argument checks; the result of
//! the arguments; the serial-number test against the table's answer (newer or not,
//! registered); the decision. `done`
//! is high in the clock [`COMMAND_LATENCY`] clocks after `command`, with `fate` and
//! `result` (held until the next `done`) and `last_accepted` (from
//! [`LAST_ACCEPTED_AFTER_DONE`] to [`LAST_ACCEPTED_HOLDS`] clocks after `done`). The configuration registers change at
//! the same edge: in the `done` clock they already hold the new values, and
//! `status_period_set` / `status_now` are high in that clock only. The table takes the
//! sequence number a clock later, from a register. `peer_ip` must be steady for
//! [`LOOKUP_CLOCKS`] clocks before `command` and commands must come at least
//! `COMMAND_LATENCY` + 1 + `LOOKUP_CLOCKS` clocks apart (the parser's sender address is
//! steady from the frame's IPv4 header on, and a frame takes at least 72 clocks), and the
//! parser's fields must stay steady from then to `done` (they are its captures of the
//! frame, which the next frame reaches no earlier than 13 clocks after the last beat: see
//! `frame_parser`).
//!
//! `last_accepted` is the sequence number the table holds for the sender after the
//! command: the command's own when it was taken, else the one it holds (0 for a host
//! not in the table, which only a command for another box can leave there). A flag says
//! whether the command was taken, and `last_accepted` is then the parser's sequence
//! number, else the table's answer for the sender (0 when the table does not know it),
//! registered (a clock after `done`: the table's distributed RAM read and the choice
//! would otherwise run on into the reply builder's field multiplexer); both hold
//! until the next frame reaches the parser's fields (its IPv4 source, byte 26, at least 20
//! + 27 clocks after the last beat: more than [`LAST_ACCEPTED_HOLDS`] after `done`).

use crate::box_configuration::BoxConfiguration;
use crate::command_checks::CommandChecks;
use crate::hdl::*;
use crate::host_table::HostTable;
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::command::AckResult;
use skinbox_protocol::link::LinkConfig;

/// Clocks from `command` to `done`.
pub const COMMAND_LATENCY: u64 = 4;

/// Clocks from `done` to the first clock in which `last_accepted` is right.
pub const LAST_ACCEPTED_AFTER_DONE: u64 = 1;

/// Clocks from `done` (its clock counted) to the last clock in which `last_accepted` holds.
pub const LAST_ACCEPTED_HOLDS: u64 = 30;

/// Clocks from `command` to `downlink_offer`: the clock before `done`.
pub const DOWNLINK_OFFER_AFTER_COMMAND: u64 = COMMAND_LATENCY - 1;

/// Build-time parameters of the command unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CommandUnitConfig {
    /// The destination after reset: `host_mac`, `host_ip`, `host_port`.
    pub link: LinkConfig,
    /// The box id.
    pub box_id: u16,
    /// Ports of the box (a cell command's port must be below, or `ALL_PORTS`).
    pub port_count: u8,
    /// Flush timeout after reset, ticks.
    pub flush_timeout_ticks: u32,
    /// Status period after reset, ticks.
    pub status_period_ticks: u32,
    /// Time-sync period after reset, ticks (0: no syncs).
    pub sync_period_ticks: u32,
}

/// The decision of steps 17-22 and the run-time configuration.
#[derive(LogicBlock)]
pub struct CommandUnit {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: forgets every host, configuration back to the build-time values.
    pub reset: Signal<In, Bit>,
    /// One clock: a command passed steps 1-16 and was stored (its fields are steady).
    pub command: Signal<In, Bit>,
    /// The sender's MAC (the Ethernet source).
    pub peer_mac: Signal<In, Bits<48>>,
    /// The sender's IPv4 address, steady from [`LOOKUP_CLOCKS`] clocks before `command` on:
    /// the host table looks it up while the frame arrives.
    pub peer_ip: Signal<In, Bits<32>>,
    /// The sender's UDP port.
    pub peer_port: Signal<In, Bits<16>>,
    /// The command's box id.
    pub command_box_id: Signal<In, Bits<16>>,
    /// The command's opcode.
    pub command_opcode: Signal<In, Bits<8>>,
    /// The command's sequence number.
    pub command_sequence: Signal<In, Bits<32>>,
    /// The command's argument length, bytes.
    pub command_argument_length: Signal<In, Bits<16>>,
    /// The first 12 argument bytes, the first in bits 95..88, bytes past the arguments 0.
    pub command_arguments: Signal<In, Bits<96>>,
    /// One clock, the clock before `done`: a cell command is carried out; the downlink
    /// queues the packet it captured.
    pub downlink_offer: Signal<Out, Bit>,
    /// The cell command's port (or `ALL_PORTS`), with `downlink_offer`.
    pub downlink_port: Signal<Out, Bits<8>>,
    /// The downlink is copying a packet into its queues.
    pub downlink_busy: Signal<In, Bit>,
    /// Bit `p`: port `p`'s downlink queue is full.
    pub downlink_full_ports: Signal<In, Bits<64>>,
    /// One clock, `COMMAND_LATENCY` clocks after `command`.
    pub done: Signal<Out, Bit>,
    /// The command's fate: a `BoxCounter` index (held until the next `done`).
    pub fate: Signal<Out, Bits<5>>,
    /// The acknowledgement's result: an `AckResult` (held until the next `done`).
    pub result: Signal<Out, Bits<8>>,
    /// The acknowledgement's last accepted sequence number (from
    /// [`LAST_ACCEPTED_AFTER_DONE`] to [`LAST_ACCEPTED_HOLDS`] clocks after `done`).
    pub last_accepted: Signal<Out, Bits<32>>,
    /// Datagrams' destination MAC.
    pub destination_mac: Signal<Out, Bits<48>>,
    /// Datagrams' destination IPv4 address.
    pub destination_ip: Signal<Out, Bits<32>>,
    /// Datagrams' destination UDP port.
    pub destination_port: Signal<Out, Bits<16>>,
    /// Flush timeout, ticks.
    pub flush_timeout_ticks: Signal<Out, Bits<32>>,
    /// Status period, ticks.
    pub status_period_ticks: Signal<Out, Bits<32>>,
    /// One clock (the `done` clock): a set-status-period was carried out.
    pub status_period_set: Signal<Out, Bit>,
    /// One clock (the `done` clock): a status-now was carried out.
    pub status_now: Signal<Out, Bit>,
    /// The box's time-sync period, ticks (0: none).
    pub sync_period_ticks: Signal<Out, Bits<32>>,
    /// One clock (the `done` clock): a set-sync-period was carried out.
    pub sync_period_set: Signal<Out, Bit>,
    /// From `done` on, held like `result`: the command was an accepted stream-to (its
    /// acknowledgement carries the destination).
    pub accepted_stream_to: Signal<Out, Bit>,
    /// From `done` on, held like `result`: the command was an accepted status-now (its
    /// acknowledgement carries the box counters).
    pub accepted_status_now: Signal<Out, Bit>,
    // build-time values
    fate_replay: Constant<Bits<5>>,
    fate_other_box: Constant<Bits<5>>,
    fate_downlink_full: Constant<Bits<5>>,
    result_replay: Constant<Bits<8>>,
    result_other_box: Constant<Bits<8>>,
    result_downlink_full: Constant<Bits<8>>,
    // argument positions in `command_arguments`
    // the run-time configuration the accepted commands set
    configuration: BoxConfiguration,
    // the box id, opcode and argument checks (stages 1 and 2)
    checks: CommandChecks,
    // the hosts and their last accepted sequence numbers, looked up while the frame arrives
    hosts: HostTable,
    // stage 1: host match and argument checks
    stage_1: DFF<Bit>,
    // a cell command's target ports, one bit each (every bit for `ALL_PORTS`)
    // stage 2: the matched host's sequence, the oldest slot, the arguments' verdict
    stage_2: DFF<Bit>,
    // stage 3: the matched host's sequence is not older than the command's
    stage_3: DFF<Bit>,
    // the command's sequence number equals the host's last, is behind it (serial numbers):
    // registered a clock before `not_newer`, so no carry chain runs into the decision
    sequence_equal: DFF<Bit>,
    // the table's last sequence number of the sender, registered (the table looked the
    // sender up while the frame arrived and holds the answer until the take): no path
    // from the distributed RAM into the compare
    table_sequence: DFF<Bits<32>>,
    sequence_behind: DFF<Bit>,
    not_newer: DFF<Bit>,
    // what the command does if its sequence number is newer: the box id and arguments are
    // right and it is this opcode (so the decision gates one flag with the serial test)
    apply_stream_to: DFF<Bit>,
    apply_flush_timeout: DFF<Bit>,
    apply_status_period: DFF<Bit>,
    apply_status_now: DFF<Bit>,
    apply_cell_command: DFF<Bit>,
    apply_sync_period: DFF<Bit>,
    // stage 5: the table's take a clock after the decision
    write_table: DFF<Bit>,
    // stage 4: outputs
    done_out: DFF<Bit>,
    fate_out: DFF<Bits<5>>,
    result_out: DFF<Bits<8>>,
    // the decision refused a cell command for a full queue: `fate` and `result` say so
    // (chosen after the registers, so the queues' state reaches one flip-flop)
    downlink_refused: DFF<Bit>,
    // the command was taken: `last_accepted` is its sequence number
    took_sequence: DFF<Bit>,
    // `last_accepted`, a clock late: the table's read and the choice reach a register,
    // not the reply builder's field multiplexer
    last_accepted_held: DFF<Bits<32>>,
    accepted_stream_to_out: DFF<Bit>,
    accepted_status_now_out: DFF<Bit>,
    // decision signals
    difference: Signal<Local, Bits<32>>,
    // the box id and the arguments are right
    checks_pass: Signal<Local, Bit>,
    taken: Signal<Local, Bit>,
    newer: Signal<Local, Bit>,
    cell_command_taken: Signal<Local, Bit>,
    downlink_room: Signal<Local, Bit>,
}

impl CommandUnit {
    /// A command unit with the build-time values of `config`.
    pub fn new(config: CommandUnitConfig) -> Self {
        let link = config.link;
        Self {
            clock: Default::default(),
            reset: Default::default(),
            command: Default::default(),
            peer_mac: Default::default(),
            peer_ip: Default::default(),
            peer_port: Default::default(),
            command_box_id: Default::default(),
            command_opcode: Default::default(),
            command_sequence: Default::default(),
            command_argument_length: Default::default(),
            command_arguments: Default::default(),
            downlink_offer: Default::default(),
            downlink_port: Default::default(),
            downlink_busy: Default::default(),
            downlink_full_ports: Default::default(),
            done: Default::default(),
            fate: Default::default(),
            result: Default::default(),
            last_accepted: Default::default(),
            destination_mac: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            flush_timeout_ticks: Default::default(),
            status_period_ticks: Default::default(),
            status_period_set: Default::default(),
            status_now: Default::default(),
            sync_period_ticks: Default::default(),
            sync_period_set: Default::default(),
            accepted_stream_to: Default::default(),
            accepted_status_now: Default::default(),
            fate_replay: constant(BoxCounter::RefusedReplay as u64),
            fate_other_box: constant(BoxCounter::RefusedOtherBox as u64),
            fate_downlink_full: constant(BoxCounter::RefusedDownlinkFull as u64),
            result_replay: constant(AckResult::Replay as u64),
            result_other_box: constant(AckResult::OtherBox as u64),
            result_downlink_full: constant(AckResult::DownlinkFull as u64),
            configuration: BoxConfiguration::new(
                &link,
                config.flush_timeout_ticks,
                config.status_period_ticks,
                config.sync_period_ticks,
            ),
            checks: CommandChecks::new(config.box_id, config.port_count),
            hosts: Default::default(),
            stage_1: Default::default(),
            stage_2: Default::default(),
            stage_3: Default::default(),
            sequence_equal: Default::default(),
            table_sequence: Default::default(),
            sequence_behind: Default::default(),
            not_newer: Default::default(),
            apply_stream_to: Default::default(),
            apply_flush_timeout: Default::default(),
            apply_status_period: Default::default(),
            apply_status_now: Default::default(),
            apply_cell_command: Default::default(),
            apply_sync_period: Default::default(),
            write_table: Default::default(),
            done_out: Default::default(),
            fate_out: Default::default(),
            result_out: Default::default(),
            downlink_refused: Default::default(),
            took_sequence: Default::default(),
            last_accepted_held: Default::default(),
            accepted_stream_to_out: Default::default(),
            accepted_status_now_out: Default::default(),
            difference: Default::default(),
            checks_pass: Default::default(),
            taken: Default::default(),
            newer: Default::default(),
            cell_command_taken: Default::default(),
            downlink_room: Default::default(),
        }
    }
}

impl Logic for CommandUnit {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            stage_1,
            stage_2,
            stage_3,
            sequence_equal,
            table_sequence,
            sequence_behind,
            not_newer,
            apply_stream_to,
            apply_flush_timeout,
            apply_status_period,
            apply_status_now,
            apply_cell_command,
            apply_sync_period,
            write_table,
            done_out,
            fate_out,
            result_out,
            downlink_refused,
            took_sequence,
            last_accepted_held,
            accepted_stream_to_out,
            accepted_status_now_out
        );
        self.hosts.clock.next = self.clock.val();
        self.hosts.reset.next = self.reset.val();
        self.hosts.peer_ip.next = self.peer_ip.val();

        // Stages 1 and 2: the box id, opcode and arguments (the parser holds the fields, so
        // the checks are steady from the clock after `command` on).
        self.stage_1.d.next = self.command.val();
        self.stage_2.d.next = self.stage_1.q.val();
        self.checks.clock.next = self.clock.val();
        self.checks.command_box_id.next = self.command_box_id.val();
        self.checks.command_opcode.next = self.command_opcode.val();
        self.checks.command_argument_length.next = self.command_argument_length.val();
        self.checks.command_arguments.next = self.command_arguments.val();
        self.checks.downlink_full_ports.next = self.downlink_full_ports.val();

        // Stage 3: the serial-number difference to the host's last accepted sequence.
        self.stage_3.d.next = self.stage_2.q.val();
        self.table_sequence.d.next = self.hosts.last_sequence.val();
        self.difference.next = self.command_sequence.val() - self.table_sequence.q.val();
        self.sequence_equal.d.next = self.command_sequence.val() == self.table_sequence.q.val();
        self.sequence_behind.d.next = self.difference.val().get_bit(31);
        self.not_newer.d.next =
            self.hosts.known.val() & (self.sequence_equal.q.val() | self.sequence_behind.q.val());
        self.checks_pass.next = self.checks.box_ok.val() & self.checks.arguments_ok.val();
        self.apply_stream_to.d.next = self.checks_pass.val() & self.checks.is_stream_to.val();
        self.apply_flush_timeout.d.next =
            self.checks_pass.val() & self.checks.is_set_flush_timeout.val();
        self.apply_status_period.d.next =
            self.checks_pass.val() & self.checks.is_set_status_period.val();
        self.apply_status_now.d.next = self.checks_pass.val() & self.checks.is_status_now.val();
        self.apply_cell_command.d.next = self.checks_pass.val() & self.checks.is_cell_command.val();
        self.apply_sync_period.d.next =
            self.checks_pass.val() & self.checks.is_set_sync_period.val();
        // Stage 4: the decision, the table and the configuration.
        self.done_out.d.next = self.stage_3.q.val();
        self.newer.next = self.stage_3.q.val() & !self.not_newer.q.val();
        self.taken.next = self.newer.val() & self.checks.box_ok.val();
        self.cell_command_taken.next = self.newer.val() & self.apply_cell_command.q.val();
        self.downlink_port.next = self.checks.cell_port.val();
        self.downlink_room.next = !self.downlink_busy.val() & !self.checks.target_full.val();
        self.downlink_offer.next = self.cell_command_taken.val() & self.downlink_room.val();
        if self.stage_3.q.val() {
            self.downlink_refused.d.next = self.checks.box_ok.val()
                & !self.not_newer.q.val()
                & self.cell_command_taken.val()
                & !self.downlink_room.val();
            self.accepted_stream_to_out.d.next = self.newer.val() & self.apply_stream_to.q.val();
            self.accepted_status_now_out.d.next = self.newer.val() & self.apply_status_now.q.val();
            if !self.checks.box_ok.val() {
                self.fate_out.d.next = self.fate_other_box.val();
                self.result_out.d.next = self.result_other_box.val();
                self.took_sequence.d.next = false;
            } else if self.not_newer.q.val() {
                self.fate_out.d.next = self.fate_replay.val();
                self.result_out.d.next = self.result_replay.val();
                self.took_sequence.d.next = false;
            } else {
                self.fate_out.d.next = self.checks.fate.val();
                self.result_out.d.next = self.checks.result.val();
                self.took_sequence.d.next = true;
            }
        }
        // Stage 5: the table's take from the registered decision (the parser holds the fields)
        self.write_table.d.next = self.taken.val();
        self.hosts.take.next = self.write_table.q.val();
        self.hosts.take_sequence.next = self.command_sequence.val();
        // the configuration, at the same edge as `done`
        self.configuration.clock.next = self.clock.val();
        self.configuration.reset.next = self.reset.val();
        self.configuration.apply_stream_to.next = self.newer.val() & self.apply_stream_to.q.val();
        self.configuration.to_sender.next = self.checks.no_arguments.val();
        self.configuration.peer_mac.next = self.peer_mac.val();
        self.configuration.peer_ip.next = self.peer_ip.val();
        self.configuration.peer_port.next = self.peer_port.val();
        self.configuration.argument_mac.next = self.checks.argument_mac.val();
        self.configuration.argument_ip.next = self.checks.argument_ip.val();
        self.configuration.argument_port.next = self.checks.argument_port.val();
        self.configuration.apply_flush_timeout.next =
            self.newer.val() & self.apply_flush_timeout.q.val();
        self.configuration.apply_status_period.next =
            self.newer.val() & self.apply_status_period.q.val();
        self.configuration.apply_status_now.next = self.newer.val() & self.apply_status_now.q.val();
        self.configuration.apply_sync_period.next =
            self.newer.val() & self.apply_sync_period.q.val();
        self.configuration.value.next = self.checks.value.val();
        self.done.next = self.done_out.q.val();
        self.fate.next = self.fate_out.q.val();
        self.result.next = self.result_out.q.val();
        if self.downlink_refused.q.val() {
            self.fate.next = self.fate_downlink_full.val();
            self.result.next = self.result_downlink_full.val();
        }
        self.last_accepted_held.d.next = self.hosts.known_sequence.val();
        if self.took_sequence.q.val() {
            self.last_accepted_held.d.next = self.command_sequence.val();
        }
        self.last_accepted.next = self.last_accepted_held.q.val();
        self.destination_mac.next = self.configuration.destination_mac.val();
        self.destination_ip.next = self.configuration.destination_ip.val();
        self.destination_port.next = self.configuration.destination_port.val();
        self.flush_timeout_ticks.next = self.configuration.flush_timeout_ticks.val();
        self.status_period_ticks.next = self.configuration.status_period_ticks.val();
        self.status_period_set.next = self.configuration.status_period_set.val();
        self.status_now.next = self.configuration.status_now.val();
        self.sync_period_ticks.next = self.configuration.sync_period_ticks.val();
        self.sync_period_set.next = self.configuration.sync_period_set.val();
        self.accepted_stream_to.next = self.accepted_stream_to_out.q.val();
        self.accepted_status_now.next = self.accepted_status_now_out.q.val();

        if self.reset.val() {
            self.stage_1.d.next = false;
            self.stage_2.d.next = false;
            self.stage_3.d.next = false;
            self.write_table.d.next = false;
            self.done_out.d.next = false;
            self.fate_out.d.next = 0.into();
            self.result_out.d.next = 0.into();
            self.downlink_refused.d.next = false;
            self.took_sequence.d.next = false;
            self.accepted_stream_to_out.d.next = false;
            self.accepted_status_now_out.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::host_table::LOOKUP_CLOCKS;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::command::*;
    use skinbox_protocol::Error;

    const BOX_ID: u16 = 0x0102;
    const PORTS: u8 = 8;
    const FLUSH: u32 = 12_500;
    const PERIOD: u32 = 125_000_000;

    fn config() -> CommandUnitConfig {
        CommandUnitConfig {
            link: LinkConfig::DEFAULT,
            box_id: BOX_ID,
            port_count: PORTS,
            flush_timeout_ticks: FLUSH,
            status_period_ticks: PERIOD,
            sync_period_ticks: 0,
        }
    }

    /// A command as the parser holds it: sender and header fields, all its argument bytes.
    #[derive(Debug, Clone)]
    struct Cmd {
        mac: u64,
        ip: u32,
        port: u16,
        box_id: u16,
        opcode: u8,
        sequence: u32,
        args: Vec<u8>,
    }

    fn cmd(ip: u32, sequence: u32, opcode: u8, args: &[u8]) -> Cmd {
        Cmd {
            mac: 0x0200_0000_0000 | u64::from(ip),
            ip,
            port: 40_000 + (ip % 1000) as u16,
            box_id: BOX_ID,
            opcode,
            sequence,
            args: args.to_vec(),
        }
    }

    /// What the unit shows in the `done` clock.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    struct Seen {
        fate: usize,
        result: u8,
        last_accepted: u32,
        destination: (u64, u32, u16),
        flush_timeout: u32,
        status_period: u32,
        status_period_set: bool,
        status_now: bool,
        sync_period: u32,
        sync_period_set: bool,
    }

    /// The rules of steps 17-22, written from docs/control.md; the arguments are judged by
    /// `Request::parse`.
    struct Model {
        /// (IPv4 address, last accepted sequence), accepted longest ago first.
        hosts: Vec<(u32, u32)>,
        destination: (u64, u32, u16),
        flush_timeout: u32,
        status_period: u32,
        sync_period: u32,
    }

    impl Model {
        fn new() -> Model {
            let link = LinkConfig::DEFAULT;
            Model {
                hosts: Vec::new(),
                destination: (
                    big_endian(&link.host_mac),
                    u32::from_be_bytes(link.host_ip),
                    link.host_port,
                ),
                flush_timeout: FLUSH,
                status_period: PERIOD,
                sync_period: 0,
            }
        }

        /// What the unit shows, and the port it offers the downlink (with a full downlink
        /// the offer is refused).
        fn apply(&mut self, c: &Cmd, downlink_full: bool) -> (Seen, Option<u8>) {
            let mut offer = None;
            let seen = self.decide(c, downlink_full, &mut offer);
            (seen, offer)
        }

        fn decide(&mut self, c: &Cmd, downlink_full: bool, offer: &mut Option<u8>) -> Seen {
            let known = self.hosts.iter().position(|h| h.0 == c.ip);
            let last = known.map(|i| self.hosts[i].1);
            let seen = Seen {
                fate: BoxCounter::CommandsAccepted as usize,
                result: AckResult::Ok as u8,
                last_accepted: c.sequence,
                destination: self.destination,
                flush_timeout: self.flush_timeout,
                status_period: self.status_period,
                status_period_set: false,
                status_now: false,
                sync_period: self.sync_period,
                sync_period_set: false,
            };
            let refuse = |seen: Seen, fate: BoxCounter, result: AckResult, last: u32| Seen {
                fate: fate as usize,
                result: result as u8,
                last_accepted: last,
                ..seen
            };
            if c.box_id != BOX_ID && c.box_id != 0xFFFF {
                let last = last.unwrap_or(0);
                return refuse(seen, BoxCounter::RefusedOtherBox, AckResult::OtherBox, last);
            }
            if let Some(last) = last {
                if (c.sequence.wrapping_sub(last) as i32) <= 0 {
                    return refuse(seen, BoxCounter::RefusedReplay, AckResult::Replay, last);
                }
            }
            match known {
                Some(i) => {
                    self.hosts.remove(i);
                }
                None if self.hosts.len() == 4 => {
                    self.hosts.remove(0);
                }
                None => {}
            }
            self.hosts.push((c.ip, c.sequence));
            let s = c.sequence;
            match Request::parse(c.opcode, &c.args, PORTS) {
                Err(Error::UnknownOpcode { .. }) => refuse(
                    seen,
                    BoxCounter::RefusedUnknownOpcode,
                    AckResult::UnknownOpcode,
                    s,
                ),
                Err(_) => refuse(
                    seen,
                    BoxCounter::RefusedBadArgument,
                    AckResult::BadArgument,
                    s,
                ),
                Ok(Request::CellCommand { port, .. }) => {
                    if !downlink_full {
                        *offer = Some(port);
                    }
                    if downlink_full {
                        refuse(
                            seen,
                            BoxCounter::RefusedDownlinkFull,
                            AckResult::DownlinkFull,
                            s,
                        )
                    } else {
                        seen
                    }
                }
                Ok(Request::StreamTo { to }) => {
                    self.destination = match to {
                        Some(d) => (big_endian(&d.mac), u32::from_be_bytes(d.ip), d.port),
                        None => (c.mac, c.ip, c.port),
                    };
                    Seen {
                        destination: self.destination,
                        ..seen
                    }
                }
                Ok(Request::SetFlushTimeout { ticks }) => {
                    self.flush_timeout = ticks;
                    Seen {
                        flush_timeout: ticks,
                        ..seen
                    }
                }
                Ok(Request::SetStatusPeriod { ticks }) => {
                    self.status_period = ticks;
                    Seen {
                        status_period: ticks,
                        status_period_set: true,
                        ..seen
                    }
                }
                Ok(Request::StatusNow) => Seen {
                    status_now: true,
                    ..seen
                },
                Ok(Request::ReadTick) => seen,
                Ok(Request::SetSyncPeriod { ticks }) => {
                    self.sync_period = ticks;
                    Seen {
                        sync_period: ticks,
                        sync_period_set: true,
                        ..seen
                    }
                }
            }
        }
    }

    struct Fixture {
        bench: Bench<CommandUnit>,
        model: Model,
        /// The downlink has no room: busy, or every port full (alternately).
        downlink_full: bool,
    }

    impl Fixture {
        fn new() -> Fixture {
            let mut bench = Bench::new(CommandUnit::new(config()), |b| &mut b.clock);
            bench.uut.reset.next = true;
            bench.cycle();
            bench.uut.reset.next = false;
            bench.cycles(2);
            Fixture {
                bench,
                model: Model::new(),
                downlink_full: false,
            }
        }

        fn seen(&self) -> Seen {
            let u = &self.bench.uut;
            Seen {
                fate: u.fate.val().to_u64() as usize,
                result: u.result.val().to_u64() as u8,
                last_accepted: u.last_accepted.val().to_u32(),
                destination: (
                    u.destination_mac.val().to_u64(),
                    u.destination_ip.val().to_u32(),
                    u.destination_port.val().to_u64() as u16,
                ),
                flush_timeout: u.flush_timeout_ticks.val().to_u32(),
                status_period: u.status_period_ticks.val().to_u32(),
                status_period_set: u.status_period_set.val(),
                status_now: u.status_now.val(),
                sync_period: u.sync_period_ticks.val().to_u32(),
                sync_period_set: u.sync_period_set.val(),
            }
        }

        /// Sends `c`, checks `done` comes exactly COMMAND_LATENCY clocks later with what
        /// the model says, and that the pulses last one clock; returns what the unit showed.
        fn run(&mut self, c: &Cmd) -> Seen {
            let u = &mut self.bench.uut;
            u.peer_mac.next = c.mac.into();
            u.peer_ip.next = u64::from(c.ip).into();
            u.peer_port.next = u64::from(c.port).into();
            u.command_box_id.next = u64::from(c.box_id).into();
            u.command_opcode.next = u64::from(c.opcode).into();
            u.command_sequence.next = u64::from(c.sequence).into();
            u.command_argument_length.next = (c.args.len() as u64).into();
            let mut first = [0u8; 12];
            let n = c.args.len().min(12);
            first[..n].copy_from_slice(&c.args[..n]);
            let high: Bits<96> = u64::from_be_bytes(first[..8].try_into().unwrap()).into();
            let low: Bits<96> =
                u64::from(u32::from_be_bytes(first[8..].try_into().unwrap())).into();
            u.command_arguments.next = (high << 32) | low;
            let busy = self.downlink_full && c.sequence.is_multiple_of(2);
            u.downlink_busy.next = busy;
            let every_port = (1u64 << PORTS) - 1;
            u.downlink_full_ports.next = match Request::parse(c.opcode, &c.args, PORTS) {
                _ if self.downlink_full && !busy => every_port.into(),
                // the other ports being full does not matter to a command for one port
                Ok(Request::CellCommand { port, .. }) if port != ALL_PORTS => {
                    (every_port & !(1u64 << port)).into()
                }
                _ => 0.into(),
            };
            // the sender is steady for the table's lookup, as the parser holds it from the
            // frame's IPv4 header on
            self.bench.cycles(LOOKUP_CLOCKS);
            self.bench.uut.command.next = true;
            self.bench.cycle();
            self.bench.uut.command.next = false;
            let mut offers = vec![];
            for clock in 1..COMMAND_LATENCY {
                assert!(!self.bench.uut.done.val(), "done early for {c:?}");
                self.bench.settle();
                if self.bench.uut.downlink_offer.val() {
                    offers.push((clock, self.bench.uut.downlink_port.val().to_u64() as u8));
                }
                self.bench.cycle();
            }
            assert!(self.bench.uut.done.val(), "no done for {c:?}");
            let mut seen = self.seen();
            // hold the fields a while, as the parser does until the next frame
            self.bench.cycle();
            let after = self.seen();
            // (`last_accepted` from `LAST_ACCEPTED_AFTER_DONE` clocks after `done`)
            seen.last_accepted = after.last_accepted;
            let (want, offer) = self.model.apply(c, self.downlink_full);
            assert_eq!(seen, want, "for {c:?}");
            let want_offers: Vec<(u64, u8)> = offer
                .map(|p| (DOWNLINK_OFFER_AFTER_COMMAND, p))
                .into_iter()
                .collect();
            assert_eq!(offers, want_offers, "offers for {c:?}");
            assert!(!self.bench.uut.done.val(), "done lasts one clock");
            assert!(
                !after.status_period_set && !after.status_now && !after.sync_period_set,
                "pulses last one clock"
            );
            assert_eq!(
                Seen {
                    status_period_set: seen.status_period_set,
                    status_now: seen.status_now,
                    sync_period_set: seen.sync_period_set,
                    ..after
                },
                seen,
                "outputs held after done"
            );
            self.bench.cycles(3);
            seen
        }

        fn expect(&mut self, c: &Cmd, result: AckResult, fate: BoxCounter) -> Seen {
            let seen = self.run(c);
            assert_eq!(
                (seen.result, seen.fate),
                (result as u8, fate as usize),
                "for {c:?}"
            );
            seen
        }
    }

    fn u32_arg(v: u32) -> Vec<u8> {
        v.to_be_bytes().to_vec()
    }

    fn destination_arg(mac: u64, ip: u32, port: u16) -> Vec<u8> {
        let mut a = mac.to_be_bytes()[2..].to_vec();
        a.extend(ip.to_be_bytes());
        a.extend(port.to_be_bytes());
        a
    }

    fn cell_arg(port: u8, reserved: [u8; 3]) -> Vec<u8> {
        let mut a = vec![port];
        a.extend(reserved);
        a.extend((0..20).map(|i| 0xA0 + i as u8));
        a
    }

    const HOST: u32 = 0xC0A8_0A02;

    #[test]
    fn every_result_of_every_opcode() {
        use AckResult::*;
        let mut f = Fixture::new();
        let ok = BoxCounter::CommandsAccepted;
        let bad = BoxCounter::RefusedBadArgument;
        let stream = Opcode::StreamTo as u8;
        let flush = Opcode::SetFlushTimeout as u8;
        let period = Opcode::SetStatusPeriod as u8;
        let now = Opcode::StatusNow as u8;
        let tick = Opcode::ReadTick as u8;
        let cell = Opcode::CellCommand as u8;
        let cases: Vec<(u8, Vec<u8>, AckResult, BoxCounter)> = vec![
            (stream, vec![], Ok, ok),
            (
                stream,
                destination_arg(0x0A0B_0C0D_0E0F, 0x0A00_0001, 9000),
                Ok,
                ok,
            ),
            (
                stream,
                destination_arg(0x0A0B_0C0D_0E0F, 0, 9000),
                BadArgument,
                bad,
            ),
            (
                stream,
                destination_arg(0x0A0B_0C0D_0E0F, 0x0A00_0001, 0),
                BadArgument,
                bad,
            ),
            (stream, vec![1; 4], BadArgument, bad),
            (stream, vec![1; 11], BadArgument, bad),
            (stream, vec![1; 13], BadArgument, bad),
            (stream, vec![1; 24], BadArgument, bad),
            (flush, u32_arg(0), BadArgument, bad),
            (flush, u32_arg(1), Ok, ok),
            (flush, u32_arg((1 << 31) - 1), Ok, ok),
            (flush, u32_arg(1 << 31), BadArgument, bad),
            (flush, u32_arg(u32::MAX), BadArgument, bad),
            (flush, vec![0, 0, 1], BadArgument, bad),
            (flush, vec![], BadArgument, bad),
            (flush, vec![0, 0, 0, 1, 0], BadArgument, bad),
            (period, u32_arg(124_999), BadArgument, bad),
            (period, u32_arg(0), BadArgument, bad),
            (period, u32_arg(125_000), Ok, ok),
            (period, u32_arg(u32::MAX), Ok, ok),
            (period, vec![0, 1, 0xE8, 0x48, 0], BadArgument, bad),
            (now, vec![], Ok, ok),
            (now, vec![0], BadArgument, bad),
            (now, vec![0; 12], BadArgument, bad),
            (tick, vec![], Ok, ok),
            (tick, vec![0; 4], BadArgument, bad),
            (cell, cell_arg(0, [0; 3]), Ok, ok),
            (cell, cell_arg(PORTS - 1, [0; 3]), Ok, ok),
            (cell, cell_arg(0xFF, [0; 3]), Ok, ok),
            (cell, cell_arg(PORTS, [0; 3]), BadArgument, bad),
            (cell, cell_arg(0xFE, [0; 3]), BadArgument, bad),
            (cell, cell_arg(0, [0, 0, 1]), BadArgument, bad),
            (cell, cell_arg(0, [0x80, 0, 0]), BadArgument, bad),
            (cell, cell_arg(0, [0; 3])[..23].to_vec(), BadArgument, bad),
            (cell, vec![], BadArgument, bad),
        ];
        let mut sequence = 100;
        for (opcode, args, result, fate) in cases {
            let seen = f.expect(&cmd(HOST, sequence, opcode, &args), result, fate);
            assert_eq!(
                seen.last_accepted, sequence,
                "every such result takes the number"
            );
            sequence += 1;
        }
        // a full downlink refuses good cell commands only; the number is taken
        f.downlink_full = true;
        for port in [0, PORTS - 1, 0xFF] {
            let c = cmd(HOST, sequence, cell, &cell_arg(port, [0; 3]));
            let seen = f.expect(&c, DownlinkFull, BoxCounter::RefusedDownlinkFull);
            assert_eq!(seen.last_accepted, sequence);
            sequence += 1;
        }
        f.expect(
            &cmd(HOST, sequence, cell, &cell_arg(PORTS, [0; 3])),
            BadArgument,
            bad,
        );
        sequence += 1;
        f.expect(&cmd(HOST, sequence, tick, &[]), Ok, ok);
        sequence += 1;
        f.downlink_full = false;
        for opcode in std::iter::once(0).chain(8..=255) {
            let c = cmd(HOST, sequence, opcode, &[]);
            f.expect(&c, UnknownOpcode, BoxCounter::RefusedUnknownOpcode);
            sequence += 1;
        }
    }

    #[test]
    fn another_box_id_is_refused_and_any_box_accepted() {
        let mut f = Fixture::new();
        let tick = Opcode::ReadTick as u8;
        let other = |sequence| Cmd {
            box_id: BOX_ID + 1,
            ..cmd(HOST, sequence, tick, &[])
        };
        // unknown host: last accepted 0, the table is not touched
        let seen = f.expect(&other(50), AckResult::OtherBox, BoxCounter::RefusedOtherBox);
        assert_eq!(seen.last_accepted, 0);
        f.expect(
            &cmd(HOST, 10, tick, &[]),
            AckResult::Ok,
            BoxCounter::CommandsAccepted,
        );
        let seen = f.expect(&other(11), AckResult::OtherBox, BoxCounter::RefusedOtherBox);
        assert_eq!(seen.last_accepted, 10);
        // even a replayed number: the box id comes first
        let seen = f.expect(&other(3), AckResult::OtherBox, BoxCounter::RefusedOtherBox);
        assert_eq!(seen.last_accepted, 10);
        let any = Cmd {
            box_id: ANY_BOX,
            ..cmd(HOST, 11, tick, &[])
        };
        let seen = f.expect(&any, AckResult::Ok, BoxCounter::CommandsAccepted);
        assert_eq!(seen.last_accepted, 11);
        // a stream-to for another box changes nothing
        let before = f.seen().destination;
        let stream = Cmd {
            box_id: 0,
            ..cmd(HOST, 12, Opcode::StreamTo as u8, &[])
        };
        let seen = f.expect(&stream, AckResult::OtherBox, BoxCounter::RefusedOtherBox);
        assert_eq!(seen.destination, before);
    }

    #[test]
    fn replays_are_refused_in_serial_number_arithmetic() {
        let mut f = Fixture::new();
        let tick = Opcode::ReadTick as u8;
        let replay = (AckResult::Replay, BoxCounter::RefusedReplay);
        let ok = (AckResult::Ok, BoxCounter::CommandsAccepted);
        let steps: [(u32, (AckResult, BoxCounter), u32); 10] = [
            (0xFFFF_FFF0, ok, 0xFFFF_FFF0),
            (0xFFFF_FFF0, replay, 0xFFFF_FFF0),     // equal
            (0xFFFF_FFEF, replay, 0xFFFF_FFF0),     // older
            (0x7FFF_FFF0, replay, 0xFFFF_FFF0),     // 2^31 ahead: not newer
            (5, ok, 5),                             // across the wrap
            (0xFFFF_FFFF, replay, 5),               // older across the wrap
            (5 + 0x7FFF_FFFF, ok, 5 + 0x7FFF_FFFF), // 2^31 - 1 ahead: newer
            (5, replay, 5 + 0x7FFF_FFFF),
            (0x8000_0005, ok, 0x8000_0005),
            (0x8000_0005, replay, 0x8000_0005),
        ];
        for (sequence, (result, fate), last) in steps {
            let seen = f.expect(&cmd(HOST, sequence, tick, &[]), result, fate);
            assert_eq!(seen.last_accepted, last, "sequence {sequence:#x}");
        }
        // a refused argument takes the number too
        let bad = cmd(HOST, 0x8000_0006, Opcode::SetFlushTimeout as u8, &[]);
        f.expect(&bad, AckResult::BadArgument, BoxCounter::RefusedBadArgument);
        let again = cmd(HOST, 0x8000_0006, tick, &[]);
        f.expect(&again, replay.0, replay.1);
    }

    #[test]
    fn five_hosts_share_four_slots() {
        let mut f = Fixture::new();
        let tick = Opcode::ReadTick as u8;
        let hosts: Vec<u32> = (0..5).map(|i| HOST + i * 17).collect();
        let ok = (AckResult::Ok, BoxCounter::CommandsAccepted);
        // A B C D fill the table, each starting anywhere
        for (i, &h) in hosts[..4].iter().enumerate() {
            f.expect(&cmd(h, 1000 * i as u32 + 7, tick, &[]), ok.0, ok.1);
        }
        // A again: now B is the one accepted longest ago
        f.expect(&cmd(hosts[0], 8, tick, &[]), ok.0, ok.1);
        // E takes B's slot; B is forgotten and may start anywhere, even lower
        f.expect(&cmd(hosts[4], 42, tick, &[]), ok.0, ok.1);
        let seen = f.expect(&cmd(hosts[1], 3, tick, &[]), ok.0, ok.1);
        assert_eq!(seen.last_accepted, 3);
        // B took C's slot; A, D, E are still remembered
        for (h, old) in [(hosts[0], 8), (hosts[3], 3007), (hosts[4], 42)] {
            let seen = f.expect(
                &cmd(h, old, tick, &[]),
                AckResult::Replay,
                BoxCounter::RefusedReplay,
            );
            assert_eq!(seen.last_accepted, old);
        }
        f.expect(&cmd(hosts[2], 0, tick, &[]), ok.0, ok.1);
        // table A E B C (oldest first); cycling D A E B C, each host comes back after four
        // others took a slot, so it is new every time and may go back to any number
        for round in 0..4u32 {
            for h in [3, 0, 4, 1, 2].map(|i| hosts[i]) {
                let seen = f.expect(&cmd(h, round, tick, &[]), ok.0, ok.1);
                assert_eq!(seen.last_accepted, round);
            }
        }
    }

    #[test]
    fn effects_on_the_configuration() {
        let mut f = Fixture::new();
        let link = LinkConfig::DEFAULT;
        let reset_state = f.seen();
        assert_eq!(
            reset_state.destination,
            (
                big_endian(&link.host_mac),
                u32::from_be_bytes(link.host_ip),
                link.host_port
            )
        );
        assert_eq!(reset_state.flush_timeout, FLUSH);
        assert_eq!(reset_state.status_period, PERIOD);
        let ok = (AckResult::Ok, BoxCounter::CommandsAccepted);
        let c = cmd(HOST, 1, Opcode::StreamTo as u8, &[]);
        let seen = f.expect(&c, ok.0, ok.1);
        assert_eq!(seen.destination, (c.mac, c.ip, c.port));
        let args = destination_arg(0x0253_4B00_00AA, 0x0A01_0203, 0xBEEF);
        let seen = f.expect(&cmd(HOST, 2, Opcode::StreamTo as u8, &args), ok.0, ok.1);
        assert_eq!(seen.destination, (0x0253_4B00_00AA, 0x0A01_0203, 0xBEEF));
        let seen = f.expect(
            &cmd(HOST, 3, Opcode::SetFlushTimeout as u8, &u32_arg(77)),
            ok.0,
            ok.1,
        );
        assert_eq!(seen.flush_timeout, 77);
        assert!(!seen.status_period_set && !seen.status_now);
        let c = cmd(HOST, 4, Opcode::SetStatusPeriod as u8, &u32_arg(250_000));
        let seen = f.expect(&c, ok.0, ok.1);
        assert_eq!(
            (seen.status_period, seen.status_period_set),
            (250_000, true)
        );
        // the same period again: set again (the status timer restarts)
        let c = cmd(HOST, 5, Opcode::SetStatusPeriod as u8, &u32_arg(250_000));
        assert!(f.expect(&c, ok.0, ok.1).status_period_set);
        let seen = f.expect(&cmd(HOST, 6, Opcode::StatusNow as u8, &[]), ok.0, ok.1);
        assert!(seen.status_now && !seen.status_period_set);
        // refused commands change nothing and pulse nothing
        let before = f.seen();
        for c in [
            cmd(HOST, 6, Opcode::StatusNow as u8, &[]),
            cmd(HOST, 7, Opcode::SetStatusPeriod as u8, &u32_arg(5)),
            cmd(HOST, 8, Opcode::StatusNow as u8, &[1]),
            cmd(HOST, 9, Opcode::StreamTo as u8, &[1, 2]),
        ] {
            let seen = f.run(&c);
            assert_eq!(
                (seen.destination, seen.flush_timeout, seen.status_period),
                (
                    before.destination,
                    before.flush_timeout,
                    before.status_period
                )
            );
            assert!(!seen.status_now && !seen.status_period_set);
        }
        // reset brings back the build-time values and forgets the hosts
        f.bench.uut.reset.next = true;
        f.bench.cycle();
        f.bench.uut.reset.next = false;
        f.bench.cycle();
        f.model = Model::new();
        let after = f.seen();
        assert_eq!(
            (after.destination, after.flush_timeout, after.status_period),
            (reset_state.destination, FLUSH, PERIOD)
        );
        f.expect(&cmd(HOST, 1, Opcode::ReadTick as u8, &[]), ok.0, ok.1);
    }

    #[test]
    fn random_commands_follow_the_rules() {
        let mut f = Fixture::new();
        let mut rng = TestRng::new(0x5EED);
        let hosts: Vec<u32> = (0..6).map(|i| HOST + i).collect();
        let mut next = [0u32; 6];
        let mut results = [0usize; 6];
        for _ in 0..1000 {
            let r = rng.next_u64();
            let h = (r % 6) as usize;
            next[h] = match (r >> 8) % 8 {
                0 => next[h],                                    // a replay of the last
                1 => next[h].wrapping_sub((r >> 16) as u32 % 5), // older
                2 => (r >> 32) as u32,                           // anywhere
                _ => next[h].wrapping_add(1 + (r >> 16) as u32 % 3),
            };
            let opcode = match (r >> 20) % 11 {
                0 => (r >> 24) as u8,
                7 | 8 => Opcode::CellCommand as u8,
                9 => Opcode::SetSyncPeriod as u8,
                k => (k % 7) as u8,
            };
            let length = match (r >> 28) % 8 {
                0 => (r >> 32) as usize % 30,
                1 | 2 => 0,
                3 => 4,
                4 => 12,
                5 => 24,
                _ => match opcode {
                    1 => 12,
                    2 | 3 | 7 => 4,
                    6 => 24,
                    _ => 0,
                },
            };
            let mut args: Vec<u8> = (0..length).map(|_| rng.byte()).collect();
            // interesting values
            match (r >> 36) % 6 {
                0 if length >= 4 => args[..4].copy_from_slice(
                    &match (r >> 40) % 5 {
                        0 => 0u32,
                        1 => 1,
                        2 => (1 << 31) - 1,
                        3 => 124_999 + (r >> 44) as u32 % 3,
                        _ => 1 << 31,
                    }
                    .to_be_bytes(),
                ),
                1 | 4 if length >= 4 => {
                    args[0] = (r >> 40) as u8 % (PORTS + 2);
                    args[1..4].fill(0);
                }
                2 if length >= 12 => args[6 + (r >> 40) as usize % 6] = 0,
                3 if length >= 12 => args[6..10].fill(0),
                _ => {}
            }
            if opcode == Opcode::CellCommand as u8 && length >= 4 && (r >> 56) & 1 == 0 {
                args[0] = [0, PORTS - 1, ALL_PORTS][(r >> 57) as usize % 3];
                args[1..4].fill(0);
            }
            let mut c = cmd(hosts[h], next[h], opcode, &args);
            c.box_id = match (r >> 48) % 12 {
                0 => BOX_ID ^ 1,
                1 => ANY_BOX,
                _ => BOX_ID,
            };
            f.downlink_full = (r >> 60) & 1 == 1;
            let seen = f.run(&c);
            results[seen.result as usize] += 1;
        }
        // every result came up often
        assert!(results.iter().all(|&n| n >= 10), "results {results:?}");
    }

    #[test]
    fn verilog_lints_clean() {
        let mut uut = CommandUnit::new(config());
        uut.connect_all();
        let text = generate_verilog(&uut);
        let dir =
            std::env::temp_dir().join(format!("skinbox-lint-command-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&text, &dir).unwrap_or_else(|e| panic!("{e}"));
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}

//! CommandChecks: the command unit's checks of a command's box id, opcode and arguments
//! (docs/control.md, steps 17, 20 and 21), as `skinbox_protocol::command::Request::parse`
//! judges them.
//!
//! Two register stages on the parser's held fields, every clock: the first registers the box
//! id's test, one flag per opcode, the argument length's tests, each argument's rule and a
//! cell command's target (its port, or every port); the second the verdict, as a fate (a
//! `BoxCounter` index) and an acknowledgement result. Whether a target port's queue is
//! full is chosen from `downlink_full_ports` by the registered target (a wire). The
//! argument fields the accepted commands use are wires from the held bytes.

use crate::command_arguments::{CommandArguments, HELD_ARGUMENT_BITS};
use crate::hdl::*;
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::command::{
    AckResult, Opcode, ALL_PORTS, ANY_BOX, CELL_COMMAND_LEN, DESTINATION_LEN,
    MAX_FLUSH_TIMEOUT_TICKS, MIN_STATUS_PERIOD_TICKS, MIN_SYNC_PERIOD_TICKS, TICKS_LEN,
};

// a sync period is 0 or at least the shortest status period: one compare serves both
const _: () = assert!(MIN_SYNC_PERIOD_TICKS == MIN_STATUS_PERIOD_TICKS);

/// Clocks from steady fields to the verdict (`arguments_ok`, `fate`, `result`); the opcode
/// flags, `box_ok`, `no_arguments` and the target of `target_full` are a clock earlier.
pub const CHECK_CLOCKS: u64 = 2;

/// The box id, opcode and argument checks.
#[derive(LogicBlock)]
pub struct CommandChecks {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The command's box id.
    pub command_box_id: Signal<In, Bits<16>>,
    /// The command's opcode.
    pub command_opcode: Signal<In, Bits<8>>,
    /// The command's argument length, bytes.
    pub command_argument_length: Signal<In, Bits<16>>,
    /// The first 12 argument bytes, the first in bits 95..88, bytes past the arguments 0.
    pub command_arguments: Signal<In, Bits<HELD_ARGUMENT_BITS>>,
    /// The downlink's ports whose queues are full, one bit each.
    pub downlink_full_ports: Signal<In, Bits<64>>,
    /// The box id is the box's or `ANY_BOX`.
    pub box_ok: Signal<Out, Bit>,
    /// The opcode is stream-to.
    pub is_stream_to: Signal<Out, Bit>,
    /// The opcode is set-flush-timeout.
    pub is_set_flush_timeout: Signal<Out, Bit>,
    /// The opcode is set-status-period.
    pub is_set_status_period: Signal<Out, Bit>,
    /// The opcode is status-now.
    pub is_status_now: Signal<Out, Bit>,
    /// The opcode is cell-command.
    pub is_cell_command: Signal<Out, Bit>,
    /// The opcode is set-sync-period.
    pub is_set_sync_period: Signal<Out, Bit>,
    /// The command has no argument bytes.
    pub no_arguments: Signal<Out, Bit>,
    /// A cell command's target port's queue is full (any port's for `ALL_PORTS`; a wire
    /// from `downlink_full_ports`).
    pub target_full: Signal<Out, Bit>,
    /// The opcode is known and its arguments are right.
    pub arguments_ok: Signal<Out, Bit>,
    /// The fate by opcode and arguments alone: accepted, unknown opcode or bad argument.
    pub fate: Signal<Out, Bits<5>>,
    /// The acknowledgement result that goes with `fate`.
    pub result: Signal<Out, Bits<8>>,
    /// Set-flush-timeout's, set-status-period's and set-sync-period's value (wires from the
    /// arguments).
    pub value: Signal<Out, Bits<32>>,
    /// A cell command's port (wires from the arguments).
    pub cell_port: Signal<Out, Bits<8>>,
    /// Stream-to's destination MAC, IPv4 address and UDP port (wires from the arguments).
    pub argument_mac: Signal<Out, Bits<48>>,
    /// See `argument_mac`.
    pub argument_ip: Signal<Out, Bits<32>>,
    /// See `argument_mac`.
    pub argument_port: Signal<Out, Bits<16>>,
    box_id: Constant<Bits<16>>,
    any_box: Constant<Bits<16>>,
    all_ports: Constant<Bits<8>>,
    port_count: Constant<Bits<8>>,
    max_flush_timeout: Constant<Bits<32>>,
    min_status_period: Constant<Bits<32>>,
    destination_length: Constant<Bits<16>>,
    value_length: Constant<Bits<16>>,
    cell_command_length: Constant<Bits<16>>,
    opcode_stream_to: Constant<Bits<8>>,
    opcode_set_flush_timeout: Constant<Bits<8>>,
    opcode_set_status_period: Constant<Bits<8>>,
    opcode_status_now: Constant<Bits<8>>,
    opcode_read_tick: Constant<Bits<8>>,
    opcode_cell_command: Constant<Bits<8>>,
    opcode_set_sync_period: Constant<Bits<8>>,
    fate_accepted: Constant<Bits<5>>,
    fate_unknown_opcode: Constant<Bits<5>>,
    fate_bad_argument: Constant<Bits<5>>,
    result_ok: Constant<Bits<8>>,
    result_unknown_opcode: Constant<Bits<8>>,
    result_bad_argument: Constant<Bits<8>>,
    // argument positions in `command_arguments`
    // stage 1
    box_ok_flag: DFF<Bit>,
    stream_to_flag: DFF<Bit>,
    set_flush_timeout_flag: DFF<Bit>,
    set_status_period_flag: DFF<Bit>,
    status_now_flag: DFF<Bit>,
    read_tick_flag: DFF<Bit>,
    cell_command_flag: DFF<Bit>,
    set_sync_period_flag: DFF<Bit>,
    length_0: DFF<Bit>,
    length_value: DFF<Bit>,
    length_destination: DFF<Bit>,
    length_cell_command: DFF<Bit>,
    destination_ok: DFF<Bit>,
    flush_timeout_ok: DFF<Bit>,
    status_period_ok: DFF<Bit>,
    value_zero: DFF<Bit>,
    cell_port_ok: DFF<Bit>,
    reserved_zero: DFF<Bit>,
    // a cell command's target: a port below 64 (its number), or every port
    target_port: DFF<Bits<6>>,
    target_one: DFF<Bit>,
    target_all: DFF<Bit>,
    // stage 2
    arguments_ok_held: DFF<Bit>,
    arguments_fate: DFF<Bits<5>>,
    arguments_result: DFF<Bits<8>>,
    fields: CommandArguments,
    arguments_good: Signal<Local, Bit>,
    opcode_known: Signal<Local, Bit>,
}

impl CommandChecks {
    /// The checks of a box with this id and port count.
    pub fn new(box_id: u16, port_count: u8) -> Self {
        Self {
            clock: Default::default(),
            command_box_id: Default::default(),
            command_opcode: Default::default(),
            command_argument_length: Default::default(),
            command_arguments: Default::default(),
            downlink_full_ports: Default::default(),
            box_ok: Default::default(),
            is_stream_to: Default::default(),
            is_set_flush_timeout: Default::default(),
            is_set_status_period: Default::default(),
            is_status_now: Default::default(),
            is_cell_command: Default::default(),
            is_set_sync_period: Default::default(),
            no_arguments: Default::default(),
            target_full: Default::default(),
            arguments_ok: Default::default(),
            fate: Default::default(),
            result: Default::default(),
            value: Default::default(),
            cell_port: Default::default(),
            argument_mac: Default::default(),
            argument_ip: Default::default(),
            argument_port: Default::default(),
            box_id: constant(box_id.into()),
            any_box: constant(ANY_BOX.into()),
            all_ports: constant(ALL_PORTS.into()),
            port_count: constant(port_count.into()),
            max_flush_timeout: constant(MAX_FLUSH_TIMEOUT_TICKS.into()),
            min_status_period: constant(MIN_STATUS_PERIOD_TICKS.into()),
            destination_length: constant(DESTINATION_LEN as u64),
            value_length: constant(TICKS_LEN as u64),
            cell_command_length: constant(CELL_COMMAND_LEN as u64),
            opcode_stream_to: constant(Opcode::StreamTo as u64),
            opcode_set_flush_timeout: constant(Opcode::SetFlushTimeout as u64),
            opcode_set_status_period: constant(Opcode::SetStatusPeriod as u64),
            opcode_status_now: constant(Opcode::StatusNow as u64),
            opcode_read_tick: constant(Opcode::ReadTick as u64),
            opcode_cell_command: constant(Opcode::CellCommand as u64),
            opcode_set_sync_period: constant(Opcode::SetSyncPeriod as u64),
            fate_accepted: constant(BoxCounter::CommandsAccepted as u64),
            fate_unknown_opcode: constant(BoxCounter::RefusedUnknownOpcode as u64),
            fate_bad_argument: constant(BoxCounter::RefusedBadArgument as u64),
            result_ok: constant(AckResult::Ok as u64),
            result_unknown_opcode: constant(AckResult::UnknownOpcode as u64),
            result_bad_argument: constant(AckResult::BadArgument as u64),
            box_ok_flag: Default::default(),
            stream_to_flag: Default::default(),
            set_flush_timeout_flag: Default::default(),
            set_status_period_flag: Default::default(),
            status_now_flag: Default::default(),
            read_tick_flag: Default::default(),
            cell_command_flag: Default::default(),
            set_sync_period_flag: Default::default(),
            length_0: Default::default(),
            length_value: Default::default(),
            length_destination: Default::default(),
            length_cell_command: Default::default(),
            destination_ok: Default::default(),
            flush_timeout_ok: Default::default(),
            status_period_ok: Default::default(),
            value_zero: Default::default(),
            cell_port_ok: Default::default(),
            reserved_zero: Default::default(),
            target_port: Default::default(),
            target_one: Default::default(),
            target_all: Default::default(),
            arguments_ok_held: Default::default(),
            arguments_fate: Default::default(),
            arguments_result: Default::default(),
            fields: Default::default(),
            arguments_good: Default::default(),
            opcode_known: Default::default(),
        }
    }
}

impl Logic for CommandChecks {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            box_ok_flag,
            stream_to_flag,
            set_flush_timeout_flag,
            set_status_period_flag,
            status_now_flag,
            read_tick_flag,
            cell_command_flag,
            set_sync_period_flag,
            length_0,
            length_value,
            length_destination,
            length_cell_command,
            destination_ok,
            flush_timeout_ok,
            status_period_ok,
            value_zero,
            cell_port_ok,
            reserved_zero,
            target_port,
            target_one,
            target_all,
            arguments_ok_held,
            arguments_fate,
            arguments_result
        );
        // Stage 1: the box id, the opcode and the arguments against the rules.
        self.box_ok_flag.d.next = (self.command_box_id.val() == self.box_id.val())
            | (self.command_box_id.val() == self.any_box.val());
        self.stream_to_flag.d.next = self.command_opcode.val() == self.opcode_stream_to.val();
        self.set_flush_timeout_flag.d.next =
            self.command_opcode.val() == self.opcode_set_flush_timeout.val();
        self.set_status_period_flag.d.next =
            self.command_opcode.val() == self.opcode_set_status_period.val();
        self.status_now_flag.d.next = self.command_opcode.val() == self.opcode_status_now.val();
        self.read_tick_flag.d.next = self.command_opcode.val() == self.opcode_read_tick.val();
        self.cell_command_flag.d.next = self.command_opcode.val() == self.opcode_cell_command.val();
        self.set_sync_period_flag.d.next =
            self.command_opcode.val() == self.opcode_set_sync_period.val();
        self.length_0.d.next = self.command_argument_length.val() == 0;
        self.length_value.d.next = self.command_argument_length.val() == self.value_length.val();
        self.length_destination.d.next =
            self.command_argument_length.val() == self.destination_length.val();
        self.length_cell_command.d.next =
            self.command_argument_length.val() == self.cell_command_length.val();
        self.fields.arguments.next = self.command_arguments.val();
        self.destination_ok.d.next = (self.fields.ip.val() != 0) & (self.fields.port.val() != 0);
        self.flush_timeout_ok.d.next = (self.fields.ticks.val() != 0)
            & (self.fields.ticks.val() <= self.max_flush_timeout.val());
        self.status_period_ok.d.next = self.fields.ticks.val() >= self.min_status_period.val();
        self.value_zero.d.next = self.fields.ticks.val() == 0;
        self.cell_port_ok.d.next = (self.fields.cell_port.val() == self.all_ports.val())
            | (self.fields.cell_port.val() < self.port_count.val());
        // (ports from 64 on target nothing, as a cell command's port never is one)
        self.target_port.d.next = self.fields.cell_port.val().get_bits::<6>(0);
        self.target_one.d.next = self.fields.cell_port.val().get_bits::<2>(6) == 0;
        self.target_all.d.next = self.fields.cell_port.val() == self.all_ports.val();
        self.reserved_zero.d.next = self.fields.cell_reserved.val() == 0;

        // Stage 2: the arguments' verdict.
        // (the opcode flags are exclusive: the verdict is an OR of one term per opcode)
        self.arguments_good.next = (self.stream_to_flag.q.val()
            & (self.length_0.q.val()
                | (self.length_destination.q.val() & self.destination_ok.q.val())))
            | (self.set_flush_timeout_flag.q.val()
                & self.length_value.q.val()
                & self.flush_timeout_ok.q.val())
            | (self.length_value.q.val()
                & (((self.set_status_period_flag.q.val() | self.set_sync_period_flag.q.val())
                    & self.status_period_ok.q.val())
                    | (self.set_sync_period_flag.q.val() & self.value_zero.q.val())))
            | ((self.status_now_flag.q.val() | self.read_tick_flag.q.val())
                & self.length_0.q.val())
            | (self.cell_command_flag.q.val()
                & self.length_cell_command.q.val()
                & self.cell_port_ok.q.val()
                & self.reserved_zero.q.val());
        self.opcode_known.next = self.stream_to_flag.q.val()
            | self.set_flush_timeout_flag.q.val()
            | self.set_status_period_flag.q.val()
            | self.status_now_flag.q.val()
            | self.read_tick_flag.q.val()
            | self.cell_command_flag.q.val()
            | self.set_sync_period_flag.q.val();
        self.arguments_fate.d.next = self.fate_unknown_opcode.val();
        self.arguments_result.d.next = self.result_unknown_opcode.val();
        if self.opcode_known.val() {
            self.arguments_fate.d.next = self.fate_bad_argument.val();
            self.arguments_result.d.next = self.result_bad_argument.val();
        }
        if self.arguments_good.val() {
            self.arguments_fate.d.next = self.fate_accepted.val();
            self.arguments_result.d.next = self.result_ok.val();
        }
        self.arguments_ok_held.d.next = self.arguments_good.val();
        self.box_ok.next = self.box_ok_flag.q.val();
        self.is_stream_to.next = self.stream_to_flag.q.val();
        self.is_set_flush_timeout.next = self.set_flush_timeout_flag.q.val();
        self.is_set_status_period.next = self.set_status_period_flag.q.val();
        self.is_status_now.next = self.status_now_flag.q.val();
        self.is_cell_command.next = self.cell_command_flag.q.val();
        self.is_set_sync_period.next = self.set_sync_period_flag.q.val();
        self.no_arguments.next = self.length_0.q.val();
        self.target_full.next = (self.target_all.q.val() & (self.downlink_full_ports.val() != 0))
            | (self.target_one.q.val()
                & self
                    .downlink_full_ports
                    .val()
                    .get_bit(self.target_port.q.val().index()));
        self.arguments_ok.next = self.arguments_ok_held.q.val();
        self.fate.next = self.arguments_fate.q.val();
        self.result.next = self.arguments_result.q.val();
        self.value.next = self.fields.ticks.val();
        self.cell_port.next = self.fields.cell_port.val();
        self.argument_mac.next = self.fields.mac.val();
        self.argument_ip.next = self.fields.ip.val();
        self.argument_port.next = self.fields.port.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command_decoder::HELD_ARGUMENT_BYTES;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::command::Request;
    use skinbox_protocol::Error;

    const BOX_ID: u16 = 0x0102;
    const PORTS: u8 = 8;

    /// The verdict `Request::parse` gives: (arguments right, fate, result, target ports).
    fn verdict(opcode: u8, args: &[u8]) -> (bool, BoxCounter, AckResult, u64) {
        match Request::parse(opcode, args, PORTS) {
            Ok(request) => {
                let ports = match request {
                    Request::CellCommand { port, .. } if port == ALL_PORTS => u64::MAX,
                    Request::CellCommand { port, .. } => 1 << port,
                    _ => 0,
                };
                (true, BoxCounter::CommandsAccepted, AckResult::Ok, ports)
            }
            Err(Error::UnknownOpcode { .. }) => (
                false,
                BoxCounter::RefusedUnknownOpcode,
                AckResult::UnknownOpcode,
                0,
            ),
            Err(_) => (
                false,
                BoxCounter::RefusedBadArgument,
                AckResult::BadArgument,
                0,
            ),
        }
    }

    #[test]
    fn random_commands_are_judged_as_the_protocol_parses_them() {
        let mut bench = Bench::new(CommandChecks::new(BOX_ID, PORTS), |b| &mut b.clock);
        let mut rng = TestRng::new(0xC4EC);
        let mut verdicts = std::collections::HashMap::new();
        for _ in 0..3000 {
            let r = rng.next_u64();
            let opcode = match r % 10 {
                0 => (r >> 8) as u8,
                k => (k % 8) as u8,
            };
            let length = match (r >> 16) % 6 {
                0 => (r >> 24) as usize % 14,
                1 => 0,
                2 => TICKS_LEN,
                3 => DESTINATION_LEN,
                _ => CELL_COMMAND_LEN,
            };
            let mut args: Vec<u8> = (0..length).map(|_| rng.byte()).collect();
            match (r >> 32) % 5 {
                // a port in range, past it, or every port, with the reserved bytes 0
                0 | 1 if length >= 4 => {
                    args[0] = [0, PORTS - 1, PORTS, ALL_PORTS][(r >> 40) as usize % 4];
                    args[1..4].fill(0);
                }
                // a value at or around the limits
                2 if length >= 4 => args[..4].copy_from_slice(
                    &[
                        0,
                        1,
                        MAX_FLUSH_TIMEOUT_TICKS,
                        MIN_STATUS_PERIOD_TICKS - 1,
                        MIN_SYNC_PERIOD_TICKS,
                    ][(r >> 40) as usize % 5]
                        .to_be_bytes(),
                ),
                // a destination without an address or a port
                3 if length >= 12 => args[6 + (r >> 40) as usize % 6..].fill(0),
                _ => {}
            }
            let box_id = [BOX_ID, ANY_BOX, BOX_ID ^ 0x10][(r >> 48) as usize % 3];
            let mut held = [0u8; HELD_ARGUMENT_BYTES];
            let n = args.len().min(HELD_ARGUMENT_BYTES);
            held[..n].copy_from_slice(&args[..n]);
            let high: Bits<96> = u64::from_be_bytes(held[..8].try_into().unwrap()).into();
            let low: Bits<96> = u64::from(u32::from_be_bytes(held[8..].try_into().unwrap())).into();
            let u = &mut bench.uut;
            u.command_box_id.next = u64::from(box_id).into();
            u.command_opcode.next = u64::from(opcode).into();
            u.command_argument_length.next = (args.len() as u64).into();
            u.command_arguments.next = (high << 32) | low;
            let full_ports = match (r >> 56) % 3 {
                0 => 0,
                1 => 1 << ((r >> 58) % 8),
                _ => rng.next_u64(),
            };
            u.downlink_full_ports.next = full_ports.into();
            bench.cycles(CHECK_CLOCKS);
            let (ok, fate, result, ports) = verdict(opcode, &args);
            let u = &bench.uut;
            let at = format!("opcode {opcode}, arguments {args:02x?}");
            assert_eq!(u.arguments_ok.val(), ok, "{at}");
            assert_eq!(u.fate.val().to_u64(), fate as u64, "{at}");
            assert_eq!(u.result.val().to_u64(), result as u64, "{at}");
            assert_eq!(u.box_ok.val(), box_id != BOX_ID ^ 0x10, "{at}");
            if ok && opcode == Opcode::CellCommand as u8 {
                let full = full_ports & ports != 0;
                assert_eq!(u.target_full.val(), full, "{at}, full {full_ports:x}");
            }
            assert_eq!(u.no_arguments.val(), args.is_empty(), "{at}");
            *verdicts.entry(result as u8).or_insert(0) += 1;
        }
        assert_eq!(verdicts.len(), 3, "every verdict came up: {verdicts:?}");
        assert!(verdicts.values().all(|&n| n >= 100), "{verdicts:?}");
    }
}

//! CommandArguments: the argument fields of the commands the box takes, as wires from the
//! held argument bytes (docs/wire-format.md): stream-to's MAC, IP and port, the u32 of
//! set-flush-timeout, set-status-period and set-sync-period, and a cell command's port and
//! reserved bytes. Field positions come from `skinbox_protocol::command`'s tables.
//!
//! Combinational: no register, no logic but the wiring.

use crate::command_decoder::HELD_ARGUMENT_BYTES;
use crate::hdl::*;
use skinbox_protocol::command::{cell_command_field, destination_field, ticks_field};
use skinbox_protocol::Field;

/// Bits of the held argument bytes.
pub const HELD_ARGUMENT_BITS: usize = 8 * HELD_ARGUMENT_BYTES;

/// The lowest bit in the held arguments of the argument bytes `field` (the first argument
/// byte is the top byte).
fn argument_bit(field: Field) -> Constant<Bits<7>> {
    assert!(
        field.end <= HELD_ARGUMENT_BYTES,
        "argument bytes {field:?} not held"
    );
    constant((8 * (HELD_ARGUMENT_BYTES - field.end)) as u64)
}

/// The argument fields of the held argument bytes.
#[derive(LogicBlock)]
pub struct CommandArguments {
    /// The first held argument bytes, the first in the top byte; bytes past the arguments 0.
    pub arguments: Signal<In, Bits<HELD_ARGUMENT_BITS>>,
    /// stream-to: the destination MAC.
    pub mac: Signal<Out, Bits<48>>,
    /// stream-to: the destination IP.
    pub ip: Signal<Out, Bits<32>>,
    /// stream-to: the destination UDP port.
    pub port: Signal<Out, Bits<16>>,
    /// set-flush-timeout, set-status-period, set-sync-period: the ticks.
    pub ticks: Signal<Out, Bits<32>>,
    /// cell command: the port (or `ALL_PORTS`).
    pub cell_port: Signal<Out, Bits<8>>,
    /// cell command: the reserved bytes.
    pub cell_reserved: Signal<Out, Bits<24>>,
    mac_bit: Constant<Bits<7>>,
    ip_bit: Constant<Bits<7>>,
    port_bit: Constant<Bits<7>>,
    ticks_bit: Constant<Bits<7>>,
    cell_port_bit: Constant<Bits<7>>,
    cell_reserved_bit: Constant<Bits<7>>,
}

impl Default for CommandArguments {
    fn default() -> Self {
        Self {
            arguments: Default::default(),
            mac: Default::default(),
            ip: Default::default(),
            port: Default::default(),
            ticks: Default::default(),
            cell_port: Default::default(),
            cell_reserved: Default::default(),
            mac_bit: argument_bit(destination_field::MAC),
            ip_bit: argument_bit(destination_field::IP),
            port_bit: argument_bit(destination_field::PORT),
            ticks_bit: argument_bit(ticks_field::TICKS),
            cell_port_bit: argument_bit(cell_command_field::PORT..cell_command_field::PORT + 1),
            cell_reserved_bit: argument_bit(cell_command_field::RESERVED),
        }
    }
}

impl Logic for CommandArguments {
    #[hdl_gen]
    fn update(&mut self) {
        self.mac.next = self
            .arguments
            .val()
            .get_bits::<48>(self.mac_bit.val().index());
        self.ip.next = self
            .arguments
            .val()
            .get_bits::<32>(self.ip_bit.val().index());
        self.port.next = self
            .arguments
            .val()
            .get_bits::<16>(self.port_bit.val().index());
        self.ticks.next = self
            .arguments
            .val()
            .get_bits::<32>(self.ticks_bit.val().index());
        self.cell_port.next = self
            .arguments
            .val()
            .get_bits::<8>(self.cell_port_bit.val().index());
        self.cell_reserved.next = self
            .arguments
            .val()
            .get_bits::<24>(self.cell_reserved_bit.val().index());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::command::{Destination, Request, ALL_PORTS};

    /// The held bytes of `arguments` (zero past them).
    fn held(arguments: &[u8]) -> Bits<HELD_ARGUMENT_BITS> {
        let mut bytes = [0u8; HELD_ARGUMENT_BYTES];
        bytes[..arguments.len()].copy_from_slice(arguments);
        let high: Bits<HELD_ARGUMENT_BITS> =
            u64::from_be_bytes(bytes[..8].try_into().unwrap()).into();
        let low: Bits<HELD_ARGUMENT_BITS> =
            u64::from(u32::from_be_bytes(bytes[8..].try_into().unwrap())).into();
        (high << 32) | low
    }

    fn fields(arguments: &[u8]) -> CommandArguments {
        let mut block = CommandArguments::default();
        block.connect_all();
        block.arguments.next = held(arguments);
        assert!(simulate(&mut block, 100), "logic did not settle");
        block
    }

    /// The held bytes of `request`'s arguments, as the protocol writes them.
    fn emitted(request: Request) -> CommandArguments {
        let mut bytes = vec![0u8; request.argument_len()];
        request.emit_arguments(&mut bytes);
        bytes.truncate(HELD_ARGUMENT_BYTES);
        fields(&bytes)
    }

    #[test]
    fn the_fields_are_where_the_protocol_emits_them() {
        let d = Destination {
            mac: [2, 0x11, 0x22, 0x33, 0x44, 0x55],
            ip: [192, 0, 2, 77],
            port: 0xBEEF,
        };
        let f = emitted(Request::StreamTo { to: Some(d) });
        assert_eq!(f.mac.val().to_u64(), 0x0211_2233_4455);
        assert_eq!(f.ip.val().to_u64(), u64::from(u32::from_be_bytes(d.ip)));
        assert_eq!(f.port.val().to_u64(), 0xBEEF);
        let f = emitted(Request::SetStatusPeriod { ticks: 0x0102_0304 });
        assert_eq!(f.ticks.val().to_u64(), 0x0102_0304);
        let f = emitted(Request::CellCommand {
            port: 5,
            packet: [0x5A; 20],
        });
        assert_eq!(f.cell_port.val().to_u64(), 5);
        assert_eq!(f.cell_reserved.val().to_u64(), 0);
        // the reserved bytes, which the protocol writes as zeros
        let mut bytes = [0u8; HELD_ARGUMENT_BYTES];
        bytes[cell_command_field::PORT] = ALL_PORTS;
        bytes[cell_command_field::RESERVED].copy_from_slice(&[1, 2, 3]);
        let f = fields(&bytes);
        assert_eq!(f.cell_port.val().to_u64(), u64::from(ALL_PORTS));
        assert_eq!(f.cell_reserved.val().to_u64(), 0x01_02_03);
    }
}
